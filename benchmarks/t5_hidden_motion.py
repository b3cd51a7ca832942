"""How much of a T5 reference's object motion can be seen: per reference, the object's true image travel (its
simulator pose projected through the release's camera), the travel of its visible pixels' centroid (which a hand
covering part of a resting object moves), the share of frames in which enough of it is visible to carry a position
(`object_track.MIN_PIXELS`), the share of its true image motion made between frames where it is hidden (under the
hand), how long it moves (from 10 % to 90 % of its true travel) and how much of that is in sight, and whether T5
can score it (`ObjectTrack.scorable`: the builder keeps only those).

Motion made only while the object is hidden cannot be told from a jump (the `teleport` negative of `wsp study
t5-negatives`), and a visible centroid that shifts because the hand covers part of a resting object is travel that a
video drawing the same arm over a still object reproduces (the `frozen` negative).

    .venv/bin/python benchmarks/t5_hidden_motion.py RELEASE t5_aloha
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval import object_track
from wsp_eval.release_format import INSTANCES
from wsp_eval.suites.reference import InstanceReference


def measure(config_dir: Path) -> list[dict]:
    out = []
    for row in pq.read_table(config_dir / INSTANCES).to_pylist():
        ref = InstanceReference(config_dir, row)
        k = int(row["evaluated_index"])
        labels, robot = ref.object_masks("reference"), ref.masks("reference")
        track = object_track.object_track(ref.frames("reference"), labels, k + 1, robot, ref.object_pose("reference", k))
        scale = 128 / labels.shape[1]
        used = np.array([t is not None for t in track.templates])
        travel = np.linalg.norm(track.points - track.points[0], axis=1) * scale
        start, end = (int(np.argmax(travel >= share * travel.max())) for share in (0.1, 0.9))
        centroids = np.array([t.centre for t in track.templates if t is not None])
        seen = float(np.linalg.norm(centroids - centroids[0], axis=1).max()) * scale if len(centroids) else 0.0
        out.append({"instance_id": row["instance_id"], "primitive": row["primitive"],
                    "true_travel": float(travel.max()), "visible_travel": seen, "frames_used": float(used.mean()),
                    "motion_s": (end - start) / ref.fps, "motion_in_sight": float(used[start:end + 1].mean()),
                    "hidden_motion": 1.0 - track.seen_motion(), "scorable": track.scorable})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("release", type=Path)
    p.add_argument("config", help="a T5 config, e.g. t5_aloha")
    args = p.parse_args(argv)
    rows = measure(args.release / args.config)
    print(f"{'instance':<20} {'primitive':<10} {'true travel':>11} {'visible travel':>14} {'frames used':>11} "
          f"{'motion hidden':>13} {'motion s':>8} {'in sight':>8} {'scorable':>8}   (travel: px per 128 px of frame "
          "height; motion s: from 10 % to 90 % of the true travel, and the share of those frames in sight)")
    for r in rows:
        print(f"{r['instance_id']:<20} {r['primitive']:<10} {r['true_travel']:>11.1f} {r['visible_travel']:>14.1f} "
              f"{r['frames_used']:>11.0%} {r['hidden_motion']:>13.0%} {r['motion_s']:>8.2f} {r['motion_in_sight']:>8.0%} "
              f"{'yes' if r['scorable'] else 'no':>8}")
    mostly = sum(r["hidden_motion"] >= 0.5 for r in rows)
    print(f"{mostly} of {len(rows)} references move their object mostly while it is hidden; "
          f"{sum(r['scorable'] for r in rows)} of {len(rows)} are scorable (`ObjectTrack.scorable`)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
