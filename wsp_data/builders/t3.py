"""T3 Action-source behaviour preservation (spec §3.3).

Slots come in groups of eight that share task, episode and scene seed, one per source: the scripted expert,
five scripted operator models H1–H5, and an early and a late behaviour-
cloning policy checkpoint (the platform's `PlatformKit.t3_source`). Slot k belongs to group g = k // 8, gets source
`SOURCE_GROUPS[k % 8]` and task `tasks[g % len(tasks)]`.

The group's scene seed is the first candidate `config.scene_seed(8·g, a)` (a = 0, 1, …) on which the expert
succeeds and all eight streams replay validly without rendering (spec §5 common checks; successes and
failures of operators and policies are both kept) and RMFA can score every one (≥ 1 window with active robot
pixels). Every slot of the group evaluates the same candidates in the same order (the outcome is cached per
worker), so all eight land on the same seed; slot k's attempt a uses candidate a and renders only its own
stream. Columns: `source_group`, `source_kind` (scripted_expert / scripted_operator / bc_policy / human_teleop),
`source_provenance` (JSON: operator parameters, or checkpoint, training steps and measured success),
`group_id` (task and seed), `source_success`, `steps`.
The tasks that have operators and policies are the platform's (`PlatformKit.t3_tasks`). Every source, the
expert included (`ExpertStream`), is asked the same thing: `stream(seed)`, the T3 source protocol of
`wsp_data.platforms.t3_sources`.
"""

from __future__ import annotations

import json

import numpy as np

from wsp_data.builders.base import BuildConfig, Dropped, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache, TaskRig
from wsp_data.platforms.t3_sources import ExpertStream, SourceStream, T3Source
from wsp_data.schema import FPS
from wsp_data.staging import RolloutArrays
from wsp_eval.flow import active_pixels_per_window, reference_flows

OPERATOR_GROUPS = ("H1", "H2", "H3", "H4", "H5")  # each platform's operator models (tested)
POLICY_GROUPS = ("policy_early", "policy_late")  # each platform's policy stages (tested)
EXPERT_GROUP = "expert"
SOURCE_GROUPS = (EXPERT_GROUP, *OPERATOR_GROUPS, *POLICY_GROUPS)
GROUP_SIZE = len(SOURCE_GROUPS)


class _Rig(TaskRig):
    """One task's expert, operators and policies, with unrendered and rendered replays."""

    def __init__(self, task: str, platform: str):
        super().__init__(task, platform)
        self.task = task
        self._sources: dict[str, T3Source] = {
            EXPERT_GROUP: ExpertStream(self.expert, self.kit.expert_script(task))}

    def source(self, group: str) -> T3Source:
        if group not in self._sources:
            self._sources[group] = self.kit.t3_source(self.task, group, self.state)
        return self._sources[group]

    def stream(self, group: str, seed: int) -> SourceStream:
        """The group's action stream on `seed` and its provenance (stream None: the source produced none)."""
        return self.source(group).stream(seed)

    def close(self) -> None:
        for s in self._sources.values():
            s.close()
        super().close()


def source_kind(provenance: dict) -> str:
    return provenance.get("kind", "unknown")


class T3Builder(SuiteBuilder):
    suite = "t3"
    title = "T3 Action-source behaviour preservation"
    description = ("Groups of eight rollouts sharing task, episode and scene seed, one per action source: the "
                   "scripted expert, scripted operator models H1-H5 (distinct speed, jerkiness, hesitation and "
                   "re-approach, approach direction) and an early and a late behaviour-cloning policy checkpoint; "
                   "successes and failures kept. Columns `source_group`, `source_kind`, `source_provenance`, "
                   "`group_id`. Score: RMFA, per source group and overall.")
    roles = ("reference",)

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        known = self.kit.t3_tasks()
        self.tasks = tuple(t for t in dict.fromkeys(config.tasks) if t in known)
        if not self.tasks:
            raise ValueError(f"T3 runs on {', '.join(known)} (trained policies and operator models); none selected")
        self.rig = RigCache(lambda task: _Rig(task, config.platform), self.kit.rigs_per_worker)
        self._groups: dict[tuple[str, int], dict | str] = {}

    def close(self) -> None:
        self.rig.close()

    def plan(self, slot: int) -> SlotPlan:
        return SlotPlan(self.tasks[(slot // GROUP_SIZE) % len(self.tasks)], SOURCE_GROUPS[slot % GROUP_SIZE])

    def group(self, task: str, seed: int) -> dict | str:
        """All eight streams of a candidate group seed, validated unrendered, or the reason it is unusable."""
        key = (task, seed)
        if key not in self._groups:
            self._groups[key] = self._validate_group(task, seed)
        return self._groups[key]

    def _validate_group(self, task: str, seed: int) -> dict | str:
        rig = self.rig(task)
        streams = {}
        for group in SOURCE_GROUPS:
            stream = rig.stream(group, seed)
            if stream.actions is None:
                return "expert_failed" if group == EXPERT_GROUP else f"{group}_no_stream"
            ro = rig.state.replay(seed, stream.actions)
            if group == EXPERT_GROUP and not ro.success:
                return "expert_failed"
            if (why := rig.invalid(ro)) is not None:
                return f"{group}_{why}"
            streams[group] = (stream.actions, stream.provenance, bool(ro.success))
        return streams

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        slot, attempt = self.config.slot_attempt(seed)
        group_seed = self.config.scene_seed(GROUP_SIZE * (slot // GROUP_SIZE), attempt)
        streams = self.group(plan.task, group_seed)
        if isinstance(streams, str):
            return Dropped(f"group_{streams}")
        actions, provenance, success = streams[plan.group]
        rig = self.rig(plan.task)
        ro = rig.render.replay(group_seed, actions)
        steps = len(actions)
        if (why := rig.invalid(ro)) is not None:
            return Dropped(f"rendered_{why}", steps)
        active = active_pixels_per_window(*reference_flows(ro.stack("rgb"), ro.stack("mask"), FPS))
        if not (active > 0).any():
            return Dropped("no_scorable_motion", steps)
        row = {
            "task": plan.task, "seed": group_seed, "instruction": rig.spec.instruction,
            "objects": list(rig.spec.objects), "source": f"{source_kind(provenance)}:{plan.group}",
            "source_group": plan.group, "source_kind": source_kind(provenance),
            "source_provenance": json.dumps(provenance, sort_keys=True), "group_id": f"{plan.task}:{group_seed}",
            "source_success": success, "steps": steps, "active_windows": int((active > 0).sum()),
            "interventions": {"reference": {"source_group": plan.group}},
        }
        return Kept(row, [RolloutArrays.from_rollout("reference", ro)], steps)
