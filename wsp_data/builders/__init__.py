"""Suite builders, found by name. One module per suite; this is the one place that registers them. Suites are
part of the benchmark's definition (seed ranges, release format), so `BUILDERS` takes no entry points."""

from __future__ import annotations

from wsp_data.builders.base import BuildConfig, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.t1 import T1Builder
from wsp_data.builders.t2 import T2Builder
from wsp_data.builders.t3 import T3Builder
from wsp_data.builders.t4 import T4Builder
from wsp_data.builders.t5 import T5Builder
from wsp_data.builders.train import TrainBuilder
from wsp_data.platforms.contract import Dropped
from wsp_eval.registry import Registry

BUILDERS: Registry[type[SuiteBuilder]] = Registry("suite builder")
BUILDERS.register(T1Builder.suite, T1Builder)
BUILDERS.register(T2Builder.suite, T2Builder)
BUILDERS.register(T3Builder.suite, T3Builder)
BUILDERS.register(T4Builder.suite, T4Builder)
BUILDERS.register(T5Builder.suite, T5Builder)
BUILDERS.register(TrainBuilder.suite, TrainBuilder)


def builder_class(suite: str) -> type[SuiteBuilder]:
    """The builder of `suite`; KeyError naming the known suites if there is none."""
    return BUILDERS[suite]


__all__ = ["BUILDERS", "BuildConfig", "Dropped", "Kept", "SlotPlan", "SuiteBuilder", "builder_class"]
