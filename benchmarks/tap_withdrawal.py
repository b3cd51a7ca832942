"""Does a T5 reference's hand withdraw at the end? Per release and primitive, from stored state (docs/suites/t5.md).

    .venv/bin/python benchmarks/tap_withdrawal.py RELEASE [RELEASE ...] [--config t5_libero] [--task SUBSTRING] [--rebuild]

For each T5 reference: the end effector's height at the clip's last frame above its lowest point after the branch
step (`observation.ee_pose` z, metres). A tap is a press-and-retract (spec §3.5), so its hand should end well
above where it struck, and LIBERO's push script lifts the hand at its end too. Prints, per primitive, how many
references end below `LOW` and the range of the rise, and lists the low pushes and taps. Reads the release alone
(no simulator).

`--rebuild` (LIBERO, needs the simulator; ≈ 6 s per clip): re-runs each push's and tap's branch with today's
builder (`LiberoRig.branch`, the scripts' own withdrawal check and next side included) and says whether it
builds the same stream, or another one (the same scene from another side), or drops it and why: whether the
release's references are what the current builder makes.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import pyarrow.parquet as pq

from wsp_eval.episode import episode_actions
from wsp_eval.release_format import INSTANCES

LOW = 0.05  # m: a hand that ends less than this above its lowest point after the branch has not withdrawn: the
# stored-state twin of LIBERO's build check `primitives.MIN_RISE` (not imported: that module needs the simulator)
SIDED = ("push", "tap")


def rises(config_dir: Path, task: str | None) -> list[tuple[str, str, str, float]]:
    """(instance_id, task, primitive, rise in m) for every reference of one T5 config."""
    out = []
    for row in pq.read_table(config_dir / INSTANCES).to_pylist():
        if task and task not in row["task"]:
            continue
        z = episode_actions(config_dir, row["episode_indices"][0], "observation.ee_pose")[:, 2]  # reads any column
        out.append((row["instance_id"], row["task"], row["primitive"], float(z[-1] - z[int(row["branch_step"]):].min())))
    return out


def rebuild_sided(config_dir: Path, task: str | None) -> None:
    """Re-run every push's and tap's branch with today's LIBERO builder; print each that is dropped or differs."""
    import numpy as np

    from wsp_data.builders.base import Dropped
    from wsp_data.platforms.libero.t5 import LiberoRig

    rows = [r for r in pq.read_table(config_dir / INSTANCES).to_pylist()
            if r["primitive"] in SIDED and not (task and task not in r["task"])]
    same: dict[str, int] = defaultdict(int)
    for name in sorted({r["task"] for r in rows}):  # one task's simulators open at a time (~1 GB each)
        rig = LiberoRig(name)
        try:
            for row in (r for r in rows if r["task"] == name):
                p = row["primitive"]
                b = rig.branch(p, row["seed"])
                stored = episode_actions(config_dir, row["episode_indices"][0], "action")  # one row per frame:
                # the stream and a last frame after it
                if isinstance(b, Dropped):
                    print(f"  rebuilt {p} {row['instance_id']}: dropped ({b.reason})", flush=True)
                elif len(stored) != len(b.stream) + 1 or not np.array_equal(b.stream, stored[:-1]):
                    z = rig.state.replay(row["seed"], b.stream).stack("tcp_pose")[:, 2]
                    print(f"  rebuilt {p} {row['instance_id']}: a different stream, rising "
                          f"{z[-1] - z[b.branch:].min():.3f} m", flush=True)
                else:
                    same[p] += 1
        finally:
            rig.close()
    for p in SIDED:
        print(f"  rebuilt {p}: {same[p]} of {sum(r['primitive'] == p for r in rows)} the same stream")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("releases", type=Path, nargs="+")
    ap.add_argument("--config", default="t5_libero")
    ap.add_argument("--task", help="only tasks whose name contains this")
    ap.add_argument("--rebuild", action="store_true", help="re-run each push's and tap's branch with today's builder (simulator)")
    args = ap.parse_args()
    for release in args.releases:
        config_dir = release / args.config
        if not (config_dir / INSTANCES).is_file():
            raise SystemExit(f"{config_dir}: no {INSTANCES} (is {release} a release with {args.config}?)")
        by_primitive: dict[str, list[float]] = defaultdict(list)
        low = []
        for instance_id, task, primitive, rise in rises(config_dir, args.task):
            by_primitive[primitive].append(rise)
            if primitive in SIDED and rise < LOW:
                low.append(f"{primitive} {instance_id} ({task.split('/')[-1]}, {rise:.3f} m)")
        cells = [f"{p} {sum(r < LOW for r in v)}/{len(v)} low, rise {min(v):.3f}–{max(v):.3f} m"
                 for p, v in sorted(by_primitive.items())]
        print(f"{release}: " + "; ".join(cells), flush=True)
        for t in low:
            print(f"  not withdrawn: {t}")
        if args.rebuild:
            rebuild_sided(config_dir, args.task)


if __name__ == "__main__":
    main()
