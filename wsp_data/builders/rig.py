"""The simulator resources one task needs in one build worker."""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

from wsp_data.builders.validity import check_rollout
from wsp_data.platforms.maniskill import ManiSkillPlatform, Rollout, _np
from wsp_data.sources.experts import ExpertSource, task_spec


class TaskRig:
    """The simulator resources of one task in one worker: expert source, unrendered and rendered replays."""

    def __init__(self, task: str):
        spec = task_spec(task)
        self.spec = spec
        self.expert = ExpertSource(task)
        self.state = self.expert.replayer
        self.render = ManiSkillPlatform(task, render=True, objects=spec.objects)
        self.qlimits = _np(self.state.robot.get_qlimits()[0])

    def close(self) -> None:
        self.expert.close()
        self.render.close()

    def invalid(self, ro: Rollout) -> str | None:
        return check_rollout(ro.stack("qpos"), ro.stack("tcp_pose"), ro.stack("object_poses"), ro.actions,
                             self.qlimits)


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
