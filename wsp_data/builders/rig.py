"""The simulator resources a build worker keeps: rigs (`wsp_data.platforms.contract.TaskRig` or a suite's own),
one per task (or task and scene)."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypeVar

from wsp_data.machine import return_freed_memory
from wsp_data.platforms.contract import TaskRig

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
            del oldest
            return_freed_memory()
        self._rigs[key] = rig = self._factory(*key)
        return rig

    def close_where(self, condition: Callable[[tuple, R], bool]) -> None:
        """Close and forget the rigs for which `condition(key, rig)` holds."""
        keys = [k for k, rig in self._rigs.items() if condition(k, rig)]
        for key in keys:
            self._rigs.pop(key).close()
        if keys:
            return_freed_memory()

    def close(self) -> None:
        for rig in self._rigs.values():
            rig.close()
        self._rigs.clear()
