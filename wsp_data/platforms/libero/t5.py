"""T5 on LIBERO: the task rig whose branch replays the expert's OSC stream up to the branch step and lets
`primitives` continue closed-loop, for the platform-free builder `wsp_data/builders/t5.py`
(docs/platforms/libero.md)."""

from __future__ import annotations

from wsp_data.platforms.contract import BACKOFF, Branch, Dropped, TaskRig, first_contact
from wsp_data.platforms.libero.primitives import branch_stream


class LiberoRig(TaskRig):
    """One LIBERO task's simulators in one worker: the expert source (its unrendered env branches and
    validates) and a rendering env."""

    def __init__(self, task: str):
        super().__init__(task, "libero")
        self.objects = self.spec.objects

    def base_xy(self) -> list[float]:
        return self.state.base_xy().astype(float).tolist()

    def branch(self, primitive: str, seed: int) -> Branch | Dropped:
        """The verified expert stream, and the same stream up to `BACKOFF` steps before first contact continued
        closed-loop by `primitive`."""
        rig = self
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
        if isinstance(stream, str):
            return Dropped(stream, simulated_steps=simulated)
        simulated += len(stream)
        return Branch(source, stream, None, branch, contact, rig.spec.target, simulated)
