"""How much of a T5 reference's object motion T5 can see: per reference, the object's true image travel (its
simulator pose projected through the release's camera), the travel of its visible pixels' centroid (what T5
measures), the share of frames in which enough of it is visible to carry a position (`object_track.MIN_PIXELS`),
and the share of its true image motion that happens between frames where it is hidden (under the hand).

Motion that happens only while the object is hidden cannot be told from a jump (the `teleport` negative of
`wsp study t5-negatives`), and a visible centroid that shifts because the hand covers part of a resting object
is travel that a video drawing the same arm over a still object reproduces (the `frozen` negative).

    .venv/bin/python benchmarks/t5_hidden_motion.py RELEASE t5_aloha
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval import object_track
from wsp_eval.reference import object_poses
from wsp_eval.release_format import INSTANCES, OBJECT_POSES_KEY
from wsp_eval.suites.reference import InstanceReference


def projected(poses: np.ndarray, intrinsic: list, extrinsic: list) -> np.ndarray:
    """World points (T, 3) → image points (T, 2) in the release frame's pixels."""
    cam = (np.asarray(extrinsic, float).reshape(3, 4) @ np.c_[poses, np.ones(len(poses))].T).T
    uv = (np.asarray(intrinsic, float).reshape(3, 3) @ cam.T).T
    return uv[:, :2] / uv[:, 2:]


def measure(config_dir: Path) -> list[dict]:
    rows = pq.read_table(config_dir / INSTANCES).to_pylist()
    data = pq.read_table(config_dir / "data", columns=["episode_index", OBJECT_POSES_KEY])
    episodes = np.asarray(data.column("episode_index"))
    stored = data.column(OBJECT_POSES_KEY).to_pylist()
    out = []
    for row in rows:
        ref = InstanceReference(config_dir, row)
        episode = ref.episode("reference")
        k = int(row["evaluated_index"])
        labels, robot = ref.object_masks("reference"), ref.masks("reference")
        height = labels.shape[1]
        visible = (labels == k + 1) & (robot == 0)
        used = visible.sum(axis=(1, 2)) >= object_track.MIN_PIXELS * (height / 128) ** 2
        poses = object_poses(np.array([stored[i] for i in np.nonzero(episodes == episode)[0]]))[:, k, :3]
        true = projected(poses, row["camera_intrinsic"], row["camera_extrinsic"])
        scale = 128 / height
        travel = np.linalg.norm(true - true[0], axis=1) * scale
        centroids = np.array([np.argwhere(v)[:, ::-1].mean(axis=0) if u else (np.nan, np.nan)
                              for v, u in zip(visible, used)])
        first = int(np.argmax(used))
        seen = float(np.nanmax(np.linalg.norm(centroids - centroids[first], axis=1))) * scale if used.any() else 0.0
        steps = np.abs(np.diff(travel))
        hidden = ~(used[1:] & used[:-1])
        out.append({"instance_id": row["instance_id"], "primitive": row["primitive"],
                    "true_travel": float(travel.max()), "visible_travel": seen, "frames_used": float(used.mean()),
                    "hidden_motion": float(steps[hidden].sum() / steps.sum()) if steps.sum() > 0 else 0.0})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("release", type=Path)
    p.add_argument("config", help="a T5 config, e.g. t5_aloha")
    args = p.parse_args(argv)
    rows = measure(args.release / args.config)
    print(f"{'instance':<20} {'primitive':<10} {'true travel':>11} {'visible travel':>14} {'frames used':>11} "
          f"{'motion hidden':>13}   (travel: px per 128 px of frame height)")
    for r in rows:
        print(f"{r['instance_id']:<20} {r['primitive']:<10} {r['true_travel']:>11.1f} {r['visible_travel']:>14.1f} "
              f"{r['frames_used']:>11.0%} {r['hidden_motion']:>13.0%}")
    mostly = sum(r["hidden_motion"] >= 0.5 for r in rows)
    print(f"{mostly} of {len(rows)} references move their object mostly while it is hidden")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
