"""Robot-Masked Flow Alignment (RMFA, spec §4.2): flows, windows, active sets and scores; no simulator.

Pipeline for one video (reference or generated) over a duration T (the common duration of the pair):
1. Sample at `EVAL_FPS` = 5 Hz: times t_k = k / 5 for every k with t_k ≤ T (t_0 = 0), each taking the
   nearest frame by timestamp (`wsp_eval.video`). A video of n frames at `fps` lasts (n − 1) / fps.
2. Resize to `FLOW_SIZE` = 160×120 (RGB bilinear, then grey; label masks nearest-neighbour).
3. Flow k = the flow backend's (default OpenCV DIS, preset MEDIUM, one thread; `wsp_eval.backends.flow`)
   from sample k to sample k + 1: K = len(samples) − 1
   fields, each (120, 160, 2) in pixels of the 160×120 grid. The reference's robot mask of flow k is the
   union of the robot masks (label > 0) at samples k and k + 1.
4. Windows (`windows`): 2 s long, 1 s stride = `WINDOW_FLOWS` = 10 consecutive flows starting every
   `STRIDE_FLOWS` = 5 flows, as long as a full window fits. If flows remain after the last full window
   (a final partial window), one more full window ending at the last flow is added, so every flow is
   covered and every window still has 10 flows. A clip with 1–9 flows (0.2 s ≤ T < 2 s) has one window
   holding all its flows; a clip with no flow (T < 0.2 s) has none.
5. Active set of a window: M = {(k, p) : k in the window, mask_k(p), ‖F*_k(p)‖ > τ}, τ = 0.25 px.
   S_w = 100·max(0, 1 − E / max(R, c)), E = RMS over M of ‖F̂ − F*‖, R = RMS over M of ‖F*‖, c = 3.16 px.
   A window with empty M is skipped; the instance score is the mean over the other windows (None when
   there is none — builders reject such references, so a release never holds one).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from wsp_eval.backends.flow import DISFlow
from wsp_eval.video import nearest_indices, timestamps

EVAL_FPS = 5.0  # Hz: the RMFA timebase (flows span 0.2 s)
FLOW_SIZE = (160, 120)  # (width, height) of the flow grid
WINDOW_FLOWS = 10  # flows per window (2 s at 5 Hz)
STRIDE_FLOWS = 5  # window stride in flows (1 s at 5 Hz)
TAU = 0.25  # px: reference flow magnitude above which a robot pixel is active
C = 3.16  # px: floor of the normaliser R (limits sensitivity to low-motion flow noise)


class ReferenceFlows(NamedTuple):
    """The reference side of RMFA: K flow fields and the robot mask of each flow pair."""

    flows: np.ndarray  # (K, 120, 160, 2) float32, px on the 160×120 grid
    masks: np.ndarray  # (K, 120, 160) bool: robot at either end of the pair


def clip_duration(num_frames: int, fps: float) -> float:
    """Seconds from the first to the last frame (frame j sits at j / fps)."""
    if num_frames < 1:
        raise ValueError("a video needs at least one frame")
    return float(timestamps(num_frames, fps)[-1])


def sample_times(duration: float) -> np.ndarray:
    """The 5 Hz evaluation grid t_k = k / 5 with 0 ≤ t_k ≤ duration."""
    if duration < 0:
        raise ValueError(f"duration must be non-negative, got {duration}")
    return np.arange(int(np.floor(duration * EVAL_FPS + 1e-9)) + 1) / EVAL_FPS


def sample_indices(num_frames: int, fps: float, duration: float | None) -> np.ndarray:
    """Frame index nearest to each 5 Hz sample time (duration defaults to the whole clip)."""
    own = clip_duration(num_frames, fps)
    if duration is None:
        duration = own
    if duration > own + 1e-9:
        raise ValueError(f"duration {duration:.3f} s exceeds the clip's {own:.3f} s")
    times = sample_times(duration)
    if num_frames == 1:
        return np.zeros(len(times), dtype=int)
    return nearest_indices(timestamps(num_frames, fps), times)


def _rgb_grid(frames: np.ndarray) -> np.ndarray:
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"expected (T, H, W, 3) uint8 RGB frames, got {frames.dtype} {frames.shape}")
    return np.stack([cv2.resize(f, FLOW_SIZE, interpolation=cv2.INTER_LINEAR) for f in frames])


def _robot_grid(labels: np.ndarray) -> np.ndarray:
    if labels.ndim != 3 or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"expected (T, H, W) integer robot labels (0 not robot, 1/2 robot), got "
                         f"{labels.dtype} {labels.shape}")
    robot = (labels > 0).astype(np.uint8)
    return np.stack([cv2.resize(m, FLOW_SIZE, interpolation=cv2.INTER_NEAREST) for m in robot]).astype(bool)


def video_flows(video: np.ndarray, fps: float, duration: float | None = None, backend=None,
                needed: np.ndarray | None = None) -> np.ndarray:
    """(K, 120, 160, 2) flows of a (T, H, W, 3) uint8 RGB video sampled at 5 Hz over `duration` seconds
    (default: the whole clip), by `backend` (default DIS). Used for both the reference and a generated video.
    `needed` (K,) bool: compute only those flows, the others are zero (a generated video's flows where the
    reference's active set is empty, `active_flows`, which RMFA never reads)."""
    idx = sample_indices(len(video), fps, duration)
    samples = _rgb_grid(np.asarray(video)[idx])
    if needed is not None and len(needed) != max(len(samples) - 1, 0):
        raise ValueError(f"{len(needed)} needed flags for {max(len(samples) - 1, 0)} flows")
    return (backend or DISFlow()).flows(samples, needed)


def reference_flows(video: np.ndarray, labels: np.ndarray, fps: float, duration: float | None = None,
                    backend=None) -> ReferenceFlows:
    """Reference flows and per-pair robot masks. `labels`: (T, H, W) integer masks aligned with `video`
    (0 not robot, 1 arm, 2 wrist/hand/fingers; robot = label > 0)."""
    if len(labels) != len(video):
        raise ValueError(f"{len(labels)} masks for {len(video)} frames")
    idx = sample_indices(len(video), fps, duration)
    robot = _robot_grid(np.asarray(labels)[idx])
    return ReferenceFlows((backend or DISFlow()).flows(_rgb_grid(np.asarray(video)[idx])), robot[:-1] | robot[1:])


def windows(num_flows: int) -> list[tuple[int, int]]:
    """Half-open flow-index ranges [start, end) of the RMFA windows (module docstring, step 4)."""
    if num_flows < 0:
        raise ValueError(f"num_flows must be non-negative, got {num_flows}")
    if num_flows == 0:
        return []
    if num_flows <= WINDOW_FLOWS:
        return [(0, num_flows)]
    out = [(s, s + WINDOW_FLOWS) for s in range(0, num_flows - WINDOW_FLOWS + 1, STRIDE_FLOWS)]
    if out[-1][1] < num_flows:
        out.append((num_flows - WINDOW_FLOWS, num_flows))
    return out


def _active(flows: np.ndarray, masks: np.ndarray, tau: float) -> np.ndarray:
    if flows.shape[:-1] != masks.shape or flows.shape[-1] != 2:
        raise ValueError(f"flows {flows.shape} and masks {masks.shape} do not match")
    fx, fy = flows[..., 0], flows[..., 1]  # |flow|: np.linalg.norm(flows, axis=-1)'s arithmetic, 15× faster
    return masks & (np.sqrt(fx * fx + fy * fy) > tau)


def active_flows(flows: np.ndarray, masks: np.ndarray, tau: float = TAU) -> np.ndarray:
    """(K,) bool: which reference flows have a non-empty active set. Only these flows of a generated video enter
    any window's E (a flow whose M is empty contributes no pixel), so only these need computing."""
    return _nonempty(_active(flows, masks, tau))


def _nonempty(active: np.ndarray) -> np.ndarray:
    """(K,) bool: which of K active sets (K, H, W) hold a pixel."""
    return active.reshape(len(active), -1).any(axis=1)


def active_pixels_per_window(flows: np.ndarray, masks: np.ndarray, tau: float = TAU) -> np.ndarray:
    """|M| of every window: robot-mask pixels whose reference flow exceeds τ, summed over its flows."""
    active = _active(flows, masks, tau)
    return np.array([int(active[s:e].sum()) for s, e in windows(len(flows))], dtype=np.int64)


class ReferenceWindow(NamedTuple):
    """One window's reference side: its flows [start, end), active set M as flat indices into the window's
    (end − start)·H·W flow vectors (ascending: the order of a boolean mask), the reference flow on M (|M|, 2) and
    R (module docstring, step 5)."""

    start: int
    end: int
    active: np.ndarray
    star: np.ndarray
    r: float


class WindowedReference(NamedTuple):
    """Every window of a reference (`windows`), None where M is empty: what a generated video's flows are scored
    against, computed once per reference instead of once per seed."""

    shape: tuple[int, ...]  # (K, H, W, 2) of the reference flows
    windows: list[ReferenceWindow | None]
    needed: np.ndarray  # (K,) bool: the flows with a non-empty active set (`active_flows`)


def windowed_reference(f_star: np.ndarray, masks: np.ndarray, tau: float = TAU) -> WindowedReference:
    """The windows of reference flows (K, H, W, 2) with their robot masks (K, H, W)."""
    active = _active(f_star, masks, tau)  # once: the windows overlap
    return WindowedReference(f_star.shape, [_window(f_star, active, a, b) for a, b in windows(len(f_star))],
                             _nonempty(active))


def _window(f_star: np.ndarray, active: np.ndarray, a: int, b: int) -> ReferenceWindow | None:
    """The reference side of the window of flows [a, b), given every flow's active set; None when M is empty."""
    index = np.flatnonzero(active[a:b])
    if len(index) == 0:
        return None
    star = f_star[a:b].reshape(-1, 2)[index]
    return ReferenceWindow(a, b, index, star, float(np.sqrt(np.mean(_squared_norms(star)))))


def _squared_norms(v: np.ndarray) -> np.ndarray:
    """‖v‖² of (N, 2) vectors: the float operations of `np.sum(v ** 2, axis=-1)` (x·x + y·y), without its reduction
    machinery."""
    x, y = v[:, 0], v[:, 1]
    return x * x + y * y


def score_windows(f_hat: np.ndarray, ref: WindowedReference, c: float = C) -> list[float | None]:
    """S_w of every window, None where M is empty: S_w = 100·max(0, 1 − E / max(R, c)), E the RMS over M of
    ‖F̂ − F*‖. `f_hat` must cover the reference's common duration (same K)."""
    if f_hat.shape != ref.shape:
        raise ValueError(f"generated flows {f_hat.shape} and reference flows {ref.shape} differ: sample both "
                         "over their common duration")
    out: list[float | None] = []
    for w in ref.windows:
        if w is None:
            out.append(None)
            continue
        d = f_hat[w.start:w.end].reshape(-1, 2)[w.active] - w.star  # F̂ − F* on M, in the boolean mask's order
        e = float(np.sqrt(np.mean(_squared_norms(d))))
        out.append(100.0 * max(0.0, 1.0 - e / max(w.r, c)))
    return out


def rmfa_window_score(f_hat: np.ndarray, f_star: np.ndarray, mask: np.ndarray, tau: float = TAU,
                      c: float = C) -> float | None:
    """S_w for one window's flows (k, H, W, 2) and masks (k, H, W); None when M is empty."""
    if f_hat.shape != f_star.shape:
        raise ValueError(f"generated flows {f_hat.shape} and reference flows {f_star.shape} differ")
    active = _active(f_star, mask, tau)
    window = _window(f_star, active, 0, len(f_star))
    if window is None:
        return None
    return score_windows(f_hat, WindowedReference(f_star.shape, [window], _nonempty(active)), c)[0]


def rmfa_windows(f_hat: np.ndarray, f_star: np.ndarray, masks: np.ndarray, tau: float = TAU, c: float = C
                 ) -> list[float | None]:
    """S_w of every window (`windows`), None where M is empty. Both flow sequences must cover the same common
    duration (same K)."""
    return score_windows(f_hat, windowed_reference(f_star, masks, tau), c)


def mean_window_score(per_window: list[float | None]) -> float | None:
    """Instance RMFA from `rmfa_windows`: mean S_w over the windows with non-empty M; None when there is none."""
    scores = [s for s in per_window if s is not None]
    return float(np.mean(scores)) if scores else None


def rmfa_score(f_hat: np.ndarray, f_star: np.ndarray, masks: np.ndarray, tau: float = TAU, c: float = C
               ) -> float | None:
    """Instance RMFA: mean S_w over the windows with non-empty M; None when no window is scorable."""
    return mean_window_score(rmfa_windows(f_hat, f_star, masks, tau, c))
