"""Suite builders, found by name. One module per suite; this is the one place that registers them."""

from __future__ import annotations

from wsp_data.builders.base import BuildConfig, Dropped, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.t1 import T1Builder
from wsp_data.builders.t2 import T2Builder
from wsp_data.builders.t3 import T3Builder
from wsp_data.builders.t4 import T4Builder
from wsp_data.builders.t5 import T5Builder
from wsp_data.builders.train import TrainBuilder

BUILDERS: dict[str, type[SuiteBuilder]] = {b.suite: b for b in (T1Builder, T2Builder, T3Builder, T4Builder, T5Builder, TrainBuilder)}


def builder_class(suite: str) -> type[SuiteBuilder]:
    if suite not in BUILDERS:
        raise KeyError(f"suite {suite!r} has no builder yet; available: {', '.join(sorted(BUILDERS))}")
    return BUILDERS[suite]


__all__ = ["BUILDERS", "BuildConfig", "Dropped", "Kept", "SlotPlan", "SuiteBuilder", "builder_class"]
