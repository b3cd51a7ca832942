"""The simulator resources one task needs in one build worker."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypeVar

import numpy as np

from wsp_data.builders.validity import check_rollout
from wsp_data.platforms import PlatformKit, kit


def rollout_problem(k: PlatformKit, qlimits: np.ndarray, ro) -> str | None:
    """The common validity checks (spec §5) of a platform rollout, read the way its platform needs."""
    return check_rollout(ro.stack("qpos"), ro.stack("tcp_pose"), ro.stack("object_poses"), k.joint_stream(ro),
                         qlimits, ro.actions, k.action_bounds, k.arm_joints)


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
    created on first use and kept for the life of the worker — at most `capacity` of them (the platform's
    `rigs_per_worker`; None: all), the least recently used closed first. A bounded cache is for builders that
    hold one rig per attempt: a rig fetched earlier in the same attempt could otherwise be closed under them.
    Rigs carry no state between attempts (every replay resets from its seed), so a rig created anew gives the
    same rollouts as the one it replaces."""

    def __init__(self, factory: Callable[..., R] = TaskRig, capacity: int | None = None):
        if capacity is not None and capacity < 1:
            raise ValueError(f"a rig cache holds at least one rig, got capacity {capacity}")
        self._factory = factory
        self._capacity = capacity
        self._rigs: OrderedDict[tuple, R] = OrderedDict()

    def __call__(self, *key) -> R:
        if key in self._rigs:
            self._rigs.move_to_end(key)
            return self._rigs[key]
        while self._capacity is not None and len(self._rigs) >= self._capacity:
            _, oldest = self._rigs.popitem(last=False)
            oldest.close()
        self._rigs[key] = rig = self._factory(*key)
        return rig

    def close(self) -> None:
        for rig in self._rigs.values():
            rig.close()
        self._rigs.clear()
