"""The training data of the reference world model: every episode of a `train_<platform>` config, decoded once
into memory (frames uint8, action features float32)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
from tqdm import tqdm

from wsp_eval.console import terminal
from wsp_eval.generate import episode_contexts
from wsp_eval.release_format import INSTANCES
from wsp_models.reference.network import condition

VALIDATION_EVERY = 10  # every 10th episode (by position in the config; the last one if there are fewer than 10)
#   is held out for the validation loss


@dataclass
class Episodes:
    frames: list[np.ndarray]  # per episode (T, S, S, 3) uint8
    features: list[np.ndarray]  # per episode (T, F) float32, `condition` of its actions
    ids: list[str]

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def num_frames(self) -> int:
        return sum(len(f) for f in self.frames)


class DataError(RuntimeError):
    """A release that cannot train the model; the message names the folder and the problem."""


def load_split(release: Path, config: str, size: int, progress: bool = True) -> tuple[Episodes, Episodes, dict]:
    """(training episodes, validation episodes, facts about the data: fps, action width, checksum)."""
    path = Path(release) / config / INSTANCES
    if not path.is_file():
        raise DataError(f"{path}: not found; build the split first (`wsp build --suite train ...`)")
    count = pq.ParquetFile(path).metadata.num_rows  # one expert episode per row
    if count < 2:
        raise DataError(f"{path}: holds {count} episode(s); training needs at least 2 (one is held out)")
    held_out = set(range(VALIDATION_EVERY - 1, count, VALIDATION_EVERY)) or {count - 1}
    train, val = Episodes([], [], []), Episodes([], [], [])
    digest = hashlib.sha256()
    contexts = episode_contexts(Path(release), [config])  # lazily: each context's decoded video is dropped after use
    for i, ctx in enumerate(tqdm(contexts, total=count, desc=f"read {config}", unit="episode", disable=not progress,
                                 file=terminal())):
        frames = _resized(ctx.frames(), size)
        actions = ctx.actions()
        n = min(len(frames), len(actions))
        digest.update(frames[:n].tobytes())
        digest.update(np.ascontiguousarray(actions[:n]).tobytes())
        part = val if i in held_out else train
        part.frames.append(frames[:n])
        part.features.append(condition(actions[:n], ctx.fps))
        part.ids.append(ctx.episode_id)
    facts = {"config": config, "episodes": count, "frames": train.num_frames + val.num_frames, "fps": ctx.fps,
             "action_dim": int(actions.shape[1]), "sha256": digest.hexdigest()}
    return train, val, facts


def _resized(frames: np.ndarray, size: int) -> np.ndarray:
    if frames.shape[1:3] == (size, size):
        return np.ascontiguousarray(frames)
    return np.stack([cv2.resize(f, (size, size), interpolation=cv2.INTER_AREA) for f in frames])
