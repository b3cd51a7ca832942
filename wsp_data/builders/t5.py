"""T5 Interaction dynamics (spec §3.5).

Proposal: a replay-verified successful expert trajectory of the slot's task; its branch step is
`BACKOFF` steps before first contact (the first frame where a robot link touches the task's target, or the
target has moved 2 mm, whichever comes first: contacts shorter than a physics substep can go unflagged). The
expert is re-run up to that step and the slot's primitive replaces the rest: the platform's T5 rig does this
(`PlatformKit.t5_rig(...).branch`, returning a `Branch`: `wsp_data.platforms.contract` holds it and the
branch point's helpers), and may add a prop beside the target
(`PlatformKit.t5_scene`; ManiSkill's knock-over and tap), whose source must succeed with the prop untouched.
Validation, unrendered first: common validity (spec §5), no other object shifted by more than 1 cm, and the
primitive's acceptance rule (`t5_rules`, with the platform's `t5_rule_thresholds`) on the evaluated object's
simulator states; only then rendered, and re-checked on the rendered rollout; its score must be defined: the
evaluated object's image moves visibly (`wsp_eval.object_track`, spec §4.3), as RMFA's suites require a scorable
window. Slots are
balanced exactly by primitive over the platform's primitives (`PlatformKit.t5_primitives`): slot k gets the
(k mod n)-th and the next of that primitive's compatible tasks (`PlatformKit.t5_primitive_tasks`) in turn, less
the (task, primitive) pairs the pair survey found no passing proposal for (`wsp_data.pair_survey`).
"""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import BuildConfig, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache
from wsp_data.builders.t5_rules import check
from wsp_data.platforms.contract import Branch, Dropped, T5Rig, max_shift
from wsp_data.platforms.interface import Rollout
from wsp_data.schema import SOURCE_ROLE
from wsp_data.staging import RolloutArrays
from wsp_eval.object_track import ObjectPose, object_track
from wsp_eval.tracking import frame_size, project

OTHER_OBJECT_MAX_SHIFT = 0.01  # m: any other object moving more is an unintended collision


def object_motion_scorable(rendered: Rollout, ev: int) -> bool:
    """Whether the evaluated object (column `ev`) moves visibly in its reference video (`ObjectTrack.scorable`)."""
    pose = ObjectPose(rendered.stack("object_poses")[:, ev], rendered.intrinsic, rendered.extrinsic)
    return object_track(rendered.stack("rgb"), rendered.stack("objects"), ev + 1, rendered.stack("mask"),
                        pose).scorable


class T5Builder(SuiteBuilder):
    suite = "t5"
    title = "T5 Interaction dynamics"
    description = ("A replay-verified expert trajectory branched 4 steps before first contact, the rest replaced by a "
                   "scripted primitive (push, pull, drag, rotate, shake, tap, knock-over, drop), balanced by "
                   "primitive. Kept only when the evaluated object's simulator states pass the primitive's rule "
                   "(`primitive`, `evaluated_object` and the measured quantities are columns). Score: primitive "
                   "object-response fidelity (where the generated video shows the object against where the "
                   "reference does), gated by the arm's RMFA.")
    roles = ("reference",)

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        scripted = self.kit.t5_primitives()  # `config.primitives` names some of them (BuildConfig checks)
        self.primitives = tuple(p for p in scripted if p in config.primitives) if config.primitives else scripted
        self.primitive_tasks = self.kit.t5_primitive_tasks(config.tasks)
        self.rig = RigCache(self.kit.t5_rig, self.kit.rigs_per_worker)
        self.thresholds = self.kit.t5_rule_thresholds()
        missing = [p for p in self.primitives if not self.primitive_tasks[p]]
        if missing:
            raise ValueError(f"T5 needs, for every primitive, {self.kit.t5_needs()}; none for {', '.join(missing)}")

    excluded: frozenset[SlotPlan] = frozenset()

    def compatible(self, primitive: str) -> tuple[str, ...]:
        return self.primitive_tasks[primitive]

    def plan(self, slot: int) -> SlotPlan | None:
        primitive = self.primitives[slot % len(self.primitives)]
        tasks = tuple(t for t in self.compatible(primitive) if SlotPlan(t, primitive) not in self.excluded)
        return SlotPlan(tasks[(slot // len(self.primitives)) % len(tasks)], primitive) if tasks else None

    def survey_pairs(self) -> tuple[SlotPlan, ...]:
        """Every (task, primitive) pair of the primitives the config's slots get."""
        used = self.primitives[: self.config.count]
        return tuple(SlotPlan(t, p) for p in used for t in self.compatible(p))

    def screen(self, plan: SlotPlan, seed: int, rng: np.random.Generator,
               rendered: bool = False) -> tuple[str | None, int]:
        if rendered:
            out = self.attempt(plan, seed, rng)
            steps = out.rendered_steps + out.simulated_steps
            return (None, steps) if isinstance(out, Kept) else (out.reason, steps)
        rig = self.rig(plan.task, self.kit.t5_scene(plan.group))
        b = rig.branch(plan.group, seed)
        if isinstance(b, Dropped):
            return b.reason, b.simulated_steps
        simulated, dropped = self._unrendered(plan, rig, seed, b)
        return None if dropped is None else dropped.reason, simulated

    def exclude(self, pairs: frozenset[SlotPlan]) -> None:
        self.excluded = frozenset(pairs)

    def close(self) -> None:
        self.rig.close()

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        rig = self.rig(plan.task, self.kit.t5_scene(plan.group))
        b = rig.branch(plan.group, seed)
        if isinstance(b, Dropped):
            return b
        return self._validate(plan, rig, seed, b)

    def _unrendered(self, plan: SlotPlan, rig: T5Rig, seed: int, b: Branch) -> tuple[int, Dropped | None]:
        """Replay the branched stream unrendered and check it: the unrendered steps so far, and why it is
        dropped (None: it passes)."""
        ro = rig.state.replay(seed, b.stream, b.placements)
        simulated = b.simulated + len(b.stream)
        why = self.reject(rig, ro, plan.group, rig.objects.index(b.evaluated))
        return simulated, None if why is None else Dropped(why, simulated_steps=simulated)

    def _validate(self, plan: SlotPlan, rig: T5Rig, seed: int, b: Branch) -> Kept | Dropped:
        """Replay the branched stream unrendered, check it, render it, check again, and make the instance."""
        primitive, spec = plan.group, rig.spec
        source, stream, placements, evaluated = b.source, b.stream, b.placements, b.evaluated
        ev = rig.objects.index(evaluated)
        simulated, dropped = self._unrendered(plan, rig, seed, b)
        if dropped is not None:
            return dropped
        rendered = rig.render.replay(seed, stream, placements)
        steps = len(stream)
        if (why := self.reject(rig, rendered, primitive, ev)) is not None:
            return Dropped(f"rendered_{why}", steps, simulated)
        poses = rendered.stack("object_poses")
        first = rendered.observations[0]
        pixel = project(poses[0, ev, :3], rendered.intrinsic, rendered.extrinsic, frame_size(first.rgb))
        if not object_motion_scorable(rendered, ev):
            return Dropped("no_scorable_object_motion", steps, simulated)
        base_xy = rig.base_xy()
        _, measured = check(primitive, poses[:, ev], rendered.stack("contacts")[:, ev], base_xy, **self.thresholds)
        parameters = {"primitive": primitive, "evaluated_object": evaluated, "branch_step": b.branch,
                      "placements": {k: v.astype(float).tolist() for k, v in (placements or {}).items()}}
        row = {
            "task": plan.task, "seed": seed, "instruction": spec.instruction, "objects": list(rig.objects),
            "source": "scripted_expert+scripted_primitive", "primitive": primitive, "evaluated_object": evaluated,
            "evaluated_index": ev, "branch_step": b.branch, "first_contact_step": b.contact,
            "source_length": len(source), "robot_base_xy": base_xy,
            "object_pixel_256": [float(x) for x in pixel],
            **measured, "interventions": {"reference": parameters},
        }
        src = rig.render.replay(seed, source, placements)  # the unperturbed source: the expert, no primitive
        return Kept(row, [RolloutArrays.from_rollout("reference", rendered),
                          RolloutArrays.from_rollout(SOURCE_ROLE, src)], steps + len(source), simulated)

    def reject(self, rig: T5Rig, ro: Rollout, primitive: str, ev: int) -> str | None:
        """Why a rollout is not a valid reference of `primitive` on object column `ev`, or None."""
        if (why := rig.invalid(ro)) is not None:
            return why
        poses = ro.stack("object_poses")
        if any(max_shift(poses[:, i]) > OTHER_OBJECT_MAX_SHIFT for i in range(len(rig.objects)) if i != ev):
            return "disturbed_other_object"
        ok, _ = check(primitive, poses[:, ev], ro.stack("contacts")[:, ev], rig.base_xy(), **self.thresholds)
        return None if ok else "primitive_not_observed"
