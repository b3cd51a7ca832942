"""What every suite builder shares: the build config, the accepted attempt (`Kept`; a rejected one is a
`wsp_data.platforms.contract.Dropped`), and the `SuiteBuilder` base class whose hooks a suite module fills in.

A build has `count` slots. Slot k is planned by `SuiteBuilder.plan(k)` (default: task `tasks[k % len(tasks)]`,
no group; suites balanced by kind or primitive override it) and tries attempts
a = 0, 1, … (scene seed `config.scene_seed(k, a)`, proposal RNG seeded by (build seed, k, a)) until one
is kept or `max_attempts` are spent. A slot's outcome depends only on (config, k): shards, workers and
resumed runs therefore produce the same instances.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np

from wsp_data.platforms import KITS, kit
from wsp_data.platforms.contract import Dropped
from wsp_data.schema import MAX_ATTEMPTS, PRIVATE_RANGE, SEED_BASE, SUITES, scene_seed, slot_attempt
from wsp_data.staging import RolloutArrays


@dataclass(frozen=True)
class BuildConfig:
    """Everything that determines a config's content. Two builds with equal configs are byte-identical."""

    suite: str
    platform: str
    count: int
    tasks: tuple[str, ...]
    seed: int = 0
    max_attempts: int = 8
    seed_range: str = ""  # scene seeds from this suite's range ("" = the config's own suite); "train" for judge data
    primitives: tuple[str, ...] = ()  # T5 only: restrict slots to these primitives (() = all the platform's)

    def __post_init__(self):
        if self.suite not in SUITES:
            raise ValueError(f"unknown suite {self.suite!r}; known: {', '.join(SUITES)}")
        if self.platform not in KITS:
            raise ValueError(f"unknown platform {self.platform!r}; known: {', '.join(KITS)}")
        if self.count <= 0:
            raise ValueError(f"--count must be a positive number of instances, got {self.count}")
        if not self.tasks:
            raise ValueError("no tasks selected")
        if not 1 <= self.max_attempts <= MAX_ATTEMPTS:
            raise ValueError(f"max_attempts must be in [1, {MAX_ATTEMPTS}], got {self.max_attempts}")
        if self.seed_range and self.seed_range not in (*SEED_BASE, PRIVATE_RANGE):
            raise ValueError(f"unknown seed range {self.seed_range!r}; known: {', '.join((*SEED_BASE, PRIVATE_RANGE))}")
        if self.primitives:
            self._check_primitives()
        if self.seed_range == PRIVATE_RANGE:
            self.scene_seed(0, 0)  # refuses a private range without a key (build seed 0), before anything runs

    def _check_primitives(self) -> None:
        """`primitives` must name T5 primitives the platform scripts (a platform without T5 is refused by the builder)."""
        if self.suite != "t5":
            raise ValueError(f"--primitives restricts T5's scripted primitives; the {self.suite} suite has none")
        platform = kit(self.platform)
        if platform.unsupported("t5") is None:
            scripted = platform.t5_primitives()
            unknown = [p for p in self.primitives if p not in scripted]
            if unknown:
                raise ValueError(f"unknown primitive(s) {', '.join(unknown)}; the {self.platform} platform scripts "
                                 f"{', '.join(scripted)}")

    @property
    def scene_suite(self) -> str:
        """Whose scene-seed range the slots draw from (`schema.SEED_BASE`, or `schema.PRIVATE_RANGE`)."""
        return self.seed_range or self.suite

    def scene_seed(self, slot: int, attempt: int) -> int:
        """The scene seed of slot `slot`'s attempt `attempt` (`schema.scene_seed`)."""
        return scene_seed(self.scene_suite, slot, attempt, self.seed)

    def slot_attempt(self, seed: int) -> tuple[int, int]:
        """The slot and attempt that drew scene seed `seed`."""
        return slot_attempt(self.scene_suite, seed, self.seed)

    @property
    def name(self) -> str:
        return f"{self.suite}_{self.platform}"

    def to_json(self) -> dict:
        d = asdict(self)
        d["tasks"] = list(self.tasks)
        d["primitives"] = list(self.primitives)
        for key in ("seed_range", "primitives"):
            if not d[key]:
                del d[key]  # defaults are left out, so configs written before the field read the same
        return d

    @classmethod
    def from_json(cls, d: dict) -> BuildConfig:
        return cls(**{**d, "tasks": tuple(d["tasks"]), "primitives": tuple(d.get("primitives", ()))})

    def task_of(self, slot: int) -> str:
        return self.tasks[slot % len(self.tasks)]

    def rng(self, slot: int, attempt: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, slot, attempt])

    def dumps(self) -> str:
        return json.dumps(self.to_json(), sort_keys=True)


@dataclass
class Kept:
    """An accepted proposal: the instance row (suite-specific fields) and its rollouts in role order.

    The row must hold `task`, `seed`, `instruction`, `objects` (pose/contact columns, in order) and `source`;
    `interventions` ({role: parameters}) is optional. `rendered_steps` / `simulated_steps` count the
    rendered and unrendered simulator steps the proposal cost (build report: rendering saved)."""

    row: dict
    rollouts: list[RolloutArrays]
    rendered_steps: int = 0
    simulated_steps: int = 0


@dataclass(frozen=True)
class SlotPlan:
    """What a slot must produce: its task and, for suites balanced by kind or primitive, its group."""

    task: str
    group: str | None = None


class SuiteBuilder(ABC):
    """One suite on one platform. Everything simulator-specific comes from the platform's kit (`self.kit`, a
    `wsp_data.platforms.interface.PlatformKit`); a builder never names a platform. A platform that cannot serve
    the suite says why (`PlatformKit.unsupported`) and the builder refuses the config before simulating.

    Roles:
        `roles`: the scored rollouts of one instance, in order (e.g. original, small, large). A suite may
        append one unscored rollout of role `SOURCE_ROLE`: the unperturbed source (instance columns
        `source_episode_index` / `source_episode_id`; the action-blind baseline plays it back).
    Hooks:
        `plan(slot)`: the slot's task (and group); default balances slots over the config's tasks. None when
        the pair survey excluded every pair the slot could draw (the slot is decided with no attempt).
        `attempt(plan, seed, rng)`: propose, execute (unrendered first), validate, render what passed.
        `survey_pairs()`, `screen(plan, seed, rng)`: the (task, group) pairs the slots draw from and the checks
        a proposal for one passes before rendering, for the pair survey (`wsp_data.pair_survey`); default: no
        survey (`wsp_data.builders.source_survey.SourceSurvey`: one pair per task, its expert source checked).
        `survey_renders`: whether a large config's survey also checks a proposal's rendered replay.
        `exclude(pairs)`: the pairs the survey found no proposal for, left out of `plan`.
        `close()`: release simulator resources.
    """

    suite: ClassVar[str]
    title: ClassVar[str]
    description: ClassVar[str]
    roles: ClassVar[tuple[str, ...]]
    survey_renders: ClassVar[bool] = True

    def __init__(self, config: BuildConfig):
        self.kit = kit(config.platform)
        if (why := self.kit.unsupported(self.suite)) is not None:
            raise ValueError(f"{self.suite} cannot be built on platform {config.platform!r}: {why}")
        self.config = config

    def plan(self, slot: int) -> SlotPlan | None:
        return SlotPlan(self.config.task_of(slot))

    def survey_pairs(self) -> tuple[SlotPlan, ...]:
        """The pairs the pair survey screens before any slot; none by default."""
        return ()

    def screen(self, plan: SlotPlan, seed: int, rng: np.random.Generator,
               rendered: bool = False) -> tuple[str | None, int]:
        """Why a proposal for `plan` at scene seed `seed` is dropped before rendering (None when it passes every
        check made before rendering: what `attempt` would render; with `rendered`, every check `attempt` makes),
        and the simulator steps spent."""
        raise NotImplementedError(f"{type(self).__name__} has no pair survey")

    def exclude(self, pairs: frozenset[SlotPlan]) -> None:
        """Leave `pairs` (found by the survey to yield nothing) out of `plan`."""
        if pairs:
            raise NotImplementedError(f"{type(self).__name__} has no pair survey")

    @abstractmethod
    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        """Try one proposal for `plan.task` (and `plan.group`) at scene seed `seed`."""

    def close(self) -> None:
        """Release simulator resources."""
