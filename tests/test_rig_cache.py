"""The builders' rig cache (wsp_data.builders.rig.RigCache): bounded per platform (`rigs_per_worker`), least
recently used closed first. The factory here is a plain recorder: the cache's own logic is under test (the
simulator side — a build whose rigs are closed mid-way gives the same release — is the byte-identical LIBERO
rebuild with `rigs_per_worker` = 2 in test_libero_release.py)."""

from __future__ import annotations

import pytest

from wsp_data.builders.rig import RigCache
from wsp_data.platforms import kit


class Recorder:
    made: list[tuple] = []

    def __init__(self, *key):
        self.key, self.closed = key, False
        Recorder.made.append(key)

    def close(self) -> None:
        self.closed = True


def test_unbounded_cache_keeps_every_rig():
    Recorder.made = []
    cache = RigCache(Recorder)
    rigs = [cache(t) for t in ("a", "b", "c", "a", "b")]
    assert Recorder.made == [("a",), ("b",), ("c",)] and rigs[0] is rigs[3] and not any(r.closed for r in rigs)
    cache.close()
    assert all(r.closed for r in rigs)


def test_bounded_cache_closes_the_least_recently_used():
    Recorder.made = []
    cache = RigCache(Recorder, capacity=2)
    a, b = cache("a"), cache("b")
    assert cache("a") is a  # a is now the most recent
    c = cache("c")  # evicts b, not a
    assert b.closed and not a.closed and not c.closed
    b2 = cache("b")  # recreated; evicts a
    assert b2 is not b and a.closed and Recorder.made == [("a",), ("b",), ("c",), ("b",)]
    cache.close()
    assert c.closed and b2.closed


def test_close_where_closes_only_the_rigs_it_names():
    Recorder.made = []
    cache = RigCache(Recorder, capacity=3)
    a, b, c = cache("a"), cache("b"), cache("c")
    cache.close_where(lambda key, rig: key != ("b",) and rig is not c)
    assert a.closed and not b.closed and not c.closed
    assert cache("b") is b and cache("a") is not a  # kept, and made anew
    cache.close()


def test_capacity_must_hold_a_rig():
    with pytest.raises(ValueError, match="at least one rig"):
        RigCache(Recorder, capacity=0)


def test_platform_bounds():
    """LIBERO's rigs (≈ 0.8 GB each) are bounded to one; ManiSkill's are kept per task."""
    assert kit("libero").rigs_per_worker == 1 and kit("maniskill").rigs_per_worker is None


def test_slots_go_to_workers_grouped_by_simulator():
    """A build hands its slots out ordered by plan (task, then group), so consecutive slots share a rig; slots
    the survey left without a plan come first (they are decided at once)."""
    from wsp_data.build import by_simulator
    from wsp_data.builders import BuildConfig, SlotPlan
    from wsp_data.builders.t1 import T1Builder
    from wsp_data.builders.t5 import T5Builder

    t1 = T1Builder(BuildConfig("t1", "maniskill", 6, ("PushCube", "PickCube", "StackCube")))
    assert by_simulator(t1, list(range(6))) == [1, 4, 0, 3, 2, 5]  # PickCube, PushCube, StackCube
    assert by_simulator(t1, [5, 2, 3]) == [3, 2, 5]
    t1.exclude(frozenset(SlotPlan(t) for t in ("PushCube", "PickCube", "StackCube")))
    assert by_simulator(t1, [4, 1]) == [1, 4]
    t5 = T5Builder(BuildConfig("t5", "maniskill", 16, ("PickCube", "PushCube")))
    plans = [t5.plan(k) for k in by_simulator(t5, list(range(16)))]
    assert plans == sorted(plans, key=lambda p: (p.task, p.group)) and len(set(plans)) > 2
