"""Does a T5 reference's hand withdraw at the end? Per release and primitive, from stored state (docs/validity.md §1,
"Version 13").

    .venv/bin/python benchmarks/tap_withdrawal.py RELEASE [RELEASE ...] [--config t5_libero] [--task SUBSTRING]

For each T5 reference: the end effector's height at the clip's last frame above its lowest point after the branch
step (`observation.ee_pose` z, metres). A tap is a press-and-retract (SPEC §3 T5), so its hand should end well
above where it struck; a LIBERO push's clip often ends with the hand still low. Prints, per primitive, how many
references end below `LOW` and the range of the rise, and lists the low taps. Reads the release alone (no
simulator).
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import pyarrow.parquet as pq

from wsp_eval.episode import episode_actions
from wsp_eval.release_format import INSTANCES

LOW = 0.05  # m: a hand that ends less than this above its lowest point after the branch has not withdrawn


def rises(config_dir: Path, task: str | None) -> list[tuple[str, str, str, float]]:
    """(instance_id, task, primitive, rise in m) for every reference of one T5 config."""
    out = []
    for row in pq.read_table(config_dir / INSTANCES).to_pylist():
        if task and task not in row["task"]:
            continue
        z = episode_actions(config_dir, row["episode_indices"][0], "observation.ee_pose")[:, 2]  # reads any column
        out.append((row["instance_id"], row["task"], row["primitive"], float(z[-1] - z[int(row["branch_step"]):].min())))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("releases", type=Path, nargs="+")
    ap.add_argument("--config", default="t5_libero")
    ap.add_argument("--task", help="only tasks whose name contains this")
    args = ap.parse_args()
    for release in args.releases:
        config_dir = release / args.config
        if not (config_dir / INSTANCES).is_file():
            raise SystemExit(f"{config_dir}: no {INSTANCES} (is {release} a release with {args.config}?)")
        by_primitive: dict[str, list[float]] = defaultdict(list)
        low_taps = []
        for instance_id, task, primitive, rise in rises(config_dir, args.task):
            by_primitive[primitive].append(rise)
            if primitive == "tap" and rise < LOW:
                low_taps.append(f"{instance_id} ({task.split('/')[-1]}, {rise:.3f} m)")
        cells = [f"{p} {sum(r < LOW for r in v)}/{len(v)} low, rise {min(v):.3f}–{max(v):.3f} m"
                 for p, v in sorted(by_primitive.items())]
        print(f"{release}: " + "; ".join(cells))
        for t in low_taps:
            print(f"  tap not withdrawn: {t}")


if __name__ == "__main__":
    main()
