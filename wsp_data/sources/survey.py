"""Survey the scripted experts: per task, how many seeds script into a replay-verified success, how long the
trajectories are and what one costs.

    python -m wsp_data.sources.survey [--platform maniskill|libero] [--seeds 20] [--tasks …] [--out experts.md]

prints a Markdown table (and writes it to `--out`). Every seed goes through the platform's expert source:
on ManiSkill, script under `pd_ee_pose`, replay under `pd_joint_pos`, keep only if the replay ends in task
success; on LIBERO, the closed-loop OSC script, kept only on task success.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

from tqdm import tqdm

from wsp_data.platforms import KITS, kit

COLUMNS = ("task", "seeds", "successes", "success rate", "mean length (steps)", "max length", "s / trajectory")


def survey(tasks: Sequence[str], seeds: Iterable[int], *, platform: str, progress: bool = True) -> list[dict]:
    """Script and verify every seed of every task of `platform` (its kit's expert); one summary row per task.

    Row keys: `task`, `seeds` (tried), `successes`, `success_rate`, `mean_length` and `max_length` (steps of
    the verified trajectories, None if there are none) and `seconds_per_trajectory` (wall time of script +
    replay, per seed tried).
    """
    seeds = list(seeds)
    k = kit(platform)
    rows = []
    with tqdm(total=len(tasks) * len(seeds), desc="experts", unit="traj", file=sys.stderr,
              disable=not progress) as bar:
        for name in tasks:
            bar.set_postfix_str(name)
            source = k.make_expert(name)
            lengths, seconds = [], 0.0
            try:
                for seed in seeds:
                    t0 = time.perf_counter()
                    actions = source.trajectory(seed)
                    seconds += time.perf_counter() - t0
                    if actions is not None:
                        lengths.append(len(actions))
                    bar.update()
            finally:
                source.close()
            n = len(seeds)
            rows.append(dict(
                task=name, seeds=n, successes=len(lengths), success_rate=len(lengths) / n if n else 0.0,
                mean_length=sum(lengths) / len(lengths) if lengths else None,
                max_length=max(lengths) if lengths else None,
                seconds_per_trajectory=seconds / n if n else 0.0,
            ))
    return rows


def markdown(rows: Sequence[dict]) -> str:
    """The survey rows as a Markdown table."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "|".join(["---"] + ["---:"] * (len(COLUMNS) - 1)) + "|"]
    for r in rows:
        mean, top = ("–", "–") if r["mean_length"] is None else (f"{r['mean_length']:.0f}", str(r["max_length"]))
        lines.append(f"| {r['task']} | {r['seeds']} | {r['successes']} | {100 * r['success_rate']:.0f}% | "
                     f"{mean} | {top} | {r['seconds_per_trajectory']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wsp_data.sources.survey", description=__doc__.split("\n\n")[0])
    ap.add_argument("--platform", choices=tuple(KITS), default="maniskill")
    ap.add_argument("--seeds", type=int, default=20, help="seeds 0..N-1 per task (default 20)")
    ap.add_argument("--tasks", nargs="+", default=None, metavar="TASK",
                    help="tasks to survey (default: the platform's registered benchmark tasks)")
    ap.add_argument("--out", type=Path, default=None, help="also write the Markdown table to this file")
    args = ap.parse_args(argv)
    known = kit(args.platform).tasks()
    unknown = [t for t in args.tasks or () if t not in known and args.platform == "maniskill"]
    if unknown:
        ap.error(f"unknown task(s) {', '.join(unknown)}; known: {', '.join(known)}")
    table = markdown(survey(args.tasks or list(known), range(args.seeds), platform=args.platform))
    print(table, end="")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
