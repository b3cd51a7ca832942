"""The platform cards of the docs site (docs/platforms/<name>.md), generated from the platform kits so they stay true.

    python scripts/platform_cards.py            # rewrite the generated part of every card
    python scripts/platform_cards.py --check    # exit 1 naming the cards that differ from the kits (a test runs it)

The generated part of a card lies between the two marker comments below; everything outside them (the title, the
hand-written notes) is kept as it is. It is made from:
- the kit's class docstring (or, where the class has none, the first paragraph of its module's docstring);
- its `PlatformInfo` (`info`: simulator, robot, camera and resolution, rate, both action streams with their column
  names, the state and end-effector columns) and its attributes (T1's perturbed dimensions, grippers, action
  bounds, default counts, simulators kept per worker);
- the suites each platform serves (`unsupported`) and their task lists: the benchmark tasks, T3's tasks, T4's
  tasks per kind and T5's per primitive.

No simulator is ever imported: the simulator packages are blocked for this process. Task lists that a kit can
only compute with its simulator (LIBERO reads its task specs from the BDDL files) are read from the platform
modules' constants with `ast`, or, where a list is computed from simulator data, shown as the rule the kit
states (`t4_needs`, `t5_needs`).
"""

from __future__ import annotations

import argparse
import ast
import importlib.abc
import inspect
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CARDS = ROOT / "docs" / "platforms"
PLATFORMS = ROOT / "wsp_data" / "platforms"
BEGIN = "<!-- platform_cards: generated from the kit; edit the kit, then run `python scripts/platform_cards.py` -->"
END = "<!-- platform_cards: end of the generated part -->"
SIMULATORS = frozenset({"sapien", "mani_skill", "mujoco", "robosuite", "libero", "torch", "gymnasium", "lerobot",
                        "dm_control", "gym_aloha", "trimesh", "OpenGL", "bddl"})
SUITE_TITLES = {"t1": "T1 Local action calibration", "t2": "T2 Global trajectory coverage",
                "t3": "T3 Action-source behaviour preservation", "t4": "T4 Interaction grounding",
                "t5": "T5 Interaction dynamics", "train": "train split"}
SUITE_PAGES = {"t1": "../suites/t1.md", "t2": "../suites/t2.md", "t3": "../suites/t3.md", "t4": "../suites/t4.md",
               "t5": "../suites/t5.md"}

# Where a platform's task lists are written down as constants (read with `ast`, never imported): the benchmark
# tasks (`TaskSpec(name, objects, instruction, …)` / `AlohaTask(name, instruction, objects, …)` calls, or a tuple
# of names) and T3's tasks.
TASK_SOURCES = {
    "maniskill": {"tasks": ("maniskill/experts.py", "TASKS"), "t3": ("maniskill/t3.py", "T3_TASKS")},
    "libero": {"tasks": ("libero/experts.py", "BENCHMARK_TASKS"), "t3": ("libero/t3.py", "T3_TASKS")},
    "aloha": {"tasks": ("aloha/env.py", "TASK_LIST"), "t3": ("aloha/t3.py", "T3_TASKS")},
}


class SimulatorBlocked(ImportError):
    pass


class _Blocker(importlib.abc.MetaPathFinder):
    """Refuses every simulator import, so a kit hook that would start one fails instead of loading it."""

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in SIMULATORS:
            raise SimulatorBlocked(f"simulator module {name!r} is not imported by the card generator")
        return None


def block_simulators() -> None:
    loaded = sorted(m for m in sys.modules if m.split(".")[0] in SIMULATORS)
    if loaded:
        raise RuntimeError(f"run this in a fresh process: simulator modules already imported ({', '.join(loaded)})")
    if not any(isinstance(f, _Blocker) for f in sys.meta_path):
        sys.meta_path.insert(0, _Blocker())


# -- reading constants with ast ----------------------------------------------------------------------------
def _assigned(path: Path, name: str) -> ast.expr:
    tree = ast.parse(path.read_text(), str(path))
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == name for t in targets) and node.value is not None:
            return node.value
    raise LookupError(f"{path}: no module-level assignment to {name}")


def _strings(node: ast.expr) -> tuple[str, ...] | None:
    if isinstance(node, ast.Tuple) and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts):
        return tuple(e.value for e in node.elts)
    return None


def tasks_of(platform: str, key: str) -> list[dict]:
    """The task list `key` of `platform` (`TASK_SOURCES`): [{name, instruction, objects}], in its order."""
    file, name = TASK_SOURCES[platform][key]
    value = _assigned(PLATFORMS / file, name)
    calls = [n for n in ast.walk(value) if isinstance(n, ast.Call) and n.args
             and isinstance(n.args[0], ast.Constant) and isinstance(n.args[0].value, str)]
    if not calls:
        return [{"name": n, "instruction": None, "objects": None} for n in ast.literal_eval(value)]
    out = []
    for call in sorted(calls, key=lambda c: (c.lineno, c.col_offset)):
        rest = call.args[1:]
        text = next((a.value for a in rest if isinstance(a, ast.Constant) and isinstance(a.value, str)), None)
        objects = next((s for a in rest if (s := _strings(a)) is not None), None)
        out.append({"name": call.args[0].value, "instruction": text, "objects": objects})
    return out


# -- the card ----------------------------------------------------------------------------------------------
def _summary(kit) -> str:
    cls = type(kit)
    doc = cls.__dict__.get("__doc__") or ""
    if not doc.strip():
        doc = (inspect.getmodule(cls).__doc__ or "").strip().split("\n\n")[0]
    text = " ".join(inspect.cleandoc(doc).split())
    return _clean(re.sub(r"\s*\(docs/[\w./-]+\)", "", text))


def _clean(text: str) -> str:
    """Text from a kit without the dates its reasons may carry (a card states what is true now)."""
    text = re.sub(r"\s*\(\d{4}-\d{2}-\d{2}\)", "", text)
    return re.sub(r",\s*\d{4}-\d{2}-\d{2}", "", text)


def _code(names) -> str:
    return ", ".join(f"`{n}`" for n in names)


def _dims(kit, dims) -> str:
    names = kit.info.action_names
    return ", ".join(f"{d} (`{names[d]}`)" for d in dims)


def _try(hook, *args):
    """The hook's result, or None where it would need the simulator."""
    try:
        return hook(*args)
    except SimulatorBlocked:
        return None


def _rows(rows: list[tuple[str, str]]) -> list[str]:
    return ["| | |", "|---|---|", *(f"| {k} | {v} |" for k, v in rows)]


def generated(name: str) -> str:
    """The generated part of platform `name`'s card (Markdown, without the markers)."""
    from wsp_data.platforms import kit as get_kit
    from wsp_eval.release_format import SUITES

    kit = get_kit(name)
    info = kit.info
    tasks = tasks_of(name, "tasks")
    task_names = tuple(t["name"] for t in tasks)
    grippers = kit.gripper_dim if isinstance(kit.gripper_dim, tuple) else (kit.gripper_dim,)
    bounds = kit.action_bounds
    if bounds is None:
        bounds_text = "none (joint targets: the joint-limit check reads them)"
    elif all(isinstance(b, (int, float)) for b in bounds):
        bounds_text = f"[{bounds[0]:g}, {bounds[1]:g}] on every dimension (beyond, the controller would clip: " \
                      "`action_limit`)"
    else:
        lo, hi = bounds
        limited = [i for i in range(len(lo)) if lo[i] > float("-inf") or hi[i] < float("inf")]
        bounds_text = "; ".join(f"`{info.action_names[i]}` in [{lo[i]:g}, {hi[i]:g}]" for i in limited)
    rows = [
        ("simulator", info.simulator),
        ("robot", f"`{info.robot_type}`"),
        ("camera", f"`{info.camera}`, {info.width}×{info.height} px (video column `{info.video_key}`)"),
        ("rate", f"{info.fps} Hz"),
        (f"native action `action` ({len(info.action_names)})", f"{info.action_space}; columns {_code(info.action_names)}"),
        (f"stored beside it `{info.alt_action_key}` ({len(info.alt_action_names)})",
         f"{info.alt_action_space}; columns {_code(info.alt_action_names)}"),
        (f"state `observation.state` ({len(info.state_names)})", f"{info.state_text}; columns {_code(info.state_names)}"),
        (f"end effector `observation.ee_pose` ({len(info.ee_names)})",
         f"{'one pose' if len(info.ee_names) == 7 else f'{len(info.ee_names) // 7} poses (one per arm)'}, xyz (m) + "
         f"quaternion wxyz; columns {_code(info.ee_names)}"),
        ("T1 perturbs", _dims(kit, kit.t1_dims())),
        ("grippers", f"{_dims(kit, grippers)}; fully open = {kit.gripper_open:g}"),
        ("action bounds", bounds_text),
        ("simulators kept per build worker", "one per task" if kit.rigs_per_worker is None else
         f"at most {kit.rigs_per_worker} (least recently used closed first)"),
    ]
    lines = [f"*{_summary(kit)}*", "", "## The platform", "", *_rows(rows), "", "## Suites", "",
             "| suite | default `--count` | on this platform |", "|---|---:|---|"]
    for suite in SUITES:
        why = kit.unsupported(suite)
        title = SUITE_TITLES[suite]
        if suite in SUITE_PAGES:
            title = f"[{title}]({SUITE_PAGES[suite]})"
        count = kit.default_counts.get(suite)
        count_text = f"{count:,}" if count else f"100 per task ({100 * len(task_names):,})"
        lines.append(f"| {title} | {count_text} | {'built' if why is None else 'not served: ' + why} |")
    lines += ["", f"## Tasks ({len(tasks)})", ""]
    if all(t["instruction"] for t in tasks):
        lines += ["| task | objects (target first) | instruction |", "|---|---|---|"]
        lines += [f"| `{t['name']}` | {_code(t['objects'] or ())} | {t['instruction']} |" for t in tasks]
    else:
        lines += [f"{i}. `{t['name']}`" for i, t in enumerate(tasks, 1)]
    lines += ["", "## Tasks per suite", ""]
    t3 = _try(kit.t3_tasks) or tuple(t["name"] for t in tasks_of(name, "t3"))
    lines += [f"**T3** (groups of eight sources on {len(t3)} tasks): {_code(t3)}.", ""]
    kinds = _try(kit.t4_kind_tasks, task_names)
    if kinds is None:
        from wsp_data.builders.t4 import KINDS

        lines += [f"**T4** kinds {_code(KINDS)}: the kit picks each kind's tasks from the task specs when a build "
                  f"starts (a kind left without a task is refused, needing {_clean(kit.t4_needs(['false_contact']))}).", ""]
    else:
        lines += ["**T4** tasks per kind:", "", "| kind | tasks |", "|---|---|"]
        lines += [f"| `{k}` | {_code(v) if v else '—'} |" for k, v in kinds.items()]
        lines.append("")
    primitives = kit.t5_primitives()
    per_primitive = _try(kit.t5_primitive_tasks, task_names)
    thresholds = kit.t5_rule_thresholds()
    if per_primitive is None:
        lines += [f"**T5** primitives {_code(primitives)}, balanced by slot; the kit picks each primitive's tasks "
                  f"from the task specs when a build starts (a primitive left without a task is refused, needing "
                  f"{_clean(kit.t5_needs())})."]
    else:
        lines += ["**T5** primitives, balanced by slot, with their tasks:", "", "| primitive | tasks |", "|---|---|"]
        lines += [f"| `{p}` | {_code(per_primitive.get(p, ())) or '—'} |" for p in primitives]
    if thresholds:
        lines += ["", "Acceptance thresholds that differ from the specification's: "
                  + ", ".join(f"`{k}` = {v:g}" for k, v in thresholds.items()) + "."]
    return "\n".join(lines) + "\n"


def render(name: str, current: str | None) -> str:
    """The card with its generated part replaced (a new card: a title, the generated part, a notes heading)."""
    body = f"{BEGIN}\n{generated(name)}{END}\n"
    if current is None or BEGIN not in current or END not in current:
        return f"# {name}\n\n{body}\n## Notes\n"
    head, rest = current.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return head + body + tail.removeprefix("\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="change nothing; exit 1 if a card differs from the kits")
    p.add_argument("platforms", nargs="*", help="default: every built-in platform (`TASK_SOURCES`)")
    args = p.parse_args(argv)
    block_simulators()
    sys.path.insert(0, str(ROOT))
    stale = []
    for name in args.platforms or list(TASK_SOURCES):
        path = CARDS / f"{name}.md"
        current = path.read_text() if path.exists() else None
        card = render(name, current)
        if card != current:
            stale.append(path)
            if not args.check:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(card)
    if args.check and stale:
        print("platform cards out of date with the kits (run `python scripts/platform_cards.py`): "
              + ", ".join(str(p.relative_to(ROOT)) for p in stale))
        return 1
    if not args.check:
        print("written: " + (", ".join(str(p.relative_to(ROOT)) for p in stale) or "nothing (all up to date)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
