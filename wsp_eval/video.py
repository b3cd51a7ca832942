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
    a, b = np.ascontiguousarray(base[keep]), np.ascontiguousarray(other[j])
    if a.dtype == np.uint8 and b.dtype == np.uint8:  # OpenCV's sum of squared differences: ~40× numpy's
        import cv2

        return float(cv2.norm(a.reshape(len(a), -1), b.reshape(len(b), -1), cv2.NORM_L2SQR) / a.size)
    diff = a.astype(np.float64) - b.astype(np.float64)
    return float(np.mean(diff * diff))


class VideoError(ValueError):
    """A video that cannot be used; the message names the file."""


MIN_FPS, MAX_FPS = 1.0, 240.0  # a submission's fps outside this range is treated as absurd


def read_video(path) -> tuple[np.ndarray, float]:
    """Decode every frame of a video file as RGB uint8 (N, H, W, 3) and return it with its fps."""
    import av

    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                raise VideoError(f"{path}: no video stream")
            stream = container.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate
            frames = [f.to_ndarray(format="rgb24") for f in container.decode(stream)]
    except VideoError:
        raise
    except (av.error.FFmpegError, OSError, ValueError) as e:
        raise VideoError(f"{path}: unreadable video ({type(e).__name__}: {e})") from e
    fps = float(rate) if rate else float("nan")
    return (np.stack(frames) if frames else np.zeros((0, 0, 0, 3), np.uint8)), fps


def write_video(path, frames: np.ndarray, fps: float) -> None:
    """Write RGB uint8 frames (N, H, W, 3) as lossless RGB h264 (libx264rgb, crf 0) mp4: decoding gives back
    exactly these frames, so a baseline or a model run through `wsp generate` is scored on what it produced."""
    import av

    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise VideoError(f"{path}: expected frames of shape (N, H, W, 3), got {frames.shape}")
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264rgb", rate=int(round(fps)))
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "rgb24"
        stream.options = {"crf": "0", "preset": "medium", "threads": "1"}
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
