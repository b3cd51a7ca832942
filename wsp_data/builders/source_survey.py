"""The source survey: for suites whose every proposal starts from a task's scripted-expert source (T1, T2, T4 and
the training split), the pair survey (`wsp_data.pair_survey`) screens each task the slots draw before any slot.
A task passes when one of its survey scenes yields an expert stream whose unrendered replay succeeds and is valid
(spec §5); a task none passes (e.g. an expert that always drives the arm past a joint limit) is left out of every
slot's plan, with its drop reasons in the build report, instead of burning `max_attempts` proposals per slot."""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import SlotPlan
from wsp_data.platforms.contract import rollout_problem


class SourceSurvey:
    """Mixin (before `SuiteBuilder`) for a builder whose `self.rig(task)` gives a rig with `expert` and `state`
    (its unrendered replays). Its default `plan` balances slots over the usable
    tasks (the config's task order, as `BuildConfig.task_of` does when none is excluded); a builder with its own
    `plan` draws from `usable(tasks)`."""

    survey_renders = False  # the screen checks the source only; rendered checks stay with the slots
    excluded_tasks: frozenset[str] = frozenset()

    def plan(self, slot: int) -> SlotPlan | None:
        tasks = self.usable(self.config.tasks)
        return SlotPlan(tasks[slot % len(tasks)]) if tasks else None

    def survey_pairs(self) -> tuple[SlotPlan, ...]:
        """One pair per task the config's slots draw while none is left out, in the order of first draw (a task
        a slot draws only after exclusions is not screened: it costs its slots what it costs without a survey)."""
        return tuple(SlotPlan(task) for task in dict.fromkeys(self.plan(k).task for k in range(self.config.count)))

    def screen(self, plan: SlotPlan, seed: int, rng: np.random.Generator,
               rendered: bool = False) -> tuple[str | None, int]:
        """Why the task's expert source at `seed` is unusable (None: it scripts, and its unrendered replay
        succeeds and passes the common validity checks, `rollout_problem`), and the unrendered steps replayed."""
        rig = self.rig(plan.task)
        actions = rig.expert.trajectory(seed)
        if actions is None:
            return "source_failed", 0
        ro = rig.state.replay(seed, actions)
        if (why := rollout_problem(self.kit, rig.state.qlimits, ro)) is not None:
            return f"source_{why}", len(actions)
        return (None if ro.success else "source_replay_failed"), len(actions)

    def exclude(self, pairs: frozenset[SlotPlan]) -> None:
        self.excluded_tasks = frozenset(p.task for p in pairs)

    def usable(self, tasks: tuple[str, ...]) -> tuple[str, ...]:
        """`tasks` less those the survey excluded, in order."""
        return tuple(t for t in tasks if t not in self.excluded_tasks)
