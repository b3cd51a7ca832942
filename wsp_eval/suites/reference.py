"""What a suite scorer may read of the release for one instance: its row and its reference rollouts."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from wsp_eval.flow import ReferenceFlows, reference_flows
from wsp_eval.flow_cache import load_or_compute
from wsp_eval.object_track import ObjectPose
from wsp_eval.reference import iter_reference_frames, reference_masks, reference_object_masks, reference_object_poses
from wsp_eval.reference_cache import entry_folder, load_or_compute_result
from wsp_eval.release_format import split_config


@dataclass
class InstanceReference:
    """One instance of a config: its instance row, reference frames, robot and object masks per role (decoded
    once)."""

    config_dir: Path
    row: dict
    flow_cache: Path | None = None  # this release's and flow backend's reference-flow cache (`flow_cache`)
    result_cache: Path | None = None  # this release's and suite's reference-result cache (`reference_cache`)
    fingerprint: str = ""  # the config's verified content (`wsp_eval.integrity`): names its cache entries
    _cache: dict = field(default_factory=dict, repr=False)

    def episode(self, role: str) -> int:
        return self.row["episode_indices"][self.row["roles"].index(role)]

    def frames(self, role: str) -> np.ndarray:
        for _ in self._in_order(role):  # decodes what is left; the whole video is then kept
            pass
        return self._cache[("frames", role)]

    def _in_order(self, role: str) -> Iterator[np.ndarray]:
        """The role's reference frames in order: those decoded for an earlier caller first, then decoding on from
        where it stopped (one decoder per role while the instance is scored); decoded to its end, the video is
        kept as `frames(role)`."""
        key = ("frames", role)
        if key in self._cache:
            yield from self._cache[key]
            return
        if ("prefix", role) not in self._cache:
            self._cache[("prefix", role)] = ([], iter_reference_frames(self.config_dir, self.episode(role)))
        prefix, decoder = self._cache[("prefix", role)]
        k = 0
        while True:
            if k == len(prefix):
                frame = next(decoder, None)
                if frame is None:
                    self._cache[key] = np.stack(prefix)
                    del self._cache[("prefix", role)]
                    return
                prefix.append(frame)
            yield prefix[k]
            k += 1

    def masks(self, role: str) -> np.ndarray:
        key = ("masks", role)
        if key not in self._cache:
            self._cache[key] = reference_masks(self.config_dir, self.episode(role))
        return self._cache[key]

    def object_masks(self, role: str) -> np.ndarray:
        """The role's object label masks (length, H, W) uint8: k + 1 where object k is the visible surface."""
        key = ("objects", role)
        if key not in self._cache:
            self._cache[key] = reference_object_masks(self.config_dir, self.episode(role))
        return self._cache[key]

    def object_pose(self, role: str, k: int) -> ObjectPose:
        """Object column `k`'s simulator pose in every frame of the role, with the instance's camera."""
        key = ("pose", role, k)
        if key not in self._cache:
            poses = reference_object_poses(self.config_dir, self.episode(role))[:, k]
            self._cache[key] = ObjectPose(poses, np.asarray(self.row["camera_intrinsic"], np.float64),
                                          np.asarray(self.row["camera_extrinsic"], np.float64))
        return self._cache[key]

    def first_mask(self, role: str) -> np.ndarray:
        """The robot label mask of frame 0 (H, W), without decoding the others."""
        key = ("masks", role)
        if key in self._cache:
            return self._cache[key][0]
        return reference_masks(self.config_dir, self.episode(role), first_only=True)[0]

    def equals(self, role: str, frames: np.ndarray, mad: float) -> bool:
        """Whether `frames` (N, H, W, 3) uint8 are this role's reference video: the same shape and a mean absolute
        difference below `mad`. The reference is decoded only until the differences summed so far reach `mad`
        over the whole video (a video unlike its reference costs a few decoded frames, which the next seed
        reuses)."""
        if len(frames) != self.num_frames(role):
            return False
        budget, total, n = mad * frames.size, 0, 0
        for k, f in enumerate(self._in_order(role)):
            if k == len(frames) or f.shape != frames.shape[1:]:
                return False
            total += int(cv2.norm(frames[k], f, cv2.NORM_L1))  # Σ|a − b|, exact for uint8 (an integer below 2⁵³)
            if total >= budget:
                return False
            n += 1
        return n == len(frames)

    def cached(self, compute: Callable[[], dict], keys: tuple[str, ...] = ()) -> dict:
        """The suite's JSON-ready result on this instance's reference, from the reference-result cache when there
        is one (`wsp_eval.reference_cache`; an entry without every one of `keys` is recomputed), else `compute()`."""
        if self.result_cache is None:
            return compute()
        return load_or_compute_result(self.result_cache, self.cache_entry, self.episode(self.row["roles"][0]),
                                      compute, keys)

    @property
    def cache_entry(self) -> str:
        """This config's entry folder in the reference caches."""
        return entry_folder(self.config_dir.name, self.fingerprint)

    def num_frames(self, role: str) -> int:
        return int(self.row["num_frames"][self.row["roles"].index(role)])

    def reference_flows(self, role: str, duration: float, backend) -> ReferenceFlows:
        """RMFA's reference side over `duration` seconds, from the flow cache when there is one."""
        def compute() -> ReferenceFlows:
            return reference_flows(self.frames(role), self.masks(role), self.fps, duration, backend)

        if self.flow_cache is None:
            return compute()
        return load_or_compute(self.flow_cache, self.cache_entry, self.episode(role), duration, compute)

    @property
    def platform(self) -> str:
        """The config's platform (`t5_aloha` → `aloha`)."""
        return split_config(self.config_dir.name)[1]

    @property
    def fps(self) -> float:
        return float(self.row["fps"])
