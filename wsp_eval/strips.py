"""Frame strips of the worst-scoring instances, for the report: what a failure looks like.

Per scored config, the `WORST` lowest-scoring instances (their lowest-scoring seed): `COLUMNS` frames spread over
the clip, the generated video above its reference, the evaluated object's frame-0 position ringed on both for
T4 and T5 and, on T4's generated row, the tracked object centroid's path so far; written as
`strips/<config>/<n>.png` beside the report, with the evidence that decided the score (T1 r against r*, T2/T3
RMFA per 2 s window, T4 displacement, gate, tracking and presence, T5 the object's fidelity, the arm's RMFA and
the label judge's verdict).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from wsp_eval.object_presence import KEEP
from wsp_eval.reference import reference_frames, reference_masks
from wsp_eval.submission import Expected
from wsp_eval.video import VideoError, read_video

WORST = 3
COLUMNS = 6
TILE = 112  # px per frame in the strip
STRIPS_DIR = "strips"


def evidence(suite: str, seed: dict, row: dict) -> str:
    """What decided one seed's score, in words."""
    s = seed["score"]
    if suite == "t4":
        return (f"S {s:.0f}: object moved d = {seed.get('displacement', 0):.1f} px (pass ≤ 10); arm gate "
                f"{'passed' if seed.get('gate_passed') else 'failed'} ({seed.get('gate', 0):.1f} px); object "
                f"{'tracked' if seed.get('tracked', True) else 'lost'} in {seed.get('visible_fraction', 0):.0%} of "
                f"frames; presence {seed.get('presence', 1.0):.2f} (pass ≥ {KEEP})")
    if suite == "t5":
        return (f"S {s:.0f}: object fidelity {seed.get('object_fidelity', 0):.0f} (relative error x "
                f"{seed.get('object_error', 0):.2f}; at the place it left {seed.get('object_vacated', 0):.2f}, "
                f"windowed {seed.get('object_windowed', 0):.2f}, frame to frame {seed.get('object_stepped', 0):.2f}), "
                f"arm RMFA {seed.get('arm_rmfa', 0):.0f}; "
                f"label judge (reported beside): judged {seed.get('label') or 'unreadable'} "
                f"(intended {row.get('primitive')})")
    if suite in ("t2", "t3"):
        windows = ", ".join("–" if w is None else f"{w:.0f}" for w in seed.get("windows") or [])
        return f"RMFA {s:.1f} over the first {seed.get('common_seconds', 0):.1f} s; per 2 s window: {windows or '–'}"
    if suite == "t1" and "r_star" in seed:
        if seed.get("r") is None:
            return f"S {s:.1f}: the large perturbation left no trace in the generated videos (r undefined)"
        return f"S {s:.1f}: r = {seed['r']:.3f} against the simulator's r* = {seed['r_star']:.3f}"
    return f"S {s:.1f}"


def _tiles(frames: np.ndarray, mark: tuple[float, float] | None, path: np.ndarray | None = None) -> np.ndarray:
    """COLUMNS frames side by side; `mark` (256² scoring frame) ringed; `path` (T, 2), the tracked centroid in
    the scoring frame, drawn up to each tile's frame."""
    picks = np.linspace(0, len(frames) - 1, COLUMNS).round().astype(int)
    scale = TILE / 256
    tiles = []
    for i in picks:
        tile = np.ascontiguousarray(cv2.resize(frames[i], (TILE, TILE), interpolation=cv2.INTER_AREA))
        if mark is not None:
            center = (int(round(mark[0] * scale)), int(round(mark[1] * scale)))
            cv2.circle(tile, center, 7, (255, 40, 40), 1, cv2.LINE_AA)
        if path is not None:
            pts = np.round(path[: min(i, len(path) - 1) + 1] * scale).astype(np.int32)
            cv2.polylines(tile, [pts.reshape(-1, 1, 2)], False, (40, 220, 255), 1, cv2.LINE_AA)
            cv2.circle(tile, tuple(int(v) for v in pts[-1]), 2, (40, 220, 255), -1)
        tiles.append(tile)
    return np.hstack(tiles)


def tracked_path(frames: np.ndarray, object_px, robot_mask0: np.ndarray) -> np.ndarray:
    """T4's object centroid through a video (`wsp_eval.tracking`, default tracker), scoring-frame pixels."""
    from wsp_eval.tracking import object_path, scoring_video

    return object_path(scoring_video(frames), np.asarray(object_px, float), robot_mask0)[1]


def write_strips(records: list[dict], rows: dict[str, list[dict]], release: Path, submission: Path,
                 out: Path) -> list[dict]:
    """Write the strips (module docstring); their entries for the report (path relative to `out`)."""
    entries = []
    for config, config_rows in rows.items():
        by_id = {r["instance_id"]: r for r in config_rows}
        recs = [r for r in records if r["config"] == config and any(not s.get("missing") for s in r["seeds"])]
        for n, rec in enumerate(sorted(recs, key=lambda r: (r["score"], r["instance_id"]))[:WORST]):
            row = by_id[rec["instance_id"]]
            seed = min((s for s in rec["seeds"] if not s.get("missing")), key=lambda s: s["score"])
            k = len(row["roles"]) - 1  # the last role: T1's large perturbation, the reference elsewhere
            exp = Expected(config, row["episode_ids"][k], seed["seed"], row["num_frames"][k], row["fps"])
            try:
                generated, _ = read_video(submission / exp.relpath, max_frames=exp.num_frames)
            except VideoError:
                continue
            reference = reference_frames(release / config, row["episode_indices"][k])
            mark = row.get("object_pixel_256") if rec["suite"] in ("t4", "t5") else None
            path = (tracked_path(generated, mark, reference_masks(release / config, row["episode_indices"][k])[0])
                    if rec["suite"] == "t4" else None)
            image = np.vstack([_tiles(generated, mark, path), np.full((4, COLUMNS * TILE, 3), 255, np.uint8),
                               _tiles(reference, mark)])
            file = Path(STRIPS_DIR) / config / f"{n + 1}.png"
            (out / file).parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(out / file), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
            entries.append({"config": config, "instance_id": rec["instance_id"], "task": rec["task"],
                            "seed": seed["seed"], "score": seed["score"], "role": row["roles"][k],
                            "evidence": evidence(rec["suite"], seed, row), "image": file.as_posix()})
    return entries
