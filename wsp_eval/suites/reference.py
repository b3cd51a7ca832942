"""What a suite scorer may read of the release for one instance: its row and its reference rollouts."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wsp_eval.flow import ReferenceFlows, reference_flows
from wsp_eval.flow_cache import load_or_compute
from wsp_eval.reference import reference_frames, reference_masks
from wsp_eval.release_format import split_config


@dataclass
class InstanceReference:
    """One instance of a config: its instance row, reference frames and robot masks per role (decoded once)."""

    config_dir: Path
    row: dict
    flow_cache: Path | None = None  # this release's and flow backend's reference-flow cache (`flow_cache`)
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

    def num_frames(self, role: str) -> int:
        return int(self.row["num_frames"][self.row["roles"].index(role)])

    def reference_flows(self, role: str, duration: float, backend) -> ReferenceFlows:
        """RMFA's reference side over `duration` seconds, from the flow cache when there is one."""
        def compute() -> ReferenceFlows:
            return reference_flows(self.frames(role), self.masks(role), self.fps, duration, backend)

        if self.flow_cache is None:
            return compute()
        return load_or_compute(self.flow_cache, self.config_dir.name, self.episode(role), duration, compute)

    @property
    def platform(self) -> str:
        """The config's platform (`t5_aloha` → `aloha`)."""
        return split_config(self.config_dir.name)[1]

    @property
    def fps(self) -> float:
        return float(self.row["fps"])
