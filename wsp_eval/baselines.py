"""Calibration baselines, found by name in `BASELINES`: each turns one episode of a release (an
`EpisodeContext`) into the frames a model would submit, of the reference horizon.

Reference-only baselines are plain functions of the reference frames (`oracle`, `static`, `blur`), wrapped
for the registry by `_of_reference`; the others read what they need from the context. Every baseline is
deterministic: the same release, name and generation seed give identical frames.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_data.schema import INSTANCES
from wsp_eval.reference import episodes, reference_frames, reference_masks

BLUR_SIGMA_PX = 2.0  # `blur`: standard deviation of the Gaussian kernel, pixels
NOISE_SIGMA = 10.0  # `noise`: standard deviation of the additive Gaussian noise, grey levels (0–255 scale)
LAG_SECONDS = 0.25  # `lag`: delay of the video (5 frames at 20 Hz)
T1_PREFIX = "t1_"  # T1 configs: the unperturbed source rollout is the scored `original` role
T1_SOURCE_ROLE = "original"  # role of the unperturbed rollout in a T1 instance
T3_PREFIX = "t3_"  # T3 configs: the canonical execution is the expert member of the instance's group
T3_SOURCE_GROUP = "expert"
SOURCE_COLUMN = "source_episode_index"  # other suites: instance column of an extra, unscored source episode


class BaselineError(RuntimeError):
    """A baseline that cannot run on this release; the message names the config or episode."""


@dataclass
class EpisodeContext:
    """One episode of a release as a baseline or model adapter sees it. The readers are lazy and cached
    (read-only arrays); `dataclasses.replace(ctx, seed=k)` shares the cache across seeds."""

    release: Path
    config: str
    row: dict  # the instance's row of instances.parquet
    role: str
    episode_index: int
    fps: float
    seed: int  # generation seed
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def config_dir(self) -> Path:
        return Path(self.release) / self.config

    @property
    def episode_id(self) -> str:
        return self.row["episode_ids"][self._position]

    @property
    def num_frames(self) -> int:
        """The reference horizon of this episode."""
        return int(self.row["num_frames"][self._position])

    @property
    def _position(self) -> int:
        return list(self.row["episode_indices"]).index(self.episode_index)

    def frames(self) -> np.ndarray:
        """Reference RGB frames (N, H, W, 3) uint8."""
        return self._cached("frames", lambda: reference_frames(self.config_dir, self.episode_index))

    def masks(self) -> np.ndarray:
        """Robot label masks (N, H, W) uint8: 0 not robot, 1 arm, 2 wrist/hand/fingers."""
        return self._cached("masks", lambda: reference_masks(self.config_dir, self.episode_index))

    def source_frames(self) -> np.ndarray:
        """RGB frames of the instance's unperturbed source rollout (its own length)."""
        index = source_episode_index(self.config, self.row, self.config_dir)
        return self._cached("source", lambda: reference_frames(self.config_dir, index))

    def actions(self, key: str = "action") -> np.ndarray:
        """The episode's action stream `key` (`action`, or `action.ee` / `action.joint`), float32 (T, D)."""
        return self._cached(f"actions/{key}", lambda: episode_actions(self.config_dir, self.episode_index, key))

    def rng(self) -> np.random.Generator:
        """A fresh generator seeded from (generation seed, episode index)."""
        return np.random.default_rng([self.seed, self.episode_index])

    def _cached(self, key: str, read: Callable[[], np.ndarray]) -> np.ndarray:
        if key not in self._cache:
            value = read()
            value.flags.writeable = False
            self._cache[key] = value
        return self._cache[key]


def episode_actions(config_dir: Path, episode_index: int, key: str = "action") -> np.ndarray:
    """Column `key` of one episode's rows (index in [dataset_from_index, dataset_to_index)), float32 (T, D)."""
    config_dir = Path(config_dir)
    ep = episodes(config_dir)[episode_index]
    info = json.loads((config_dir / "meta" / "info.json").read_text())
    path = config_dir / info["data_path"].format(chunk_index=ep["data/chunk_index"], file_index=ep["data/file_index"])
    names = pq.read_schema(path).names
    if key not in names:
        known = ", ".join(n for n in names if n.startswith("action"))
        raise ValueError(f"{path}: no column {key!r}; action columns: {known}")
    lo, hi = ep["dataset_from_index"], ep["dataset_to_index"]
    t = pq.read_table(path, columns=["index", key], filters=[("index", ">=", lo), ("index", "<", hi)]).sort_by("index")
    if t.num_rows != hi - lo:
        raise ValueError(f"{path}: episode {episode_index} has {t.num_rows} rows, expected {hi - lo}")
    return np.asarray(t.column(key).to_pylist(), dtype=np.float32).reshape(t.num_rows, -1)


@functools.lru_cache(maxsize=8)
def _t3_experts(config_dir: Path) -> dict[str, int]:
    """T3: group_id → the episode index of the group's expert rollout."""
    rows = pq.read_table(Path(config_dir) / INSTANCES, columns=["group_id", "source_group", "episode_indices"])
    return {g: int(e[0]) for g, s, e in zip(*(rows.column(c).to_pylist() for c in rows.column_names))
            if s == T3_SOURCE_GROUP}


def source_episode_index(config: str, row: dict, config_dir: Path | None = None) -> int:
    """The episode index of an instance's unperturbed source rollout: T1's `original` role; T3's canonical
    execution, the expert of the same group (needs `config_dir`); else the instance column
    `source_episode_index`."""
    if config.startswith(T1_PREFIX):
        return int(row["episode_indices"][list(row["roles"]).index(T1_SOURCE_ROLE)])
    if config.startswith(T3_PREFIX) and config_dir is not None and row.get("group_id") in _t3_experts(config_dir):
        return _t3_experts(Path(config_dir))[row["group_id"]]
    index = row.get(SOURCE_COLUMN)
    if index is None:
        raise BaselineError(f"{config}: the release has no source rollouts (no {SOURCE_COLUMN!r} for instance "
                            f"{row.get('instance_id')}); action_blind needs a build that stores them")
    return int(index)


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


BASELINES: dict[str, Baseline] = {
    "oracle": _of_reference(oracle), "static": _of_reference(static), "action_blind": action_blind,
    "blur": _of_reference(blur), "noise": noise, "lag": lag,
    "robot_corrupt": robot_corrupt, "background_corrupt": background_corrupt,
}


def write_baseline(name: str, release: Path, out: Path, seeds: tuple[int, ...] = (0, 1, 2),
                   progress: bool = False) -> int:
    """Write (or resume) a complete submission of baseline `name` for every scored config, with model
    `baseline:<name>`; returns the number of videos written by this call. Raises KeyError for an unknown
    name, BaselineError for anything else that stops it."""
    from wsp_eval.generate import GenerateError, write_submission  # generate imports this module

    if name not in BASELINES:
        raise KeyError(f"unknown baseline {name!r}; known: {', '.join(BASELINES)}")
    try:
        result = write_submission(BASELINES[name], release, out, seeds=seeds, name=f"baseline:{name}",
                                  progress=progress)
    except GenerateError as e:
        raise BaselineError(str(e)) from None
    return result.written
