"""T5 on ManiSkill: which tasks serve which primitive, and the task rig that scripts the branch, for the
platform-free builder `wsp_data/builders/t5.py` (docs/suites/t5.md). Knock-over and tap act on a prop (`primitives.PROPS`) the rig's scene
adds beside the target."""

from __future__ import annotations

import numpy as np

from wsp_data.platforms import kit
from wsp_data.platforms.contract import (
    BACKOFF, SOURCE_PROP_MAX_SHIFT, Branch, Dropped, first_contact, max_shift, rollout_problem,
)

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


class Rig:
    """One ManiSkill task's simulators in one worker (with a prop, if any): branching script, unrendered and
    rendered `pd_joint_pos` replays, all built with the same scene extras."""

    def __init__(self, task: str, prop):
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform
        from wsp_data.platforms.maniskill.experts import task_spec
        from wsp_data.platforms.maniskill.primitives import BranchScript

        self.prop = prop
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

    def branch(self, primitive: str, seed: int) -> Branch | Dropped:
        """The expert scripted and verified in this very scene (with the prop), then re-run up to `BACKOFF`
        steps before first contact and continued by `primitive`'s script."""
        from wsp_data.platforms.maniskill.primitives import SCRIPTS, prop_placement

        rig, prop = self, self.prop
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
        return Branch(source, stream, placements, branch, contact, evaluated, simulated)
