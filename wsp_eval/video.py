"""Timestamps and nearest-frame resampling (SPEC §4), and the temporally aligned MSE of T1 (SPEC §3)."""

from __future__ import annotations

import numpy as np


def timestamps(num_frames: int, fps: float) -> np.ndarray:
    """Frame j of a video without explicit timestamps sits at j / fps; every video starts at t = 0."""
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    return np.arange(num_frames, dtype=np.float64) / fps


def nearest_indices(source_ts: np.ndarray, target_ts: np.ndarray) -> np.ndarray:
    """For each target timestamp, the index of the nearest source frame (ties go to the earlier frame)."""
    source_ts = np.asarray(source_ts, dtype=np.float64)
    idx = np.clip(np.searchsorted(source_ts, target_ts), 1, len(source_ts) - 1)
    left, right = source_ts[idx - 1], source_ts[idx]
    return np.where(np.abs(target_ts - left) <= np.abs(right - target_ts), idx - 1, idx)


def aligned_mse(base: np.ndarray, other: np.ndarray, base_fps: float, other_fps: float) -> float:
    """D(base, other): `base`'s timestamps are the timebase; keep those within the common duration (up to
    the earlier of the two last-frame timestamps), take `other`'s nearest frame at each, average the
    squared difference over frames, pixels and channels (0–255 scale). No warping, no phase search."""
    if len(base) == 0 or len(other) == 0:
        raise ValueError("aligned_mse needs two non-empty videos")
    tb, to = timestamps(len(base), base_fps), timestamps(len(other), other_fps)
    keep = tb <= min(tb[-1], to[-1]) + 1e-9
    j = nearest_indices(to, tb[keep]) if len(other) > 1 else np.zeros(int(keep.sum()), dtype=int)
    diff = base[keep].astype(np.float64) - other[j].astype(np.float64)
    return float(np.mean(diff * diff))
