"""T1 Local action calibration score (spec §3.1).

For one generation seed: r = D(ĝ⁰, ĝˢ) / D(ĝ⁰, ĝˡ) with D the temporally aligned full-video MSE (the
generated original is the timebase); r* = D⁰ˢ / D⁰ˡ from the simulator references (stored in the instance
row). S = clip₀¹(r / r*) if r ≤ r*, else clip₀¹((1 − r) / (1 − r*)); S = 0 when D(ĝ⁰, ĝˡ) = 0. The instance
score averages S over seeds; the suite score is 100 · mean over instances.
"""

from __future__ import annotations

import numpy as np

from wsp_eval.video import aligned_mse

SUITE, TITLE = "t1", "Local action calibration"
ROLES = ("original", "small", "large")
NEEDS: tuple[str, ...] = ()
GROUP_BY, BALANCED = "task", False
REFERENCE_RESULTS = False


def calibration(r: float, r_star: float) -> float:
    s = r / r_star if r <= r_star else (1.0 - r) / (1.0 - r_star)
    return float(np.clip(s, 0.0, 1.0))


def distances(videos: dict[str, tuple[np.ndarray, float]]) -> tuple[float, float]:
    """(D(ĝ⁰, ĝˢ), D(ĝ⁰, ĝˡ)) for one seed: the generated response to each perturbation."""
    (g0, f0), (gs, fs), (gl, fl) = (videos[r] for r in ROLES)
    return aligned_mse(g0, gs, f0, fs), aligned_mse(g0, gl, f0, fl)


def ratio_of(d_os: float, d_ol: float) -> float | None:
    """r = D⁰ˢ / D⁰ˡ; None when D⁰ˡ = 0 (the large perturbation left no trace)."""
    return None if d_ol == 0 else d_os / d_ol


def ratio(videos: dict[str, tuple[np.ndarray, float]]) -> float | None:
    """r = D(ĝ⁰, ĝˢ) / D(ĝ⁰, ĝˡ) for one seed (`ratio_of`)."""
    return ratio_of(*distances(videos))


def ratio_score(r: float | None, r_star: float) -> float:
    """S from r (`ratio`): 0 when r is undefined."""
    return 0.0 if r is None else calibration(r, r_star)


def seed_score(videos: dict[str, tuple[np.ndarray, float]], r_star: float) -> float:
    """S for one seed; `videos` maps role → (frames, fps) of the generated rollouts."""
    return ratio_score(ratio(videos), r_star)


def instance_score(per_seed: list[dict[str, tuple[np.ndarray, float]]], r_star: float) -> float:
    """Seeds are averaged per instance before anything else."""
    return float(np.mean([seed_score(v, r_star) for v in per_seed]))


def prepare(ref, backends) -> float:
    return float(ref.row["r_star"])


def score_seed(r_star: float, videos, backends) -> tuple[float, dict]:
    """The engine's interface: S on the 0–100 scale of the suite score, with r, r* and the generated distances
    D(ĝ⁰, ĝˢ), D(ĝ⁰, ĝˡ) (the report's evidence; `wsp study t1-response` reads them)."""
    d_os, d_ol = distances(videos)
    r = ratio_of(d_os, d_ol)
    return 100.0 * ratio_score(r, r_star), {"r": r, "r_star": r_star, "d_os": d_os, "d_ol": d_ol}


def groups(rows: list[dict]) -> list[str]:
    return [r["task"] for r in rows]
