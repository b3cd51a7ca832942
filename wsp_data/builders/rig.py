"""The simulator resources one task needs in one build worker."""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

import numpy as np

from wsp_data.builders.validity import check_rollout
from wsp_data.platforms import PlatformKit, kit


def rollout_problem(k: PlatformKit, qlimits: np.ndarray, ro) -> str | None:
    """The common validity checks (SPEC §5) of a platform rollout, read the way its platform needs."""
    return check_rollout(ro.stack("qpos"), ro.stack("tcp_pose"), ro.stack("object_poses"), k.joint_stream(ro),
                         qlimits, ro.actions, k.action_bounds)


class TaskRig:
    """The simulator resources of one task in one worker: expert source, unrendered and rendered replays."""

    def __init__(self, task: str, platform: str):
        self.kit = kit(platform)
        self.expert = self.kit.make_expert(task)
        self.spec = self.expert.spec
        self.state = self.expert.replayer
        self.render = self.kit.make_renderer(task, self.spec.objects)
        self.qlimits = self.state.qlimits

    def close(self) -> None:
        self.expert.close()
        self.render.close()

    def invalid(self, ro) -> str | None:
        return rollout_problem(self.kit, self.qlimits, ro)


R = TypeVar("R")


class RigCache(Generic[R]):
    """Rigs (`TaskRig` or a suite's own) keyed by their factory's arguments (a task, or a task and a prop),
    created on first use and kept for the life of the worker."""

    def __init__(self, factory: Callable[..., R] = TaskRig):
        self._factory = factory
        self._rigs: dict[tuple, R] = {}

    def __call__(self, *key) -> R:
        if key not in self._rigs:
            self._rigs[key] = self._factory(*key)
        return self._rigs[key]

    def close(self) -> None:
        for rig in self._rigs.values():
            rig.close()
        self._rigs.clear()
