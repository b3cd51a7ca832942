"""Generated-video stand-ins made from a reference and its exact masks: the object frozen, erased, re-timed, moved
otherwise, another object moved, the arm blurred. Evaluator validity studies score these as a model's videos
(`wsp study t5-negatives`, `wsp study t4-negatives`).

Every composite is built frame by frame from the reference: the object's pixels are removed (inpainted from
their surroundings, `erase`), the object's appearance from another frame is pasted where the variant puts it
(`paste`), and the robot's pixels of the frame are pasted back on top, so the arm is exactly the reference's.
Deterministic: no random draw except the seeded noise of `noisy`.
"""

from __future__ import annotations

import cv2
import numpy as np

ERASE_DILATE = 2  # px: the object's mask grows by this before inpainting (its anti-aliased rim goes too)
INPAINT_RADIUS = 3  # px: OpenCV Telea inpainting neighbourhood


def _kernel(px: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * px + 1, 2 * px + 1))


def erase(frames: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """(T, H, W, 3) frames with the pixels of `masks` (T, H, W) bool inpainted from their surroundings."""
    out = frames.copy()
    for t, (f, m) in enumerate(zip(frames, masks)):
        if m.any():
            hole = cv2.dilate(m.astype(np.uint8), _kernel(ERASE_DILATE))
            out[t] = cv2.inpaint(f, hole, INPAINT_RADIUS, cv2.INPAINT_TELEA)
    return out


def centroids(masks: np.ndarray) -> np.ndarray:
    """(T, 2) x, y centroid of each frame's mask; a frame where the mask is empty keeps the last seen centroid
    (frame 0's when it is empty too: the first non-empty one's)."""
    out = np.full((len(masks), 2), np.nan)
    for t, m in enumerate(masks):
        ys, xs = np.nonzero(m)
        if len(xs):
            out[t] = xs.mean(), ys.mean()
    seen = np.flatnonzero(~np.isnan(out[:, 0]))
    if len(seen) == 0:
        raise ValueError("the object is never in sight")
    out[: seen[0]] = out[seen[0]]
    for t in range(1, len(out)):
        if np.isnan(out[t, 0]):
            out[t] = out[t - 1]
    return out


def paste(base: np.ndarray, source: np.ndarray, mask: np.ndarray, shift: tuple[float, float]) -> np.ndarray:
    """`base` (H, W, 3) with `source`'s pixels under `mask` (H, W) bool moved by `shift` (dx, dy px, rounded)."""
    dx, dy = int(round(shift[0])), int(round(shift[1]))
    h, w = mask.shape
    ys, xs = np.nonzero(mask)
    ty, tx = ys + dy, xs + dx
    keep = (ty >= 0) & (ty < h) & (tx >= 0) & (tx < w)
    out = base.copy()
    out[ty[keep], tx[keep]] = source[ys[keep], xs[keep]]
    return out


def with_robot(frames: np.ndarray, reference: np.ndarray, robot: np.ndarray) -> np.ndarray:
    """`frames` with the reference's robot pixels (`robot` (T, H, W) bool) pasted back on top."""
    out = frames.copy()
    out[robot] = reference[robot]
    return out


def relayer(reference: np.ndarray, obj: np.ndarray, robot: np.ndarray, source: np.ndarray,
            shifts: np.ndarray) -> np.ndarray:
    """The reference with its object drawn at frame t as it is in frame `source[t]`, moved by `shifts[t]` (dx, dy);
    the robot stays the reference's."""
    plate = erase(reference, obj)
    out = np.stack([paste(plate[t], reference[s], obj[s], shifts[t]) for t, s in enumerate(source)])
    return with_robot(out, reference, robot)


def blurred_region(frames: np.ndarray, region: np.ndarray, sigma: float) -> np.ndarray:
    """`frames` with a Gaussian blur (σ px) inside `region` (T, H, W) bool grown by 2σ: a smeared arm or object."""
    out = frames.copy()
    grow = _kernel(max(1, int(round(2 * sigma))))
    for t, (f, m) in enumerate(zip(frames, region)):
        if m.any():
            area = cv2.dilate(m.astype(np.uint8), grow).astype(bool)
            out[t][area] = cv2.GaussianBlur(f, (0, 0), sigma)[area]
    return out


def blurred(frames: np.ndarray, sigma: float) -> np.ndarray:
    """Every frame Gaussian-blurred (σ px)."""
    return np.stack([cv2.GaussianBlur(f, (0, 0), sigma) for f in frames])


def noisy(frames: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """Every frame with i.i.d. Gaussian noise (σ grey levels), seeded."""
    noise = np.random.default_rng(seed).normal(0.0, sigma, frames.shape)
    return np.clip(frames.astype(np.float64) + noise, 0, 255).astype(np.uint8)


def faded(reference: np.ndarray, obj: np.ndarray, robot: np.ndarray, start: int, length: int) -> np.ndarray:
    """The object fading out linearly over `length` frames from `start` (then gone), the robot the reference's."""
    plate = erase(reference, obj)
    alpha = np.clip((np.arange(len(reference)) - start) / max(length, 1), 0.0, 1.0)[:, None, None, None]
    out = (reference * (1 - alpha) + plate * alpha).round().astype(np.uint8)
    return with_robot(out, reference, robot)
