"""`wsp study t4-negatives`: T4's score on generated-video stand-ins made from each T4 reference with its exact masks
(`wsp_eval.composites`): the evaluated object moving without contact, which must score 0, and the still object
drawn as learned models draw it, which must still pass.

From the middle of the clip on (`START` of its length), with the arm exactly the reference's:
- `shifted`: the object slides `SHIFT` px (per 128 px of frame height) sideways over `RAMP_SECONDS`, then rests;
- `faded`: the object fades out over `RAMP_SECONDS` and is gone;
- `carried`: the object follows the hand (the distal arm's centroid; on two arms the hand nearest the object) from
  then on, as a model draws a grasp that never happened (only where that hand travels more than T4's 10 px);
- `smeared`: the object drifts `SHIFT` / 2 px while it smears out (a Gaussian growing to `SMEAR` px).
Positive controls: `oracle`, `object_blur` (the still object blurred by 1.5 px per 128), `noise` (the calibration
baseline's σ 10 grey levels on every frame).
Each clip is scored as a submission's (`wsp_eval.suites.t4.score_seed`); reported per platform and type: the mean
and the share of clips that pass (score 100).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval import composites as cp
from wsp_eval.baselines import NOISE_SIGMA
from wsp_eval.release_format import INSTANCES, split_config
from wsp_eval.studies import run_negatives
from wsp_eval.suites import t4
from wsp_eval.suites.reference import InstanceReference
from wsp_eval.tracking import MOTION_MAX, SCORING_SIZE, nearest_hand

START = 0.5  # the share of the clip before the object starts doing what it must not
RAMP_SECONDS = 1.0
SHIFT = 12.0  # px per 128 px of frame height (T4 fails a displacement above 5 px at 128², 10 px at 256²)
SMEAR = 4.0  # px per 128 px: the smear's final Gaussian σ
OBJECT_BLUR = 1.5  # px per 128 px
NOISE_SEED = 0
POSITIVES = ("oracle", "object_blur", "noise")
NEGATIVES = ("shifted", "faded", "carried", "smeared")


class Clip:
    """One T4 reference: frames, robot and distal-arm masks, the evaluated object's mask, fps."""

    def __init__(self, ref: InstanceReference):
        self.frames = ref.frames("reference")
        labels = ref.masks("reference")
        self.robot, self.hand = labels > 0, labels == 2
        self.obj = ref.object_masks("reference") == int(ref.row["evaluated_object_index"]) + 1
        self.fps = ref.fps
        self.n = len(self.frames)
        self.scale = self.frames.shape[1] / 128
        self.start = int(START * self.n)
        hands = ref.row.get("hand_pixels_256")
        self.hands = None if hands is None else np.asarray(hands, np.float64)

    def ramp(self) -> np.ndarray:
        """0 before `start`, rising linearly to 1 over RAMP_SECONDS, then 1."""
        return np.clip((np.arange(self.n) - self.start) / max(RAMP_SECONDS * self.fps, 1), 0.0, 1.0)

    def shifted_by(self, shifts: np.ndarray) -> np.ndarray:
        return cp.relayer(self.frames, self.obj, self.robot, np.arange(self.n), shifts)


def _nearest_hand(c: Clip) -> np.ndarray:
    """The distal-arm mask of the hand nearest the object at `start` (a two-arm robot's pixels go to the nearer
    frame-0 hand pixel); the whole label-2 mask on a one-arm robot."""
    if c.hands is None or not c.hand.any():
        return c.hand
    h, w = c.hand.shape[1:]
    hands = (c.hands + 0.5) * np.array([w, h]) / SCORING_SIZE - 0.5
    ys, xs = np.mgrid[:h, :w]
    owner = nearest_hand(np.stack([xs.ravel(), ys.ravel()], -1), hands).reshape(h, w)
    near = int(np.linalg.norm(hands - cp.centroids(c.obj)[c.start], axis=1).argmin())
    return c.hand & (owner == near)[None]


def _carried(c: Clip) -> np.ndarray | None:
    hand_mask = _nearest_hand(c)
    hand = cp.centroids(hand_mask) if hand_mask.any() else np.zeros((c.n, 2))
    follow = hand - hand[c.start]
    follow[: c.start] = 0
    if np.linalg.norm(follow, axis=1).max() * SCORING_SIZE / c.frames.shape[1] <= MOTION_MAX:
        return None  # the hand stays within T4's tolerance: carrying the object with it is no negative
    return c.shifted_by(follow)


def _smeared(c: Clip) -> np.ndarray:
    drift = np.zeros((c.n, 2))
    drift[:, 0] = 0.5 * SHIFT * c.scale * c.ramp()
    moved = c.shifted_by(drift)
    out = moved.copy()
    for t, r in enumerate(c.ramp()):
        if r <= 0:
            continue
        m = np.roll(c.obj[t], int(round(drift[t, 0])), axis=1)
        area = cv2.dilate(m.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & ~c.robot[t]
        out[t][area] = cv2.GaussianBlur(moved[t], (0, 0), max(0.3, SMEAR * c.scale * r))[area]
    return out


# None: the variant does not apply to the clip
VARIANTS: dict[str, Callable[[Clip], np.ndarray | None]] = {
    "oracle": lambda c: c.frames,
    "object_blur": lambda c: cp.blurred_region(c.frames, c.obj & ~c.robot, OBJECT_BLUR * c.scale),
    "noise": lambda c: cp.noisy(c.frames, NOISE_SIGMA, NOISE_SEED),
    "shifted": lambda c: c.shifted_by(np.stack([SHIFT * c.scale * c.ramp(), np.zeros(c.n)], axis=1)),
    "faded": lambda c: cp.faded(c.frames, c.obj, c.robot, c.start, int(RAMP_SECONDS * c.fps)),
    "carried": _carried,
    "smeared": _smeared,
}


def score_clips(release: Path, config: str, backends, limit: int | None = None, progress=None) -> list[dict]:
    rows = pq.read_table(release / config / INSTANCES).to_pylist()[:limit]
    out = []
    for row in rows:
        ref = InstanceReference(release / config, row)
        clip, prepared = Clip(ref), t4.prepare(ref, backends)
        for name, make in VARIANTS.items():
            if (frames := make(clip)) is None:
                continue
            score, detail = t4.score_seed(prepared, {"reference": (frames, clip.fps)}, backends)
            out.append({"config": config, "instance_id": row["instance_id"], "kind": row["kind"], "variant": name,
                        "score": float(score),
                        **{k: detail[k] for k in ("displacement", "gate_passed", "tracked", "presence")}})
        if progress:
            progress()
    return out


def summarise(records: list[dict]) -> dict:
    out: dict[str, dict] = {}
    for platform in sorted({split_config(r["config"])[1] for r in records}):
        rows = {}
        for name in VARIANTS:
            recs = [r for r in records if split_config(r["config"])[1] == platform and r["variant"] == name]
            if not recs:
                continue
            s = np.array([r["score"] for r in recs])
            rows[name] = {"n": len(recs), "mean": float(s.mean()), "passed": float(100 * (s >= 50).mean()),
                          "negative": name in NEGATIVES}
        out[platform] = {"variants": rows,
                         "goal_met": all(v["mean"] == 0.0 for v in rows.values() if v["negative"])}
    return out


def markdown(summary: dict) -> str:
    lines = ["T4 on generated-video stand-ins (negatives must score 0; positives should pass)", ""]
    for platform, p in summary.items():
        lines += [f"## {platform}", "", "| clip | n | mean | passed % |", "|---|---:|---:|---:|"]
        lines += [f"| {k} | {v['n']} | {v['mean']:.1f} | {v['passed']:.1f} |" for k, v in p["variants"].items()]
        lines += ["", f"Every negative type scores 0: {'yes' if p['goal_met'] else 'NO'}", ""]
    return "\n".join(lines)


def run(release: Path, out: Path, *, configs: list[str] | None = None, limit: int | None = None,
        progress: bool = True) -> dict:
    """Score every variant of up to `limit` instances of each T4 config; write the study's OUTPUTS."""
    summary, _ = run_negatives(release, out, "t4", t4.NEEDS, score_clips, summarise, markdown,
                               configs=configs, limit=limit, progress=progress)
    return summary


OUTPUTS = ("t4_negatives.md", "t4_negatives.json")
