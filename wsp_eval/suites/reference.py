"""What a suite scorer may read of the release for one instance: its row and its reference rollouts."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wsp_eval.reference import reference_frames, reference_masks


@dataclass
class InstanceReference:
    """One instance of a config: its instance row, reference frames and robot masks per role (decoded once)."""

    config_dir: Path
    row: dict
    _cache: dict = field(default_factory=dict, repr=False)

    def episode(self, role: str) -> int:
        return self.row["episode_indices"][self.row["roles"].index(role)]

    def frames(self, role: str) -> np.ndarray:
        key = ("frames", role)
        if key not in self._cache:
            self._cache[key] = reference_frames(self.config_dir, self.episode(role))
        return self._cache[key]

    def masks(self, role: str) -> np.ndarray:
        key = ("masks", role)
        if key not in self._cache:
            self._cache[key] = reference_masks(self.config_dir, self.episode(role))
        return self._cache[key]

    @property
    def fps(self) -> float:
        return float(self.row["fps"])
