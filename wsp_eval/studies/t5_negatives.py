"""`wsp study t5-negatives`: T5's scores on generated-video stand-ins a faithful model would never produce, made from
each T5 reference with its exact object and robot masks (`wsp_eval.composites`), beside positive controls that keep
the object's motion.

Negatives (the arm is the reference's in each but `static`; each also with the arm blurred, "+ arm blur"):
- `static`: frame 0 held (the calibration baseline); `frozen`: the object stays as in frame 0 while the arm moves; `erased`: the object inpainted away;
- `early` / `late`: the object's own motion `SHIFT_SECONDS` ahead of / behind the reference's (frame t shows the
  object as at t ± shift);
- `reversed`: the object displaced against the reference's displacement (c₀ − (c_t − c₀), image centroid c);
  `scaled`: displaced `SCALE` of the reference's way; `teleport`: still until the reference's displacement reaches
  half its maximum, then at its final place at once;
- `other_object`: the evaluated object frozen, and another object (the scene's, else a copy of the evaluated one at
  the mirrored position) moved by the reference's displacement.
Positive controls: `oracle` (the reference), `blur_1px` (a 1 px Gaussian per 128 px of frame height), `noise`
(the calibration baseline's transform), `lossless` (the reference through the contract's lossless encoding and back);
reported beside them, `blur` (the calibration baseline's 2 px blur, which smears ManiSkill's 5 px cubes into the
gripper) and `arm_blur` (only the arm smeared, over a margin that reaches a grasped object).
A negative counts only where its object is visibly different from the reference's (`judge_data.visibly_different`:
a clip no one could tell from the reference by eye is no negative); an arm-blurred negative counts where the same
negative unblurred does, since the blurred arm alone would make every clip differ. The report says how many did not.

Every clip is scored exactly as a submission's (`wsp_eval.suites.t5.score_seed`): the T5 score, its object-response
fidelity, the arm's RMFA, and the paper-protocol label judge ("primitive recognised"). Reported per platform and
type: the mean and the share of clips scoring ≥ `PASS`, for the T5 score and for the label judge.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval import composites as cp
from wsp_eval.baselines import NOISE_SIGMA, blur
from wsp_eval.judge_data import visibly_different
from wsp_eval.release_format import INSTANCES, split_config
from wsp_eval.studies import run_negatives
from wsp_eval.suites import t5
from wsp_eval.suites.reference import InstanceReference

SHIFT_SECONDS = 1.0  # `early` / `late`: the object's motion moved by this much
SCALE = 0.3  # `scaled`: the share of the reference displacement kept
ARM_BLUR_SIGMA = 1.5  # px per 128 px of frame height: how learned models smear the arm
PASS = 50.0  # a clip scoring at least this counts as credited
NOISE_SEED = 0
POSITIVES = ("oracle", "blur", "blur_1px", "noise", "arm_blur", "lossless")
NEGATIVES = ("static", "frozen", "erased", "early", "late", "reversed", "scaled", "teleport", "other_object")
GOAL_MEAN, GOAL_SHARE = 10.0, 5.0  # every negative type: mean ≤ 10 and share ≥ PASS at most 5 %


class Clip:
    """One T5 reference with what the composites need: frames, robot and object masks, fps."""

    def __init__(self, ref: InstanceReference):
        self.ref = ref
        self.frames = ref.frames("reference")
        self.robot = ref.masks("reference") > 0
        labels = ref.object_masks("reference")
        self.label = int(ref.row["evaluated_index"]) + 1
        self.obj = labels == self.label
        others = (labels > 0) & ~self.obj
        self.other = others if others[0].any() else None
        self.fps = ref.fps
        self.c = cp.centroids(self.obj)

    @property
    def n(self) -> int:
        return len(self.frames)

    def layered(self, source: np.ndarray, shifts: np.ndarray) -> np.ndarray:
        return cp.relayer(self.frames, self.obj, self.robot, source, shifts)

    def still(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(self.n, dtype=int), np.zeros((self.n, 2))

    def displacement(self) -> np.ndarray:
        return self.c - self.c[0]


def _shifted_source(clip: Clip, frames: int) -> np.ndarray:
    return np.clip(np.arange(clip.n) + frames, 0, clip.n - 1)


def _teleport(clip: Clip) -> np.ndarray:
    d = np.linalg.norm(clip.displacement(), axis=1)
    jump = int(np.argmax(d >= 0.5 * d.max())) if d.max() > 0 else clip.n // 2
    return np.where(np.arange(clip.n) < jump, 0, clip.n - 1)


def _other_object(clip: Clip) -> np.ndarray:
    """The evaluated object frozen; another object moved by the evaluated object's reference displacement."""
    d = clip.displacement()
    if clip.other is not None:
        mover, source = clip.other[0], clip.frames[0]
        plate = cp.erase(clip.frames, clip.obj | clip.other)
    else:  # a copy of the evaluated object at the mirrored position moves instead
        h, w = clip.obj.shape[1:]
        cx, cy = clip.c[0]
        offset = (w - 1 - 2 * cx, 0.0) if abs(w - 1 - 2 * cx) >= 0.25 * w else (0.0, h - 1 - 2 * cy)
        mover = np.zeros_like(clip.obj[0])
        ys, xs = np.nonzero(clip.obj[0])
        ty, tx = ys + int(round(offset[1])), xs + int(round(offset[0]))
        keep = (ty >= 0) & (ty < h) & (tx >= 0) & (tx < w)
        mover[ty[keep], tx[keep]] = True
        source = cp.paste(clip.frames[0], clip.frames[0], clip.obj[0], offset)
        plate = cp.erase(clip.frames, clip.obj)
    out = np.stack([cp.paste(cp.paste(plate[t], clip.frames[0], clip.obj[0], (0, 0)), source, mover, d[t])
                    for t in range(clip.n)])
    return cp.with_robot(out, clip.frames, clip.robot)


def _lossless(clip: Clip) -> np.ndarray:
    from wsp_eval.video import read_video, write_video

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "clip.mp4"
        write_video(path, clip.frames, clip.fps)
        return read_video(path)[0]


def _arm_blur(clip: Clip, frames: np.ndarray) -> np.ndarray:
    return cp.blurred_region(frames, clip.robot, ARM_BLUR_SIGMA * clip.frames.shape[1] / 128)


VARIANTS: dict[str, Callable[[Clip], np.ndarray]] = {
    "oracle": lambda c: c.frames,
    "blur": lambda c: blur(c.frames),
    "blur_1px": lambda c: cp.blurred(c.frames, c.frames.shape[1] / 128),
    "noise": lambda c: cp.noisy(c.frames, NOISE_SIGMA, NOISE_SEED),
    "arm_blur": lambda c: _arm_blur(c, c.frames),
    "lossless": _lossless,
    "static": lambda c: np.repeat(c.frames[:1], c.n, axis=0),
    "frozen": lambda c: c.layered(*c.still()),
    "erased": lambda c: cp.with_robot(cp.erase(c.frames, c.obj), c.frames, c.robot),
    "early": lambda c: c.layered(_shifted_source(c, int(round(SHIFT_SECONDS * c.fps))), np.zeros((c.n, 2))),
    "late": lambda c: c.layered(_shifted_source(c, -int(round(SHIFT_SECONDS * c.fps))), np.zeros((c.n, 2))),
    "reversed": lambda c: c.layered(np.arange(c.n), -2.0 * c.displacement()),
    "scaled": lambda c: c.layered(np.arange(c.n), (SCALE - 1.0) * c.displacement()),
    "teleport": lambda c: c.layered(_teleport(c), np.zeros((c.n, 2))),
    "other_object": _other_object,
}


def variant_frames(clip: Clip, name: str) -> np.ndarray:
    """The frames of variant `name` (a key of VARIANTS, or a negative with the suffix "+arm_blur")."""
    base, _, blurred = name.partition("+")
    frames = VARIANTS[base](clip)
    return _arm_blur(clip, frames) if blurred else frames


def variant_names() -> list[str]:
    return [*POSITIVES, *NEGATIVES, *(f"{n}+arm_blur" for n in NEGATIVES)]


def score_clips(release: Path, config: str, backends, limit: int | None = None, progress=None) -> list[dict]:
    """One record per (instance, variant): the T5 score, its parts and the label judge's verdict."""
    rows = pq.read_table(release / config / INSTANCES).to_pylist()[:limit]
    out = []
    for row in rows:
        ref = InstanceReference(release / config, row)
        clip, prepared = Clip(ref), t5.prepare(ref, backends)
        visible: dict[str, bool] = {}
        for name in variant_names():
            base, _, blurred = name.partition("+")
            frames = variant_frames(clip, name)
            visible[name] = visible[base] if blurred else (name in POSITIVES or visibly_different(frames, clip.frames))
            score, detail = t5.score_seed(prepared, {"reference": (frames, clip.fps)}, backends)
            out.append({"config": config, "instance_id": row["instance_id"], "primitive": row["primitive"],
                        "variant": name, "score": round(float(score), 3),
                        "visible": visible[name],
                        **{k: detail[k] for k in ("object_fidelity", "object_error", "object_blur", "object_arm_blur",
                                                  "object_vacated", "object_turned", "object_windowed",
                                                  "object_stepped", "arm_rmfa", "recognised", "label")}})
        if progress:
            progress()
    return out


def summarise(records: list[dict]) -> dict:
    """Per platform and variant: n, mean and share ≥ PASS of the T5 score and of the label judge; and whether every
    negative type meets the goal."""
    out: dict[str, dict] = {}
    for platform in sorted({split_config(r["config"])[1] for r in records}):
        rows = {}
        for name in variant_names():
            alike = [r for r in records if split_config(r["config"])[1] == platform and r["variant"] == name]
            recs = [r for r in alike if r["visible"]]
            if not recs:
                continue
            s = np.array([r["score"] for r in recs])
            j = np.array([r["recognised"] for r in recs])
            rows[name] = {"n": len(recs), "not_visible": len(alike) - len(recs), "t5_mean": float(s.mean()), "t5_share": float(100 * (s >= PASS).mean()),
                          "judge_mean": float(j.mean()), "judge_share": float(100 * (j >= PASS).mean()),
                          "negative": name not in POSITIVES}
        negatives = [v for v in rows.values() if v["negative"]]
        out[platform] = {"variants": rows, "goal_met": all(v["t5_mean"] <= GOAL_MEAN and v["t5_share"] <= GOAL_SHARE
                                                            for v in negatives),
                         "judge_false_accept": float(np.mean([v["judge_share"] for v in negatives]))
                         if negatives else None}
    return out


def markdown(summary: dict) -> str:
    lines = [f"T5 on generated-video negatives (credited: score ≥ {PASS:g}; goal per negative type: mean ≤ "
             f"{GOAL_MEAN:g}, credited ≤ {GOAL_SHARE:g} %)", ""]
    for platform, p in summary.items():
        lines += [f"## {platform}", "", "| clip | n | not visible | T5 mean | T5 credited % | judge mean | "
                  "judge credited % |", "|---|---:|---:|---:|---:|---:|---:|"]
        for name, v in p["variants"].items():
            lines.append(f"| {name} | {v['n']} | {v['not_visible']} | {v['t5_mean']:.1f} | {v['t5_share']:.1f} | {v['judge_mean']:.1f} | "
                         f"{v['judge_share']:.1f} |")
        lines += ["", f"Goal met: {'yes' if p['goal_met'] else 'NO'}; the label judge credits "
                      f"{p['judge_false_accept']:.1f} % of the negatives.", ""]
    return "\n".join(lines)


def plot(summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(summary), 1, figsize=(11, 3.2 * len(summary)), squeeze=False)
    for ax, (platform, p) in zip(axes[:, 0], summary.items()):
        names = list(p["variants"])
        x = np.arange(len(names))
        ax.bar(x - 0.2, [p["variants"][n]["t5_mean"] for n in names], 0.4, label="T5 (object-response fidelity)")
        ax.bar(x + 0.2, [p["variants"][n]["judge_mean"] for n in names], 0.4, label="label judge (paper protocol)")
        ax.axhline(GOAL_MEAN, color="k", lw=0.8, ls=":")
        ax.set_xticks(x, names, rotation=60, ha="right", fontsize=8)
        ax.set_ylim(0, 100)
        ax.set_ylabel("mean score")
        ax.set_title(f"{platform}: positives (left) and negatives")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=2, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(release: Path, out: Path, *, configs: list[str] | None = None, limit: int | None = None,
        progress: bool = True) -> dict:
    """Score every variant of up to `limit` instances of each T5 config; write the study's OUTPUTS."""
    summary, _ = run_negatives(release, out, "t5", t5.NEEDS, score_clips, summarise, markdown,
                               configs=configs, limit=limit, progress=progress)
    plot(summary, Path(out) / "t5_negatives.png")
    return summary


OUTPUTS = ("t5_negatives.md", "t5_negatives.json", "t5_negatives.png")
