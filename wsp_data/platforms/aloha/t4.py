"""T4 on ALOHA: the task rig that proposes the three kinds' scene edits (docs/platforms/aloha.md).

- distractor: the scene's spare yellow cube (parked out of sight) placed on the table, in view, clear of both
  arms' swept region; the expert's stream must still succeed around it.
- false contact: the expert's stream with both grippers clamped open (`wsp_data.platforms.contract.false_contact`).
- spatial proximity: the task's target moved, in xy only, out of both arms' swept region.

The swept region is the xy of every robot body origin that comes lower than `REACH_Z` above the table in the
original rollout (both arms; the grip points included), as on the other platforms.
"""

from __future__ import annotations

import itertools

import numpy as np

from wsp_data.platforms.contract import (
    CLEARANCE, DISTRACTOR_MARGIN, KINDS, PLACEMENT_TRIES, REACH_Z, SWEPT_MARGIN, Proposal, Sight, TaskRig, box_gap,
    false_contact, point_gaps,
)
from wsp_data.schema import MAX_OBJECTS
from wsp_eval.object_track import rotation_matrices

TABLE = ((-0.25, 0.25), (0.32, 0.68))  # m: x and y ranges a placed object may take (on the table, in view, in reach)
_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))


EXCLUDED = {  # (kind, task) pairs never drawn, with the measured reason (8 attempts each)
    ("false_contact", "peg_insertion"): "the open fingers pass over the 2 cm peg and hide it: the reference's own "
                                        "tracking drifts (7 of 8 attempts)",
    ("false_contact", "push_cube"): "the expert pushes with open fingers: there is no grasp to clamp open (8 of 8)",
    ("spatial_proximity", "peg_insertion"): "the other hand still grasps the socket, a contact with a task object "
                                            "(8 of 8 attempts)",
}


def kind_tasks(tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """The selected tasks serving each kind: all of them but the `EXCLUDED` pairs."""
    return {k: tuple(t for t in tasks if (k, t) not in EXCLUDED) for k in KINDS}


def needs(missing) -> str:
    """What a task must be to serve the `missing` kinds (the end of T4's refusal)."""
    out = []
    for k in missing:
        but = [f"{t} ({why})" for (kind, t), why in EXCLUDED.items() if kind == k]
        out.append(f"{k}: any ALOHA task" + (f" but {', '.join(but)}" if but else ""))
    return "; ".join(out)


class AlohaTaskRig(TaskRig):
    """One ALOHA task's simulators in one worker, and the three kinds' proposals."""

    def __init__(self, task: str):
        super().__init__(task, "aloha")
        self.intrinsic, self.extrinsic = self.state.camera_params()
        m = self.state.model
        self._robot_bodies = [b for b in range(m.nbody) if m.body(b).name.startswith("vx300s_")]

    def replay(self, platform, seed: int, p: Proposal):
        platform.track(p.objects)
        try:
            return platform.replay(seed, p.actions, p.placements)
        finally:
            platform.track(self.spec.objects)

    def sight(self, seed: int) -> Sight:
        return Sight(self.intrinsic, self.extrinsic, self.render.reset(seed).mask)

    # -- geometry -------------------------------------------------------------------------------
    def _box(self, name: str, pose: np.ndarray) -> np.ndarray:
        """The xy box (2, 2: min, max; m) of object `name` at world `pose` (its box parts' corners)."""
        from wsp_data.platforms.aloha.env import OBJECTS

        R = rotation_matrices(pose[None, 3:])[0]
        local = np.concatenate([np.asarray(p.pos) + _CORNERS * p.half for p in OBJECTS[name].parts])
        xy = (pose[:3] + local @ R.T)[:, :2]
        return np.stack([xy.min(0), xy.max(0)])

    def _footprint(self, qpos: np.ndarray) -> np.ndarray:
        """xy of the robot body origins below REACH_Z over the rollout's states (T+1, 14)."""
        pts = self.state.body_positions(qpos, self._robot_bodies)
        return pts[pts[:, 2] < REACH_Z, :2]

    def _place(self, name: str, start: np.ndarray, others: list[np.ndarray], footprint: np.ndarray, margin: float,
               sight: Sight, rng: np.random.Generator) -> np.ndarray | None:
        """A frame-0 pose for `name` (from `start`, at its resting height and orientation, moved in xy): in
        view, `margin` clear of the swept region and CLEARANCE clear of the `others` boxes."""
        from wsp_data.platforms.aloha.env import OBJECTS

        lo, hi = np.array([TABLE[0][0], TABLE[1][0]]), np.array([TABLE[0][1], TABLE[1][1]])
        for xy in rng.uniform(lo, hi, size=(PLACEMENT_TRIES, 2)):
            to = start.copy()
            to[:2], to[2] = xy, OBJECTS[name].rest_z
            box = self._box(name, to)
            if (sight(to[:3]) and point_gaps(box, footprint).min(initial=np.inf) >= margin
                    and all(box_gap(box, b) >= CLEARANCE for b in others)):
                return to
        return None

    def _frame0(self, base) -> dict[str, np.ndarray]:
        o = base.observations[0].object_poses
        return {n: o[i].astype(np.float64) for i, n in enumerate(self.spec.objects)}

    # -- proposals ------------------------------------------------------------------------------
    def distractor(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        from wsp_data.platforms.aloha.env import DISTRACTOR

        objects = self.spec.objects
        if len(objects) >= MAX_OBJECTS:
            return "too_many_objects"
        poses = self._frame0(base)
        others = [self._box(n, p) for n, p in poses.items()]
        start = np.array([0, 0, 0, 1, 0, 0, 0], np.float64)
        to = self._place(DISTRACTOR, start, others, self._footprint(base.stack("qpos")), DISTRACTOR_MARGIN, sight, rng)
        if to is None:
            return "no_clear_distractor_placement"
        params = {"kind": "distractor", "object": DISTRACTOR, "pose": to.tolist()}
        return Proposal(source, objects + (DISTRACTOR,), DISTRACTOR, {DISTRACTOR: to}, params)

    def false_contact(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        return false_contact(self, base, source, sight)

    def spatial_proximity(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        target = self.spec.target
        poses = self._frame0(base)
        others = [self._box(n, p) for n, p in poses.items() if n != target]
        to = self._place(target, poses[target], others, self._footprint(base.stack("qpos")), SWEPT_MARGIN, sight, rng)
        if to is None:
            return "no_clear_placement"
        params = {"kind": "spatial_proximity", "from": poses[target].tolist(), "to": to.tolist()}
        return Proposal(source, self.spec.objects, target, {target: to}, params)
