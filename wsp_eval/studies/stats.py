"""The statistics the paper's analyses share (`docs/analyses.md`): percentile bootstrap intervals, least-squares
slopes, principal components, convex hulls and their areas. NumPy only (the scoring-only install has no SciPy)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

BOOTSTRAP = 2000  # resamples of every analysis interval
SEED = 0


def bootstrap_ci(statistic: Callable[[np.ndarray], float | None], n: int, *, resamples: int = BOOTSTRAP,
                 seed: int = SEED) -> list[float] | None:
    """95 % percentile interval of `statistic(indices)` over `resamples` draws of n indices with replacement;
    draws where it is undefined (None or NaN) are skipped; None when n < 2 or no draw is defined."""
    if n < 2:
        return None
    rng = np.random.default_rng(seed)
    values = [v for _ in range(resamples) if (v := statistic(rng.integers(0, n, n))) is not None and np.isfinite(v)]
    if not values:
        return None
    lo, hi = np.percentile(values, [2.5, 97.5])
    return [float(lo), float(hi)]


def interval_text(ci: list[float] | None, fmt: str = ".2f") -> str:
    """" [lo, hi]" of a 95 % interval in the format `fmt` (e.g. ".3f", "+.1f"), for a table cell after its value;
    "" when the interval is undefined."""
    return f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]" if ci else ""


def mean_ci(values) -> dict:
    """Mean, 95 % bootstrap interval and n of `values`."""
    x = np.asarray(values, float)
    return {"mean": float(x.mean()) if len(x) else None, "ci": bootstrap_ci(lambda i: float(x[i].mean()), len(x)),
            "n": len(x)}


def slope(x, y) -> float | None:
    """Least-squares slope of y on x (with an intercept); None when x is constant."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 2 or np.ptp(x) == 0:
        return None
    dx = x - x.mean()
    return float(dx @ (y - y.mean()) / (dx @ dx))


def pca(points: np.ndarray, k: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(scores (n, k), components (k, d), explained-variance share of each) of the rows of `points`, centred;
    each component's sign makes its largest-magnitude loading positive (a reproducible orientation)."""
    x = np.asarray(points, float)
    x = x - x.mean(axis=0)
    _, s, vt = np.linalg.svd(x, full_matrices=False)
    vt = vt[:k]
    vt = vt * np.sign(vt[np.arange(len(vt)), np.abs(vt).argmax(axis=1)])[:, None]
    total = float((s ** 2).sum())
    share = (s[:k] ** 2) / total if total > 0 else np.zeros(len(vt))
    return x @ vt.T, vt, share


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of 2-D `points`, counter-clockwise (Andrew's monotone chain); fewer than three
    when the points are fewer or collinear."""
    pts = sorted(set(map(tuple, np.asarray(points, float).tolist())))
    if len(pts) < 3:
        return np.array(pts, float).reshape(-1, 2)

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def half(seq) -> list:
        out: list = []
        for p in seq:
            while len(out) >= 2 and cross(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.array(lower[:-1] + upper[:-1], float)


def polygon_area(vertices: np.ndarray) -> float:
    """Area of a simple polygon (shoelace formula); 0 for fewer than three vertices."""
    v = np.asarray(vertices, float)
    if len(v) < 3:
        return 0.0
    x, y = v[:, 0], v[:, 1]
    return float(abs(x @ np.roll(y, -1) - y @ np.roll(x, -1)) / 2)


def inside_hull(point: np.ndarray, hull: np.ndarray) -> bool:
    """Whether 2-D `point` lies in (or on) the counter-clockwise convex polygon `hull` of ≥ 3 vertices."""
    p, h = np.asarray(point, float), np.asarray(hull, float)
    edges = np.roll(h, -1, axis=0) - h
    rel = p - h
    return bool(np.all(edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0] >= -1e-12))


def generalised_variance(points: np.ndarray) -> float | None:
    """Determinant of the sample covariance of 2-D `points`; None for fewer than three points."""
    p = np.asarray(points, float)
    return float(np.linalg.det(np.cov(p.T))) if len(p) >= 3 else None


def grouped_bootstrap_ci(groups: dict[str, np.ndarray], statistic: Callable[[dict[str, float]], float | None], *,
                         resamples: int = BOOTSTRAP, seed: int = SEED) -> list[float] | None:
    """95 % percentile interval of `statistic(group → mean)` when each group's values are resampled on their own;
    None when no group has two values or no draw is defined."""
    if all(len(v) < 2 for v in groups.values()):
        return None
    rng = np.random.default_rng(seed)
    values = []
    for _ in range(resamples):
        means = {g: float(v[rng.integers(0, len(v), len(v))].mean()) for g, v in groups.items()}
        if (s := statistic(means)) is not None and np.isfinite(s):
            values.append(s)
    if not values:
        return None
    lo, hi = np.percentile(values, [2.5, 97.5])
    return [float(lo), float(hi)]
