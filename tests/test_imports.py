"""The evaluation side stands alone (spec §8.9): importing any `wsp_eval` module loads neither the build
side nor a simulator nor torch; and no module of either package imports itself back at module level."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("wsp_eval", "wsp_data")
FORBIDDEN = ("wsp_data", "torch", "sapien", "mani_skill", "mujoco", "lerobot")


def test_evaluation_side_imports_no_build_side_simulator_or_torch():
    script = textwrap.dedent(f"""
        import importlib, json, sys
        names = {json.dumps(sorted(_modules(ROOT, "wsp_eval")))}
        for name in names:
            importlib.import_module(name)
        print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in {FORBIDDEN!r})))
    """)
    r = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.splitlines()[-1]) == []


def test_no_module_level_import_cycles():
    graph = import_graph(ROOT, PACKAGES)
    assert "wsp_eval.score" in graph and "wsp_eval.cli" in graph
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_cycle_check_finds_a_cycle(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "a.py").write_text("from pkg.b import B\nA = 1\n")
    (tmp_path / "pkg" / "b.py").write_text("def lazy():\n    import pkg.c\nfrom . import c\nB = 2\n")
    (tmp_path / "pkg" / "c.py").write_text("import pkg.a\n")
    assert find_cycle(import_graph(tmp_path, ("pkg",))) == ["pkg.a", "pkg.b", "pkg.c", "pkg.a"]
    (tmp_path / "pkg" / "c.py").write_text("def lazy():\n    import pkg.a\n")  # function-local: allowed
    assert find_cycle(import_graph(tmp_path, ("pkg",))) is None


# -- helpers ------------------------------------------------------------------------------------------------
def _modules(root: Path, package: str) -> dict[str, Path]:
    """Dotted name → file of every module of `package` under `root`."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _top_level_imports(tree: ast.Module, module: str, is_package: bool) -> list[list[str]]:
    """What `module` imports when it runs (function bodies skipped), each as its candidate names, most specific
    first: `from m import x` is module `m.x` if there is one, else `m`."""
    found, todo = [], list(tree.body)
    while todo:
        node = todo.pop(0)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        if isinstance(node, ast.Import):
            found += [[a.name] for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".")
                base = ".".join(parts[: len(parts) - node.level + is_package] + ([base] if base else []))
            found += [[f"{base}.{a.name}", base] for a in node.names]
        else:
            todo += list(ast.iter_child_nodes(node))
    return found


def import_graph(root: Path, packages: tuple[str, ...]) -> dict[str, list[str]]:
    """Module → the modules of `packages` it imports at module level."""
    files = {name: path for p in packages for name, path in _modules(root, p).items()}
    graph = {}
    for name, path in files.items():
        imports = _top_level_imports(ast.parse(path.read_text()), name, path.name == "__init__.py")
        edges = {next((c for c in candidates if c in files), None) for candidates in imports}
        graph[name] = sorted(edges - {None, name})
    return graph


def find_cycle(graph: dict[str, list[str]]) -> list[str] | None:
    """One cycle of `graph` as [a, b, …, a], or None when it is acyclic."""
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in graph.get(node, ()):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None
