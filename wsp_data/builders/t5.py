"""T5 Interaction dynamics (SPEC §3 T5).

Proposal: a replay-verified successful expert trajectory of the slot's task; its branch step is
`BACKOFF` steps before first contact (the first frame where a robot link touches the task's target, or the
target has moved 2 mm, whichever comes first: contacts shorter than a physics substep can go unflagged). The
expert's script is re-run up to that step and the slot's primitive (`wsp_data.platforms.maniskill.primitives`) replaces
the rest. Knock-over and tap act on a prop added beside the target by a scene hook (a tall box, a ball); their
source must succeed with the prop resting there untouched.
Validation, unrendered first: common validity (SPEC §5), no other object shifted by more than 1 cm, and the
primitive's acceptance rule (`t5_rules`) on the evaluated object's simulator states; only then rendered, and
re-checked on the rendered rollout. Slots are balanced exactly by primitive: slot k gets `PRIMITIVES[k % 8]`
and the next of that primitive's compatible tasks (`PRIMITIVE_TASKS`) in turn.
LIBERO uses push, pull, tap and drop (`t5_rules.PLATFORM_PRIMITIVES`), no props: the branch replays the
expert's OSC stream up to the branch step and `libero_primitives` continues closed-loop; push and tap serve
tasks with a low target (`libero_primitives.compatible`).
"""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import BuildConfig, Dropped, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache, TaskRig, rollout_problem
from wsp_data.builders.t5_rules import MOTION_ONSET, PLATFORM_PRIMITIVES, check
from wsp_data.platforms import kit
from wsp_data.schema import IMAGE_SIZE, SOURCE_ROLE
from wsp_data.staging import RolloutArrays
from wsp_eval.tracking import project

# Which tasks serve which primitive. The evaluated object is the task's target (first object), except for
# knock-over and tap, whose evaluated object is their prop (`PROPS`): the tasks' own objects are no tall
# objects, and a cube stops as soon as the hand leaves it, so only a rolling ball answers a brief strike.
PRIMITIVE_TASKS: dict[str, tuple[str, ...]] = {
    "push": ("PushCube", "PickCube", "PullCube", "StackCube"),
    "pull": ("PullCube", "PickCube", "PushCube", "StackCube"),
    "drag": ("PickCube", "StackCube", "PushCube", "PullCube"),
    "rotate": ("PickCube", "StackCube", "PushCube", "PullCube"),
    "shake": ("PickCube", "StackCube", "PushCube", "PullCube"),
    "tap": ("PickCube", "PushCube", "PullCube", "StackCube"),
    "knock-over": ("PickCube", "PushCube", "PullCube", "StackCube"),
    "drop": ("PickCube", "StackCube", "PlaceSphere", "PushCube"),
}
BACKOFF = 4  # steps (0.2 s) before first contact
OTHER_OBJECT_MAX_SHIFT = 0.01  # m: any other object moving more is an unintended collision
SOURCE_PROP_MAX_SHIFT = 0.001  # m: a prop must rest untouched through the source trajectory


class _Rig:
    """One ManiSkill task's simulators in one worker (with a prop, if any): branching script, unrendered and
    rendered `pd_joint_pos` replays, all built with the same scene extras."""

    def __init__(self, task: str, prop):
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform
        from wsp_data.platforms.maniskill.experts import task_spec
        from wsp_data.platforms.maniskill.primitives import BranchScript

        self.kit = kit("maniskill")
        self.spec = task_spec(task)
        extras = (prop,) if prop else ()
        self.objects = self.spec.objects + tuple(e.name for e in extras)
        self.script = BranchScript(task, self.objects, extras)
        self.state = ManiSkillPlatform(task, render=False, objects=self.objects, extras=extras)
        self.render = ManiSkillPlatform(task, render=True, objects=self.objects, extras=extras)
        self.qlimits = self.state.qlimits

    def close(self) -> None:
        for p in (self.script, self.state, self.render):
            p.close()

    def invalid(self, ro) -> str | None:
        return rollout_problem(self.kit, self.qlimits, ro)

    def base_xy(self) -> list[float]:
        return self.state.robot.pose.p[0, :2].cpu().numpy().astype(float).tolist()


class _LiberoRig(TaskRig):
    """One LIBERO task's simulators in one worker: the expert source (its unrendered env branches and
    validates) and a rendering env."""

    def __init__(self, task: str):
        super().__init__(task, "libero")
        self.objects = self.spec.objects

    def base_xy(self) -> list[float]:
        return self.state.base_xy().astype(float).tolist()


def first_contact(poses: np.ndarray, contacts: np.ndarray) -> int | None:
    """First frame where the robot touches the object or the object has moved `MOTION_ONSET` from its start."""
    moved = np.linalg.norm(poses[:, :3] - poses[0, :3], axis=1) >= MOTION_ONSET
    hits = np.nonzero(contacts | moved)[0]
    return int(hits[0]) if len(hits) else None


def max_shift(poses: np.ndarray) -> float:
    """Largest distance of an object from its frame-0 position, (T, 7) poses."""
    return float(np.linalg.norm(poses[:, :3] - poses[0, :3], axis=1).max())


class T5Builder(SuiteBuilder):
    suite = "t5"
    title = "T5 Interaction dynamics"
    description = ("A replay-verified expert trajectory branched 4 steps before first contact, the rest replaced by a "
                   "scripted primitive (push, pull, drag, rotate, shake, tap, knock-over, drop), balanced by "
                   "primitive. Kept only when the evaluated object's simulator states pass the primitive's rule "
                   "(`primitive`, `evaluated_object` and the measured quantities are columns). Score: primitive "
                   "judge on 12 frames.")
    roles = ("reference",)
    platforms = frozenset({"maniskill", "libero"})

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        self.primitives = PLATFORM_PRIMITIVES[config.platform]
        if config.platform == "libero":
            from wsp_data.platforms.libero.experts import task_spec
            from wsp_data.platforms.libero.primitives import compatible

            self.primitive_tasks = {p: tuple(t for t in config.tasks if compatible(p, task_spec(t)))
                                    for p in self.primitives}
            self.rig = RigCache(lambda task, prop: _LiberoRig(task))
            needs = "a task whose target is a bowl or a flat box (push, tap) among the selected ones"
        else:
            self.primitive_tasks = {p: tuple(t for t in PRIMITIVE_TASKS[p] if t in config.tasks)
                                    for p in self.primitives}
            self.rig = RigCache(_Rig)
            needs = "one of its tasks among the selected ones; tasks per primitive: " + "; ".join(
                f"{p}: {', '.join(PRIMITIVE_TASKS[p])}" for p in self.primitives)
        missing = [p for p in self.primitives if not self.primitive_tasks[p]]
        if missing:
            raise ValueError(f"T5 needs, for every primitive, {needs}; none for {', '.join(missing)}")

    def compatible(self, primitive: str) -> tuple[str, ...]:
        return self.primitive_tasks[primitive]

    def plan(self, slot: int) -> SlotPlan:
        primitive = self.primitives[slot % len(self.primitives)]
        tasks = self.compatible(primitive)
        return SlotPlan(tasks[(slot // len(self.primitives)) % len(tasks)], primitive)

    def close(self) -> None:
        self.rig.close()

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        if self.config.platform == "libero":
            return self._attempt_libero(plan, seed)
        from wsp_data.platforms.maniskill.primitives import PROPS, SCRIPTS, prop_placement

        primitive, prop = plan.group, PROPS.get(plan.group)
        rig = self.rig(plan.task, prop)
        script, spec = rig.script, rig.spec
        target, others = spec.target, tuple(o for o in spec.objects if o != spec.target)
        evaluated = prop.name if prop else target
        ev = rig.objects.index(evaluated)
        placements = None
        if prop:
            script.reset(seed)
            placements = prop_placement(script, prop, target, others)
            if placements is None:
                return Dropped("no_room_for_prop")
        # the source: the expert, scripted and verified in this very scene
        script.reset(seed, placements)
        try:
            spec.solve(script)
        except Exception:  # noqa: BLE001 - an unsolvable seed (IK or geometry failure) is just a miss
            return Dropped("source_failed")
        source = script.trajectory()
        src = rig.state.replay(seed, source, placements)
        simulated = 2 * len(source)
        if not src.success:
            return Dropped("source_failed", simulated_steps=simulated)
        src_poses = src.stack("object_poses")
        if prop and (src.stack("contacts")[:, ev].any() or max_shift(src_poses[:, ev]) > SOURCE_PROP_MAX_SHIFT):
            return Dropped("source_disturbs_prop", simulated_steps=simulated)
        contact = first_contact(src_poses[:, 0], src.stack("contacts")[:, 0])
        if contact is None:
            return Dropped("source_without_contact", simulated_steps=simulated)
        branch = max(1, contact - BACKOFF)
        # branch: the expert's script up to `branch`, then the primitive
        script.reset(seed, placements)
        script.run_until(spec.solve, branch)
        if not np.array_equal(script.trajectory(), source[:branch]):
            return Dropped("branch_mismatch", simulated_steps=simulated + branch)
        SCRIPTS[primitive](script, target, others)
        stream = script.trajectory()
        simulated += len(stream)
        return self._validate(plan, rig, seed, source, stream, placements, branch, contact, evaluated, simulated)

    def _attempt_libero(self, plan: SlotPlan, seed: int) -> Kept | Dropped:
        from wsp_data.platforms.libero.primitives import branch_stream

        rig, primitive = self.rig(plan.task, None), plan.group
        source = rig.expert.trajectory(seed)  # scripted and verified in this scene
        if source is None:
            return Dropped("source_failed")
        src = rig.state.replay(seed, source)
        simulated = 2 * len(source)
        contact = first_contact(src.stack("object_poses")[:, 0], src.stack("contacts")[:, 0])
        if contact is None:
            return Dropped("source_without_contact", simulated_steps=simulated)
        branch = max(1, contact - BACKOFF)
        stream = branch_stream(rig.state, rig.spec, seed, source, branch, primitive)
        if stream is None:
            return Dropped("primitive_out_of_time", simulated_steps=simulated)
        simulated += len(stream)
        return self._validate(plan, rig, seed, source, stream, None, branch, contact, rig.spec.target, simulated)

    def _validate(self, plan: SlotPlan, rig, seed: int, source: np.ndarray, stream: np.ndarray, placements,
                  branch: int, contact: int, evaluated: str, simulated: int) -> Kept | Dropped:
        """Replay the branched stream unrendered, check it, render it, check again, and make the instance."""
        primitive, spec = plan.group, rig.spec
        ev = rig.objects.index(evaluated)
        ro = rig.state.replay(seed, stream, placements)
        simulated += len(stream)
        if (why := self.reject(rig, ro, primitive, ev)) is not None:
            return Dropped(why, simulated_steps=simulated)
        rendered = rig.render.replay(seed, stream, placements)
        steps = len(stream)
        if (why := self.reject(rig, rendered, primitive, ev)) is not None:
            return Dropped(f"rendered_{why}", steps, simulated)
        poses = rendered.stack("object_poses")
        base_xy = rig.base_xy()
        _, measured = check(primitive, poses[:, ev], rendered.stack("contacts")[:, ev], base_xy, self.config.platform)
        parameters = {"primitive": primitive, "evaluated_object": evaluated, "branch_step": branch,
                      "placements": {k: v.astype(float).tolist() for k, v in (placements or {}).items()}}
        row = {
            "task": plan.task, "seed": seed, "instruction": spec.instruction, "objects": list(rig.objects),
            "source": "scripted_expert+scripted_primitive", "primitive": primitive, "evaluated_object": evaluated,
            "evaluated_index": ev, "branch_step": branch, "first_contact_step": contact,
            "source_length": len(source), "robot_base_xy": base_xy,
            "object_pixel_256": [float(x) for x in project(poses[0, ev, :3], rendered.intrinsic,
                                                           rendered.extrinsic, IMAGE_SIZE)],
            **measured, "interventions": {"reference": parameters},
        }
        src = rig.render.replay(seed, source, placements)  # the unperturbed source: the expert, no primitive
        return Kept(row, [RolloutArrays.from_rollout("reference", rendered),
                          RolloutArrays.from_rollout(SOURCE_ROLE, src)], steps + len(source), simulated)

    def reject(self, rig, ro, primitive: str, ev: int) -> str | None:
        """Why a rollout is not a valid reference of `primitive` on object column `ev`, or None."""
        if (why := rig.invalid(ro)) is not None:
            return why
        poses = ro.stack("object_poses")
        if any(max_shift(poses[:, i]) > OTHER_OBJECT_MAX_SHIFT for i in range(len(rig.objects)) if i != ev):
            return "disturbed_other_object"
        ok, _ = check(primitive, poses[:, ev], ro.stack("contacts")[:, ev], rig.base_xy(), self.config.platform)
        return None if ok else "primitive_not_observed"
