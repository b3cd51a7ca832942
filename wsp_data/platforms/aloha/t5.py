"""T5 on ALOHA: which tasks serve which primitive, and the task rig whose branch replays the expert's stream up
to the branch step and lets `primitives` continue closed-loop with the acting arm (docs/platforms/aloha.md). Knock-over
acts on a prop (`primitives.PROP`) that the rig's scene adds beside the target."""

from __future__ import annotations

from wsp_data.platforms import kit
from wsp_data.platforms.contract import (
    BACKOFF, PRIMITIVES, SOURCE_PROP_MAX_SHIFT, Branch, Dropped, first_contact, max_shift, rollout_problem,
)

# (primitive, task) pairs T5 never draws, with the measured reason (unrendered sweep, 20 seeds per pair); every
# other pair kept all 20 proposals but knock-over on two_arm_lift (16: no room for the prop)
EXCLUDED = {
    ("pull", "peg_insertion"): "the 12 cm peg lies along the pull, too long for the open fingers (7 cm apart) to "
                               "straddle: ≤ 0.044 m toward the base (0 of 20)",
    ("pull", "two_arm_lift"): "the 30 cm bar, likewise (0 of 20; 11 of them sank through the table)",
    ("shake", "peg_insertion"): "the 2 cm peg slips in the fingers and stays put (9 of 20)",
    ("shake", "two_arm_lift"): "the bar, held at its middle by one hand, swings and turns over: ≤ 2 reversals "
                               "(0 of 20)",
    ("drop", "peg_insertion"): "the 2 cm peg dropped from 10 cm sinks 8 mm into the table on landing, and fell "
                               "through it once in 20",
}


def primitive_tasks(tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """The selected tasks serving each primitive, in their order: all of them but the `EXCLUDED` pairs (the
    six cube tasks serve all eight primitives; the peg and the bar five and six)."""
    return {p: tuple(t for t in tasks if (p, t) not in EXCLUDED) for p in PRIMITIVES}


def needs() -> str:
    """What a task must be to serve each primitive (the end of T5's refusal)."""
    return "any ALOHA task but, per primitive: " + "; ".join(f"{p}: {t} ({why})" for (p, t), why in EXCLUDED.items())


class AlohaT5Rig:
    """One ALOHA task's simulators in one worker (with knock-over's prop, if asked): an unrendered platform that
    scripts the expert and the branch and validates, and a rendering one, both with the same scene."""

    def __init__(self, task: str, prop: str | None):
        from wsp_data.platforms.aloha.env import AlohaPlatform, aloha_task
        from wsp_data.platforms.aloha.primitives import ACTING_ARM, base_xy

        self.kit, self.spec, self.prop = kit("aloha"), aloha_task(task), prop
        extras = (prop,) if prop else ()
        self.objects = self.spec.objects + extras
        self.state = AlohaPlatform(task, render=False, objects=self.objects, extras=extras)
        self.render = AlohaPlatform(task, render=True, objects=self.objects, extras=extras)
        self.qlimits = self.state.qlimits
        self.arm = ACTING_ARM[task]
        self._base = base_xy(self.state, self.arm).astype(float).tolist()

    def close(self) -> None:
        self.state.close()
        self.render.close()

    def invalid(self, ro) -> str | None:
        return rollout_problem(self.kit, self.qlimits, ro)

    def base_xy(self) -> list[float]:
        """The acting arm's base (world xy, m): what pull moves the target toward."""
        return list(self._base)

    def _source(self, seed: int, placements: dict | None):
        """The expert scripted in this very scene, and its replay; (None, replay or None) when it fails."""
        from wsp_data.platforms.aloha.experts import script_stream

        source = script_stream(self.state, self.spec.name, seed, placements)
        if source is None:
            return None, None
        src = self.state.replay(seed, source, placements)
        return (source if src.success else None), src

    def branch(self, primitive: str, seed: int) -> Branch | Dropped:
        """The expert scripted and verified in this scene (with the prop: at the first of its places where the
        expert succeeds and never touches it), then replayed up to `BACKOFF` steps before first contact and
        continued by `primitive`."""
        from wsp_data.platforms.aloha.primitives import branch_stream, prop_placements

        evaluated = self.prop or self.spec.target
        ev, simulated, why = self.objects.index(evaluated), 0, "no_room_for_prop"
        for placements in (prop_placements(self.state, self.spec.name, seed) if self.prop else [None]):
            source, src = self._source(seed, placements)
            simulated += 2 * len(src.actions) if src is not None else 0
            if source is None:
                why = "source_failed"
                continue
            if self.prop and (src.stack("contacts")[:, ev].any()
                              or max_shift(src.stack("object_poses")[:, ev]) > SOURCE_PROP_MAX_SHIFT):
                why = "source_disturbs_prop"
                continue
            break
        else:
            return Dropped(why, simulated_steps=simulated)
        contact = first_contact(src.stack("object_poses")[:, 0], src.stack("contacts")[:, 0])
        if contact is None:
            return Dropped("source_without_contact", simulated_steps=simulated)
        branch = max(1, contact - BACKOFF)
        stream = branch_stream(self.state, self.spec.name, seed, source, branch, primitive, placements)
        if stream is None:
            return Dropped("primitive_out_of_time", simulated_steps=simulated)
        simulated += len(stream)
        return Branch(source, stream, placements, branch, contact, evaluated, simulated)
