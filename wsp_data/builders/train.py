"""`train_<platform>`: expert rollouts for training world models (issue: training split).

Each instance is one rendered, replay-verified scripted-expert episode (role `expert`) of a benchmark task,
on scene seeds from the training range (`SEED_BASE["train"]`), disjoint from every test suite's range, in
the same LeRobot format as the test configs, so LeRobot's own dataloader trains on it directly. Tasks whose
expert yields no valid source on any survey scene are left out (`SourceSurvey`).
"""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import BuildConfig, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache
from wsp_data.builders.source_survey import SourceSurvey
from wsp_data.platforms.contract import Dropped, TaskRig
from wsp_data.staging import RolloutArrays

EPISODES_PER_TASK = 100  # default size: 100 expert episodes per task


class TrainBuilder(SourceSurvey, SuiteBuilder):
    suite = "train"
    title = "Training split"
    description = ("Scripted-expert rollouts of the benchmark tasks on training-range scene seeds (disjoint from "
                   "every test suite), one episode per row, for training world models with LeRobot's dataloader.")
    roles = ("expert",)

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        self.rig = RigCache(lambda task: TaskRig(task, config.platform), self.kit.rigs_per_worker)

    def close(self) -> None:
        self.rig.close()

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        rig = self.rig(plan.task)
        # The rendered replay checks success itself, so the expert's unrendered verifying replay is skipped where
        # it has one (`scripted`): it would cost ≈ 10 % of a kept instance (docs/performance.md).
        # A slot's first attempt is rendered at once; once an attempt of the slot was dropped (a task whose expert
        # often breaks a check), each next one is replayed unrendered first, so a drop costs no rendering.
        actions = getattr(rig.expert, "scripted", rig.expert.trajectory)(seed)
        if actions is None:
            return Dropped("source_failed")
        simulated = len(actions)
        if self.config.slot_attempt(seed)[1] > 0:
            ro = rig.state.replay(seed, actions)
            simulated += len(actions)
            if (why := rig.invalid(ro) or (None if ro.success else "reference_failed")) is not None:
                return Dropped(why, simulated_steps=len(actions))  # the rendering it avoided
        ro = rig.render.replay(seed, actions)
        if not ro.success:
            return Dropped("rendered_reference_failed", len(actions), simulated)
        if (why := rig.invalid(ro)) is not None:
            return Dropped(why, len(actions), simulated)
        row = {"task": plan.task, "seed": seed, "instruction": rig.spec.instruction,
               "objects": list(rig.spec.objects), "source": "scripted_expert"}
        return Kept(row, [RolloutArrays.from_rollout("expert", ro)], len(actions), simulated)
