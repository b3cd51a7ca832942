"""How the code imports itself (spec §8.9). The evaluation side stands alone: importing any `wsp_eval` module loads
neither the build side nor a simulator nor torch, and no `wsp_eval` file names `wsp_data` or `wsp_models`. No
module of the packages or of the script folders imports itself back at module level. Platforms never import a
builder: both sides meet in `wsp_data.platforms.contract`. No module imports another module's private names."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("wsp_data", "wsp_eval", "wsp_models", "wsp_serve")
SCRIPT_FOLDERS = ("scripts", "benchmarks")  # folders of scripts: file x.py is module `folder.x`
ROOTS = PACKAGES + SCRIPT_FOLDERS
FORBIDDEN = ("wsp_data", "torch", "sapien", "mani_skill", "mujoco", "lerobot")

# Private names other modules may import, one entry per (importing module, name as imported); none today. An entry
# must be in use: the test fails on a stale one.
PRIVATE_IMPORTS_ALLOWED: set[tuple[str, str]] = set()


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


def test_evaluation_side_never_names_the_build_side_or_the_models():
    found = [f"{module} imports {name}" for module, name in _all_imports(_modules(ROOT, "wsp_eval"))
             if name.split(".")[0] in ("wsp_data", "wsp_models")]
    assert found == []


def test_no_module_level_import_cycles():
    graph = import_graph(ROOT, ROOTS)
    for name in ("wsp_eval.score", "wsp_eval.cli", "wsp_models.reference.model", "scripts.platform_cards",
                 "benchmarks.score_speed"):
        assert name in graph
    assert "wsp_eval.score" in graph["benchmarks.score_speed"] and "wsp_data.builders" in graph["wsp_data.build"]
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_platforms_never_import_a_builder():
    found = [f"{module} imports {name}" for module, name in _all_imports(_modules(ROOT, "wsp_data/platforms"))
             if name == "wsp_data.builders" or name.startswith("wsp_data.builders.")]
    assert found == []


def test_no_module_imports_a_private_name_of_another():
    found = set(private_imports(ROOT, ROOTS))
    unexpected = sorted(found - PRIVATE_IMPORTS_ALLOWED)
    assert unexpected == [], "private names imported: " + "; ".join(f"{m}: {n}" for m, n in unexpected)
    stale = sorted(PRIVATE_IMPORTS_ALLOWED - found)
    assert stale == [], "no longer imported, remove from PRIVATE_IMPORTS_ALLOWED: " + "; ".join(map(str, stale))


def test_cycle_check_finds_a_cycle(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "a.py").write_text("from pkg.b import B\nA = 1\n")
    (tmp_path / "pkg" / "b.py").write_text("def lazy():\n    import pkg.c\nfrom . import c\nB = 2\n")
    (tmp_path / "pkg" / "c.py").write_text("import pkg.a\n")
    assert find_cycle(import_graph(tmp_path, ("pkg",))) == ["pkg.a", "pkg.b", "pkg.c", "pkg.a"]
    (tmp_path / "pkg" / "c.py").write_text("def lazy():\n    import pkg.a\n")  # function-local: allowed
    assert find_cycle(import_graph(tmp_path, ("pkg",))) is None
    (tmp_path / "pkg" / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n")
    assert find_cycle(import_graph(tmp_path, ("pkg",))) is None  # annotations only: never runs


def test_cycle_check_counts_the_packages_an_import_runs(tmp_path):
    for pkg in ("one", "two", "two/sub"):
        (tmp_path / pkg).mkdir()
    (tmp_path / "one" / "__init__.py").write_text("from one.a import A\n")
    (tmp_path / "one" / "a.py").write_text("from one.b import B\nA = 1\n")  # a sibling: `one` is already running
    (tmp_path / "one" / "b.py").write_text("B = 2\n")
    (tmp_path / "two" / "__init__.py").write_text("")
    (tmp_path / "two" / "sub" / "__init__.py").write_text("import one\n")
    (tmp_path / "two" / "sub" / "c.py").write_text("")
    graph = import_graph(tmp_path, ("one", "two"))
    assert find_cycle(graph) is None and graph["one.a"] == ["one.b"]
    (tmp_path / "one" / "b.py").write_text("from two.sub.c import C\n")  # runs two and two.sub, which imports one
    assert find_cycle(import_graph(tmp_path, ("one", "two"))) == ["one", "one.a", "one.b", "two.sub", "one"]
    (tmp_path / "one" / "b.py").write_text("from one import A\n")  # the package itself, before it set A
    assert find_cycle(import_graph(tmp_path, ("one", "two"))) == ["one", "one.a", "one.b", "one"]


def test_private_import_check_finds_them(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "a.py").write_text("_X = 1\n__version__ = '1'\n")
    (tmp_path / "pkg" / "b.py").write_text("from pkg.a import _X, __version__\nimport pkg.a as a\n"
                                           "def f():\n    from . import a as m\n    return a._X + m._X + a.__name__\n")
    assert sorted(private_imports(tmp_path, ("pkg",))) == [("pkg.b", "pkg.a._X")] * 3


# -- helpers ------------------------------------------------------------------------------------------------
def _modules(root: Path, folder: str) -> dict[str, Path]:
    """Dotted name → file of every module under `root / folder` (a package, or a folder of scripts)."""
    out = {}
    for path in sorted((root / folder).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _ancestors(name: str) -> list[str]:
    """The packages a module sits in: a.b.c → [a, a.b]."""
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _is_type_checking(node: ast.AST) -> bool:
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING"
            or isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _absolute(node: ast.ImportFrom, module: str, is_package: bool, files: dict[str, Path]) -> str:
    """The module a `from … import` names, relative levels resolved; in a script folder, a bare name of a sibling
    script (its folder is on the path when it runs) is that script."""
    base = node.module or ""
    if node.level:
        parts = module.split(".")
        return ".".join(parts[: len(parts) - node.level + is_package] + ([base] if base else []))
    return _sibling(base, module, files)


def _sibling(name: str, module: str, files: dict[str, Path]) -> str:
    folder = module.split(".")[0]
    if folder in SCRIPT_FOLDERS and name not in files and f"{folder}.{name.split('.')[0]}" in files:
        return f"{folder}.{name}"
    return name


def _top_level_imports(tree: ast.Module, module: str, is_package: bool, files: dict[str, Path]) -> set[str]:
    """The modules of `files` that `module` runs when it runs (function bodies and `if TYPE_CHECKING:` skipped).
    `import a.b.c` runs a, a.b and a.b.c; `from a.b import x` runs a, a.b and a.b.x if that is a module. The
    packages `module` itself sits in are already running, so only the one an import names outright counts
    (`from a import x` inside a.m: it reads x from a, perhaps before a set it)."""
    found, todo, own = set(), list(tree.body), set(_ancestors(module))
    while todo:
        node = todo.pop(0)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        if _is_type_checking(node):
            todo += node.orelse
            continue
        if isinstance(node, ast.Import):
            for a in node.names:
                name = _sibling(a.name, module, files)
                found |= {p for p in _ancestors(name) if p not in own} | {name}
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(node, module, is_package, files)
            found |= {p for p in _ancestors(base) if p not in own}
            submodules = {f"{base}.{a.name}" for a in node.names} & files.keys()
            found |= submodules
            if len(submodules) < len(node.names) or base not in own:
                found.add(base)  # it reads names that are not submodules from `base`, or runs it
        else:
            todo += list(ast.iter_child_nodes(node))
    return found & files.keys()


def import_graph(root: Path, roots: tuple[str, ...]) -> dict[str, list[str]]:
    """Module → the modules of `roots` it runs at module level."""
    files = {name: path for r in roots for name, path in _modules(root, r).items()}
    return {name: sorted(_top_level_imports(ast.parse(path.read_text()), name, path.name == "__init__.py", files)
                         - {name})
            for name, path in files.items()}


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


def _all_imports(files: dict[str, Path]) -> Iterator[tuple[str, str]]:
    """(module, imported module) for every import anywhere in `files` (function-local ones too); `from m import x`
    yields m and m.x."""
    for module, path in files.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                yield from ((module, a.name) for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(node, module, path.name == "__init__.py", files)
                yield module, base
                yield from ((module, f"{base}.{a.name}") for a in node.names)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(root: Path, roots: tuple[str, ...]) -> Iterator[tuple[str, str]]:
    """(module, dotted name) for every private name of another module of `roots` that a module uses: imported
    (`from m import _x`) or read off an imported module (`import m` … `m._x`), anywhere in the file."""
    files = {name: path for r in roots for name, path in _modules(root, r).items()}
    for module, path in files.items():
        tree = ast.parse(path.read_text())
        bound: dict[str, str] = {}  # local name → the module of `files` it is bound to
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    name = _sibling(a.name, module, files)
                    bound[a.asname or a.name.split(".")[0]] = name if a.asname else name.split(".")[0]
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(node, module, path.name == "__init__.py", files)
                for a in node.names:
                    if _private(a.name) and base in files and base != module:
                        yield module, f"{base}.{a.name}"
                    if f"{base}.{a.name}" in files:
                        bound[a.asname or a.name] = f"{base}.{a.name}"
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and _private(node.attr):
                chain, value = [node.attr], node.value
                while isinstance(value, ast.Attribute):
                    chain.insert(0, value.attr)
                    value = value.value
                if isinstance(value, ast.Name) and value.id in bound:
                    owner = ".".join([bound[value.id], *chain[:-1]])
                    if owner in files and owner != module:
                        yield module, f"{owner}.{node.attr}"
