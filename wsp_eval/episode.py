"""One episode of a release as a model adapter or a calibration baseline sees it (`EpisodeContext`), and the
readers behind it: the episode's action stream and its instance's unperturbed source rollout.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval.reference import episodes, reference_frames, reference_masks
from wsp_eval.release_format import FIRST_FRAME, INPUT_ACTIONS, INSTANCES

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

    @property
    def inputs_only(self) -> bool:
        """Whether the release is an inputs-only export (`wsp_eval.inputs`): first frames and actions, no video."""
        return (self.config_dir / INPUT_ACTIONS).is_file()

    def first_frame(self) -> np.ndarray:
        """Frame 0 (H, W, 3) uint8: what a model conditions on (from either kind of release)."""
        if self.inputs_only:
            return self._cached("first", lambda: _first_frame(self.config_dir, self.episode_id))
        return self.frames()[0]

    def frames(self) -> np.ndarray:
        """Reference RGB frames (N, H, W, 3) uint8."""
        self._full_release("reference frames")
        return self._cached("frames", lambda: reference_frames(self.config_dir, self.episode_index))

    def masks(self) -> np.ndarray:
        """Robot label masks (N, H, W) uint8: 0 not robot, 1 arm, 2 wrist/hand/fingers."""
        self._full_release("robot masks")
        return self._cached("masks", lambda: reference_masks(self.config_dir, self.episode_index))

    def source_frames(self) -> np.ndarray:
        """RGB frames of the instance's unperturbed source rollout (its own length)."""
        self._full_release("source rollouts")
        index = source_episode_index(self.config, self.row, self.config_dir)
        return self._cached("source", lambda: reference_frames(self.config_dir, index))

    def actions(self, key: str = "action") -> np.ndarray:
        """The episode's action stream `key` (`action`, or `action.ee` / `action.joint`), float32 (T, D)."""
        read = _input_actions if self.inputs_only else episode_actions
        return self._cached(f"actions/{key}", lambda: read(self.config_dir, self.episode_index, key))

    def _full_release(self, what: str) -> None:
        if self.inputs_only:
            raise BaselineError(f"{self.release}: an inputs-only release holds no {what} (only first frames and "
                                "actions: that is what keeps its references private); use the full release")

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


def _first_frame(config_dir: Path, episode_id: str) -> np.ndarray:
    import cv2

    path = config_dir / FIRST_FRAME.format(episode_id=episode_id)
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"{path}: missing or unreadable first frame")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def _input_actions(config_dir: Path, episode_index: int, key: str) -> np.ndarray:
    path = config_dir / INPUT_ACTIONS
    names = pq.read_schema(path).names
    if key not in names:
        raise ValueError(f"{path}: no column {key!r}; action columns: "
                         + ", ".join(n for n in names if n.startswith("action")))
    t = pq.read_table(path, columns=[key], filters=[("episode_index", "=", episode_index)])
    if t.num_rows != 1:
        raise ValueError(f"{path}: episode {episode_index} found {t.num_rows} times")
    rows = t.column(key)[0].as_py()
    return np.asarray(rows, dtype=np.float32).reshape(len(rows), -1)


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
