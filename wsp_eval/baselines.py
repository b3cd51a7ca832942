"""Calibration baselines, found by name in `BASELINES`: each turns one episode of a release (an
`EpisodeContext`) into the frames a model would submit, of the reference horizon.

Reference-only baselines are plain functions of the reference frames (`oracle`, `static`, `blur`), wrapped
for the registry by `_of_reference`; the others read what they need from the context. Every baseline is
deterministic: the same release, name and generation seed give identical frames.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wsp_eval.episode import BaselineError, EpisodeContext
from wsp_eval.generate import GenerateError, per_episode, write_submission
from wsp_eval.registry import Registry

BLUR_SIGMA_PX = 2.0  # `blur`: standard deviation of the Gaussian kernel, pixels
NOISE_SIGMA = 10.0  # `noise`: standard deviation of the additive Gaussian noise, grey levels (0–255 scale)
LAG_SECONDS = 0.25  # `lag`: delay of the video (5 frames at 20 Hz)


# -- frame transforms ---------------------------------------------------------------------------------
def oracle(reference: np.ndarray) -> np.ndarray:
    """The reference video itself."""
    return reference


def static(reference: np.ndarray) -> np.ndarray:
    """Frame 0 of the reference repeated over the horizon."""
    return np.repeat(reference[:1], len(reference), axis=0)


def blur(reference: np.ndarray) -> np.ndarray:
    """The reference blurred by a Gaussian of BLUR_SIGMA_PX pixels."""
    import cv2

    return np.stack([cv2.GaussianBlur(f, (0, 0), BLUR_SIGMA_PX, borderType=cv2.BORDER_REFLECT_101)
                     for f in reference])


def fit_length(frames: np.ndarray, n: int) -> np.ndarray:
    """`frames` truncated to `n`, or padded with its last frame."""
    return np.concatenate([frames[:n], np.repeat(frames[-1:], max(0, n - len(frames)), axis=0)])


def delayed(frames: np.ndarray, shift: int) -> np.ndarray:
    """Frame t shows frames[t − shift]; the first frame fills the start."""
    return np.concatenate([np.repeat(frames[:1], shift, axis=0), frames])[: len(frames)]


def corrupt(frames: np.ndarray, regions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """`frames` with the pixels where `regions` (N, H, W) is true replaced by uniform noise over the values
    other than the original one, channel by channel (so every selected pixel changes)."""
    out = frames.copy()
    out[regions] += rng.integers(1, 256, size=(int(regions.sum()), 3), dtype=np.uint8)  # wraps modulo 256
    return out


def paired_regions(robot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame of `robot` (N, H, W) bool, a robot region and a background region of equal pixel count.
    Robot: every robot pixel (when the robot covers more than half the frame, its first pixels in raster
    order, as many as there are background pixels). Background, chosen compactly: the robot region moved
    sideways (cyclically) by the one shift per episode that overlaps the robot least over all frames (ties:
    the shift nearest half the width), where it still overlaps the robot topped up with the non-robot pixels
    nearest to it (Euclidean distance, ties in raster order)."""
    width = robot.shape[2]
    shifts = sorted(range(1, width), key=lambda s: (abs(s - width / 2), s))
    overlaps = [int((np.roll(robot, s, axis=2) & robot).sum()) for s in shifts]
    shift = shifts[int(np.argmin(overlaps))]
    fg = np.stack([_capped(m) for m in robot])
    return fg, np.stack([_nearest_free(m, np.roll(r, shift, axis=1), int(r.sum())) for m, r in zip(robot, fg)])


def _capped(robot: np.ndarray) -> np.ndarray:
    """`robot` (H, W), or its first (raster order) pixels up to the number of non-robot pixels."""
    free = robot.size - int(robot.sum())
    if robot.sum() <= free:
        return robot
    flat = robot.ravel().copy()
    flat[np.flatnonzero(flat)[free:]] = False
    return flat.reshape(robot.shape)


def _nearest_free(robot: np.ndarray, target: np.ndarray, n: int) -> np.ndarray:
    """The `n` pixels outside `robot` (H, W) nearest to `target` (H, W), ties in raster order."""
    import cv2

    distance = cv2.distanceTransform((~target).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    order = np.argsort(np.where(robot, np.inf, distance).ravel(), kind="stable")[:n]
    region = np.zeros(robot.size, dtype=bool)
    region[order] = True
    return region.reshape(robot.shape)


# -- baselines (EpisodeContext → frames) --------------------------------------------------------------
Baseline = Callable[[EpisodeContext], np.ndarray]


def _of_reference(transform: Callable[[np.ndarray], np.ndarray]) -> Baseline:
    """A baseline applying `transform` to the reference frames, documented by the transform."""
    @functools.wraps(transform)
    def baseline(ctx: EpisodeContext) -> np.ndarray:
        return transform(ctx.frames())
    return baseline


def action_blind(ctx: EpisodeContext) -> np.ndarray:
    """The unperturbed source rollout's video whatever the action, fitted to the reference horizon."""
    return fit_length(ctx.source_frames(), ctx.num_frames)


def noise(ctx: EpisodeContext) -> np.ndarray:
    """The reference plus Gaussian noise of NOISE_SIGMA grey levels, seeded by (seed, episode)."""
    ref = ctx.frames()
    noisy = ref + ctx.rng().normal(0.0, NOISE_SIGMA, ref.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def lag(ctx: EpisodeContext) -> np.ndarray:
    """The reference LAG_SECONDS late: frame t shows reference t − 5 at 20 Hz, frame 0 repeated first."""
    return delayed(ctx.frames(), int(round(LAG_SECONDS * ctx.fps)))


def robot_corrupt(ctx: EpisodeContext) -> np.ndarray:
    """The reference with its robot pixels (mask > 0; `paired_regions`) replaced by seeded uniform noise."""
    return corrupt(ctx.frames(), paired_regions(ctx.masks() > 0)[0], ctx.rng())


def background_corrupt(ctx: EpisodeContext) -> np.ndarray:
    """The reference with as many background pixels as `robot_corrupt` corrupts replaced by noise."""
    return corrupt(ctx.frames(), paired_regions(ctx.masks() > 0)[1], ctx.rng())


BASELINES: Registry[Baseline] = Registry("baseline", "worldsimprobe.baselines")
BASELINES.register("oracle", _of_reference(oracle))
BASELINES.register("static", _of_reference(static))
BASELINES.register("action_blind", action_blind)
BASELINES.register("blur", _of_reference(blur))
BASELINES.register("noise", noise)
BASELINES.register("lag", lag)
BASELINES.register("robot_corrupt", robot_corrupt)
BASELINES.register("background_corrupt", background_corrupt)


def write_baseline(name: str, release: Path, out: Path, seeds: tuple[int, ...] = (0, 1, 2),
                   progress: bool = False) -> int:
    """Write (or resume) a complete submission of baseline `name` for every scored config, with model
    `baseline:<name>`; returns the number of videos written by this call. Raises KeyError for an unknown
    name, BaselineError for anything else that stops it."""
    baseline = BASELINES[name]
    try:
        result = write_submission(per_episode(baseline), release, out, seeds=seeds, name=f"baseline:{name}",
                                  progress=progress)
    except GenerateError as e:
        raise BaselineError(str(e)) from None
    return result.written
