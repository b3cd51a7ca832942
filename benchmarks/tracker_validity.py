"""The T4 tracker against simulator ground truth (docs/validity.md, T4 tracker): the evaluated object's true image
position in every frame is its stored pose projected through the stored camera, so what the tracker reports can
be checked on references whose object moves (T5) and on references whose object stays (T4).

    .venv/bin/python benchmarks/tracker_validity.py RELEASE [RELEASE ...] [--out FILE.json]

Per platform:
- moving objects (T5 references, and T4 source rollouts — the unperturbed expert, which often grasps and
  carries the evaluated object — whose true displacement exceeds 10 px in the 256² scoring frame): detection =
  the tracker's d > 10 px (what T4 uses), and d > 10 px *or* a visible fraction under half the frames (T4's
  tracking-failure rule, with the reference's own visibility taken as 1);
- still objects: false alarm = d > 10 px, on T4 references (the issue's still set: the object never moves) and
  on any rollout whose true displacement is ≤ 10 px (which adds T5 references whose object moved 5–10 px: there
  the tracker's error of a few px decides);
- each row split by the default tracker's stage on that object (colour region, or LK where the colour is not
  distinct; `wsp_eval.tracking.colour_model`);
- centroid error: per visible frame, |tracked displacement − true displacement| (px; both from frame 0, so the
  grid centroid's offset from the projected centre cancels), median and 90th percentile over frames;
- the motion gate on a static video (frame 0 repeated): g ≥ 0.5·g_ref would pass it (must never happen);
- T4 as it scores a model that carries the object away: a false-contact instance's source rollout (the expert,
  gripper closing, same arm path as the reference, so the same first frame and gate) scored as a submission
  against that instance with the full rule (`t4_score`: gate, tracking failure, d ≤ 10). Where the expert
  moved the object more than 10 px it must score 0; where it did not, 100.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval.reference import episodes, reference_frames
from wsp_eval.release_format import INSTANCES, OBJECT_POSES_KEY, RELEASE_JSON, split_config
from wsp_eval.suites.reference import InstanceReference
from wsp_eval.tracking import (GATE_RATIO, MOTION_MAX, TRACKED_RATIO, colour_model, frame_size, motion_gate,
                               object_path, project, scoring_video, t4_score)

POSES = OBJECT_POSES_KEY
IN_VIEW_MARGIN = 12  # px: another object counts when its frame-0 position is this far inside the frame


def object_poses(config_dir: Path, episode_index: int) -> np.ndarray:
    """(T, MAX_OBJECTS, 7) poses of one episode."""
    ep = episodes(config_dir)[episode_index]
    lo, hi = ep["dataset_from_index"], ep["dataset_to_index"]
    rows = []
    for path in sorted((config_dir / "data").glob("*/*.parquet")):
        t = pq.read_table(path, columns=["index", POSES], filters=[("index", ">=", lo), ("index", "<", hi)])
        rows += t.sort_by("index").column(POSES).to_pylist()
    return np.asarray(rows, np.float64).reshape(len(rows), -1, 7)


def measure(config_dir: Path, row: dict, evaluated: int, role: str = "reference") -> list[dict]:
    """The tracker on one rollout of an instance (`role`: reference, or the unperturbed source rollout): the
    evaluated object, and on references every other object in view (never selected by the build, unlike the
    evaluated one, which the build keeps only when the tracker passes it: an unbiased false-alarm sample)."""
    ref = InstanceReference(config_dir, row)
    episode = ref.episode("reference") if role == "reference" else int(row["source_episode_index"])
    frames = ref.frames("reference") if role == "reference" else reference_frames(config_dir, episode)
    video = scoring_video(frames)
    mask0 = ref.masks("reference")[0]
    all_poses = object_poses(config_dir, episode)
    out = []
    for k in range(all_poses.shape[1]) if role == "reference" else (evaluated,):
        poses = all_poses[:, k]
        if not np.linalg.norm(poses[0, 3:]) > 0:  # an unused slot (all zeros): no such object in this rollout
            continue
        try:
            truth = np.stack([project(p[:3], row["camera_intrinsic"], row["camera_extrinsic"],
                                      frame_size(frames[0])) for p in poses])
        except ValueError:  # behind the camera
            continue
        if k != evaluated and not ((truth[0] >= IN_VIEW_MARGIN) & (truth[0] <= 255 - IN_VIEW_MARGIN)).all():
            continue
        # The query sits on the object's frame-0 position in *this* rollout: a spatial-proximity reference moved
        # the object, so in its source rollout the object starts elsewhere than `object_pixel_256`.
        query = np.asarray(row["object_pixel_256"]) if role == "reference" and k == evaluated else truth[0]
        tracks, path = object_path(video, query, mask0)
        visible = tracks.visible.any(axis=1)
        err = np.linalg.norm((path - path[0]) - (truth - truth[0]), axis=1)[visible]
        rec = {"instance_id": row["instance_id"], "role": role, "task": row["task"],
               "object": "evaluated" if k == evaluated else "other",
               "true_d": float(np.linalg.norm(truth - truth[0], axis=1).max()),
               "d": float(np.linalg.norm(path - path[0], axis=1).max()), "visible_fraction": float(visible.mean()),
               "errors": err.tolist(), "stage": "lk" if colour_model(video.rgb[0], query, mask0) is None else "colour"}
        if k == evaluated and role == "source" and row.get("kind") == "false_contact":
            visible_ref = object_path(scoring_video(ref.frames("reference")), np.asarray(row["object_pixel_256"]),
                                      mask0)[0]
            s = t4_score(frames, np.asarray(row["object_pixel_256"]), mask0, row["gate_reference"],
                         float(visible_ref.visible.any(axis=1).mean()))
            rec["t4_as_submission"] = s.score
        if k == evaluated and "gate_reference" in row and role == "reference":
            static = np.repeat(video.grey[:1], len(video.grey), axis=0)
            rec["static_gate_passes"] = bool(motion_gate(static, mask0)
                                             >= GATE_RATIO * row["gate_reference"])
        out.append(rec)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("releases", type=Path, nargs="+")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    import cv2

    cv2.setNumThreads(1)
    records: dict[str, list[dict]] = defaultdict(list)
    for release in args.releases:
        for config in sorted(json.loads((release / RELEASE_JSON).read_text())["configs"]):
            suite, platform = split_config(config)
            if suite not in ("t4", "t5"):
                continue
            for row in pq.read_table(release / config / INSTANCES).to_pylist():
                ev = row["evaluated_index"] if suite == "t5" else row["evaluated_object_index"]
                roles = ("reference", "source") if suite == "t4" and row.get("source_episode_index") is not None \
                    else ("reference",)  # a T4 source rollout: the expert, which often carries the object away
                for role in roles:
                    records[platform] += [{"suite": suite, **r} for r in measure(release / config, row, int(ev), role)]
    print(table(records))
    if args.out:
        args.out.write_text(json.dumps(records, indent=1))


def table(records: dict[str, list[dict]]) -> str:
    """One row per platform, object class (the evaluated object; other objects in view of a reference) and
    tracking stage (colour region, LK), plus the class's total."""
    lines = ["| platform | objects | stage | moving (true d > 10 px) | detected: d > 10 | detected: d > 10 or lost "
             "| clearly moving (true d > 20): detected or lost | still: T4 references | false alarms: d > 10 "
             "| still: any true d ≤ 10 | false alarms: d > 10 | centroid error median / p90 px "
             "| static video passes the gate | carried away, scored as a T4 submission: 0 | not carried: 100 |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    groups = {}
    for platform, rs in records.items():
        for cls in ("evaluated", "other"):
            for stage in ("colour", "lk", "all"):
                groups[platform, cls, stage] = [r for r in rs if r["object"] == cls and stage in (r["stage"], "all")]
    for (platform, cls, stage), recs in sorted(groups.items()):
        if not recs:
            continue
        moving = [r for r in recs if r["true_d"] > MOTION_MAX]
        still = [r for r in recs if r["true_d"] <= MOTION_MAX]
        t4_still = [r for r in still if r["suite"] == "t4" and r["role"] == "reference"]
        det = sum(r["d"] > MOTION_MAX for r in moving)
        det_lost = sum(r["d"] > MOTION_MAX or r["visible_fraction"] < TRACKED_RATIO for r in moving)
        clear = [r["d"] > MOTION_MAX or r["visible_fraction"] < TRACKED_RATIO for r in moving if r["true_d"] > 2 * MOTION_MAX]
        errs = np.concatenate([r["errors"] for r in recs if r["errors"]] or [np.zeros(1)])
        gates = [r["static_gate_passes"] for r in recs if "static_gate_passes" in r]
        carried = [r["t4_as_submission"] == 0 for r in recs if "t4_as_submission" in r and r["true_d"] > MOTION_MAX]
        kept = [r["t4_as_submission"] == 100 for r in recs if "t4_as_submission" in r and r["true_d"] <= MOTION_MAX]
        pct = lambda k, n: f"{k} ({100 * k / max(n, 1):.0f} %)"  # noqa: E731
        fa = lambda rs: pct(sum(r["d"] > MOTION_MAX for r in rs), len(rs))  # noqa: E731
        lines.append(f"| {platform} | {cls} | {stage} | {len(moving)} | {pct(det, len(moving))} "
                     f"| {pct(det_lost, len(moving))} | {pct(sum(clear), len(clear))} of {len(clear)} "
                     f"| {len(t4_still)} | {fa(t4_still)} | {len(still)} | {fa(still)} "
                     f"| {np.median(errs):.1f} / {np.percentile(errs, 90):.1f} | {sum(gates)} / {len(gates)} "
                     f"| {sum(carried)} / {len(carried)} | {sum(kept)} / {len(kept)} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
