"""RMFA under controlled visual corruption (the paper's §"RMFA Sensitivity in Task 2").

For each of N T2 references (the first N instances of the config, by instance id), the reference video is
corrupted and scored by RMFA against itself uncorrupted, exactly as a submission would be (`wsp_eval.suites.t2`):

- *where*: inside the robot mask (label > 0) of each frame, or in an **equal-area region outside it**: the
  `area_t` non-robot pixels nearest to an anchor point drawn once per trajectory (seeded) among the pixels at
  least `MARGIN_PX` from the robot in every frame — a compact blob, the same size as the robot in every frame,
  that never touches it;
- *what*, at matched strength levels 1–4: Gaussian blur (σ = `SIGMAS`, px of the stored 128² frame) or
  texture removal (each pixel moved a fraction α = `ALPHAS` of the way to the region's mean colour in that
  frame; α = 1 leaves a flat silhouette).

Every other pixel, the timestamps and the action stream are untouched, so each robot/background pair differs
only in where the corruption lands. Reported, per trajectory then bootstrapped over trajectories (95 % paired
CIs, `BOOTSTRAP` resamples, seeded): the RMFA drop from the clean reference (100 by construction up to flow
noise) averaged over both corruptions and all four levels, for the robot region and the background control, and
their paired difference (the excess drop); per corruption and level; and how many trajectories fall
monotonically (RMFA non-increasing as the robot-region strength rises, both corruptions averaged).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval.flow import reference_flows, rmfa_score, video_flows
from wsp_eval.release_format import INSTANCES, load_release
from wsp_eval.studies import StudyError
from wsp_eval.suites.reference import InstanceReference

SIGMAS = (3.0, 6.0, 9.0, 12.0)  # Gaussian blur σ per level, px (the paper's strongest: 12)
ALPHAS = (0.25, 0.5, 0.75, 1.0)  # texture removal α per level (the paper's strongest: 1)
CORRUPTIONS = ("blur", "texture")
REGIONS = ("robot", "background")
MARGIN_PX = 4  # the background region keeps this far from the robot in every frame
BOOTSTRAP = 10_000
PAPER = {"robot": (30.55, 28.35, 32.83), "background": (7.93, 6.99, 8.90), "excess": (22.62, 20.98, 24.35),
         "monotone": (48, 50)}


def background_regions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(T, H, W) bool: per frame, as many non-robot pixels as the robot has, nearest to one anchor drawn among
    the pixels at least MARGIN_PX from the robot in every frame (ties broken by raster order)."""
    robot = masks > 0
    T, H, W = robot.shape
    ever = robot.any(axis=0).astype(np.uint8)
    far = cv2.distanceTransform(1 - ever, cv2.DIST_L2, 3) >= MARGIN_PX
    ys, xs = np.nonzero(far)
    if len(ys) == 0:
        raise StudyError("the robot covers the whole frame: no background region to corrupt")
    k = rng.integers(len(ys))
    yy, xx = np.mgrid[0:H, 0:W]
    dist = np.hypot(yy - ys[k], xx - xs[k]).ravel()
    order = np.lexsort((np.arange(H * W), dist))  # nearest first, raster order among ties
    candidates = order[far.ravel()[order]]
    out = np.zeros_like(robot)
    for t in range(T):
        out[t].flat[candidates[: int(robot[t].sum())]] = True  # equal area unless the background is smaller
    return out


def corrupt(frames: np.ndarray, regions: np.ndarray, corruption: str, level: int) -> np.ndarray:
    """The video with `corruption` at `level` (0-based) applied inside `regions` (T, H, W) only."""
    out = frames.copy()
    for t, (f, r) in enumerate(zip(frames, regions)):
        if not r.any():
            continue
        if corruption == "blur":
            changed = cv2.GaussianBlur(f, (0, 0), SIGMAS[level])
        else:
            mean = f[r].mean(axis=0)
            changed = np.clip(np.rint((1 - ALPHAS[level]) * f + ALPHAS[level] * mean), 0, 255).astype(np.uint8)
        out[t][r] = changed[r]
    return out


@dataclass
class Trajectory:
    """RMFA of one reference: clean, and per (region, corruption) the four levels."""

    instance_id: str
    clean: float
    scores: dict[str, dict[str, list[float]]]

    def drop(self, region: str) -> float:
        return float(np.mean([self.clean - s for c in CORRUPTIONS for s in self.scores[region][c]]))

    def monotone(self) -> bool:
        curve = [self.clean] + list(np.mean([self.scores["robot"][c] for c in CORRUPTIONS], axis=0))
        return bool(all(b <= a + 1e-9 for a, b in zip(curve, curve[1:])))


def _regions(ref: InstanceReference, masks: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng([seed, int(ref.row["instance_id"].rsplit("/", 1)[1])])
    return {"robot": masks > 0, "background": background_regions(masks, rng)}


def study_one(ref: InstanceReference, seed: int, backend=None) -> Trajectory:
    frames, masks, fps = ref.frames("reference"), ref.masks("reference"), ref.fps
    target = reference_flows(frames, masks, fps, None, backend)

    def rmfa(video: np.ndarray) -> float:
        s = rmfa_score(video_flows(video, fps, None, backend), target.flows, target.masks)
        return 0.0 if s is None else s

    where = _regions(ref, masks, seed)
    scores = {r: {c: [rmfa(corrupt(frames, where[r], c, i)) for i in range(len(SIGMAS))] for c in CORRUPTIONS}
              for r in REGIONS}
    return Trajectory(ref.row["instance_id"], rmfa(frames), scores)


def _ci(values: np.ndarray, idx: np.ndarray) -> list[float]:
    means = values[idx].mean(axis=1)
    return [float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))]


def summarise(trajectories: list[Trajectory], seed: int) -> dict:
    """The study's numbers (module docstring): means, paired bootstrap CIs, per-level drops, monotone count."""
    idx = np.random.default_rng(seed).integers(0, len(trajectories), (BOOTSTRAP, len(trajectories)))  # paired
    robot = np.array([t.drop("robot") for t in trajectories])
    background = np.array([t.drop("background") for t in trajectories])
    rows = {}
    for name, v in (("robot", robot), ("background", background), ("excess", robot - background)):
        rows[name] = {"drop": float(v.mean()), "ci95": _ci(v, idx)}
    levels = {r: {c: [float(np.mean([t.clean - t.scores[r][c][i] for t in trajectories])) for i in range(len(SIGMAS))]
                  for c in CORRUPTIONS} for r in REGIONS}
    return {"trajectories": len(trajectories), "clean_rmfa": float(np.mean([t.clean for t in trajectories])),
            "rows": rows, "per_level_drop": levels, "monotone": sum(t.monotone() for t in trajectories),
            "sigmas": list(SIGMAS), "alphas": list(ALPHAS), "paper": PAPER}


def markdown(summary: dict, config: str) -> str:
    n, p = summary["trajectories"], summary["paper"]
    label = {"robot": "Robot-region corruption", "background": "Background control", "excess": "Paired excess drop"}
    lines = [f"RMFA under corruption, `{config}`, {n} references (clean RMFA {summary['clean_rmfa']:.2f})", "",
             "| condition | RMFA drop (ours) | 95 % CI | paper | paper 95 % CI |", "|---|---:|---|---:|---|"]
    for k in ("robot", "background", "excess"):
        r = summary["rows"][k]
        lines.append(f"| {label[k]} | {r['drop']:.2f} | [{r['ci95'][0]:.2f}, {r['ci95'][1]:.2f}] | {p[k][0]:.2f} "
                     f"| [{p[k][1]:.2f}, {p[k][2]:.2f}] |")
    lines += ["", f"Monotone in robot-region strength: {summary['monotone']}/{n} (paper {p['monotone'][0]}/"
              f"{p['monotone'][1]}).", "", "| region | corruption | " + " | ".join(
                  f"level {i + 1} (σ {s:g} / α {a:g})" for i, (s, a) in enumerate(zip(SIGMAS, ALPHAS))) + " |",
              "|---|---|" + "---:|" * len(SIGMAS)]
    for r in REGIONS:
        for c in CORRUPTIONS:
            lines.append(f"| {r} | {c} | " + " | ".join(f"{v:.2f}" for v in summary["per_level_drop"][r][c]) + " |")
    return "\n".join(lines) + "\n"


def example_strip(ref: InstanceReference, trajectory: Trajectory, seed: int, path: Path, columns: int = 6) -> None:
    """A PNG like the paper's figure: rows clean / strongest blur and texture removal in each region, with
    their RMFA, over `columns` frames spread across the clip."""
    frames, masks = ref.frames("reference"), ref.masks("reference")
    where = _regions(ref, masks, seed)
    picks = np.linspace(0, len(frames) - 1, columns).round().astype(int)
    rows = [("clean", frames, trajectory.clean)]
    for r in REGIONS:
        for c in CORRUPTIONS:
            rows.append((f"{c} {r}", corrupt(frames, where[r], c, len(SIGMAS) - 1), trajectory.scores[r][c][-1]))
    side = 160
    out = []
    for name, video, score in rows:
        tiles = [cv2.resize(video[i], (side, side), interpolation=cv2.INTER_NEAREST) for i in picks]
        label = np.full((side, 180, 3), 255, np.uint8)
        cv2.putText(label, name, (6, 70), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(label, f"RMFA {score:.1f}", (6, 95), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        out.append(np.hstack([label] + tiles))
    cv2.imwrite(str(path), cv2.cvtColor(np.vstack(out), cv2.COLOR_RGB2BGR))


def run(release: Path, out: Path, *, config: str | None = None, count: int = 50, seed: int = 0,
        progress: bool = True) -> dict:
    """Study the first `count` T2 references of `config` (default: the release's only or first T2 config); write
    corruption.json, corruption.md and example.png to `out`; resumable (finished trajectories are cached)."""
    from tqdm import tqdm

    configs = sorted(c for c in load_release(release)["configs"] if c.startswith("t2_"))
    if config is None:
        if not configs:
            raise StudyError(f"{release}: no T2 config to study (has {', '.join(load_release(release)['configs'])})")
        config = configs[0]
    elif config not in configs:
        raise StudyError(f"{release}: no config {config!r}; T2 configs here: {', '.join(configs) or 'none'}")
    rows = sorted(pq.read_table(release / config / INSTANCES).to_pylist(), key=lambda r: r["instance_id"])[:count]
    if len(rows) < 2:
        raise StudyError(f"{release / config}: {len(rows)} instance(s); the bootstrap needs at least 2")
    out.mkdir(parents=True, exist_ok=True)
    cache_path = out / "trajectories.jsonl"
    done = {}
    if cache_path.exists():
        for line in cache_path.read_text().splitlines():
            t = json.loads(line)
            done[t["instance_id"]] = Trajectory(**t)
    cv2.setNumThreads(1)
    trajectories = []
    with open(cache_path, "a") as cache, tqdm(total=len(rows), desc=f"corruption {config}", unit="ref",
                                              disable=not progress) as bar:
        for row in rows:
            if row["instance_id"] not in done:
                t = study_one(InstanceReference(release / config, row), seed)
                cache.write(json.dumps(t.__dict__) + "\n")
                cache.flush()
                done[t.instance_id] = t
            trajectories.append(done[row["instance_id"]])
            bar.update()
    summary = {"release": str(release), "config": config, "seed": seed, **summarise(trajectories, seed)}
    (out / "corruption.json").write_text(json.dumps(summary, indent=1))
    (out / "corruption.md").write_text(markdown(summary, config))
    example_strip(InstanceReference(release / config, rows[0]), trajectories[0], seed, out / "example.png")
    return summary
