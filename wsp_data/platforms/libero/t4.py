"""T4 on LIBERO: the task rig that proposes the three kinds' scene edits on a BDDL scene, for the platform-free
builder `wsp_data/builders/t4.py`, through `wsp_data.platforms.contract` (docs/platforms/libero.md)."""

from __future__ import annotations

import numpy as np

from wsp_data.platforms.contract import (
    CLEARANCE, DISTRACTOR_MARGIN, PLACEMENT_TRIES, REACH_Z, SWEPT_MARGIN, Proposal, Sight, TaskRig, box_gap,
    false_contact, point_gaps,
)
from wsp_data.schema import MAX_OBJECTS

# LIBERO scenes are compiled from BDDL, so a body cannot be added without changing the model: its distractor
# is one of the scene's own movable objects that the task does not involve, relocated (docs/platforms/libero.md).
LIBERO_SUPPORT_TOL = 0.01  # m: a LIBERO distractor candidate rests on the same surface as the task's target
LIBERO_AROUND = 0.25  # m: LIBERO placements are drawn this far around the task objects' xy box


class LiberoTaskRig(TaskRig):
    """One LIBERO task's simulators in one worker, and the three kinds' proposals. The swept region, object
    boxes and placements are measured on the scene itself (every scene object, not only the task's, must stay
    clear); heights are taken relative to the surface the target rests on."""

    def __init__(self, task: str):
        super().__init__(task, "libero")
        self.intrinsic, self.extrinsic = self.state.camera_params()

    def replay(self, platform, seed: int, p: Proposal):
        platform.track(p.objects)
        try:
            return platform.replay(seed, p.actions, p.placements)
        finally:
            platform.track(self.spec.objects)

    def sight(self, seed: int) -> Sight:
        return Sight(self.intrinsic, self.extrinsic, self.render.reset(seed).mask)

    def _scene(self, seed: int) -> tuple[dict[str, np.ndarray], dict[str, float]]:
        """Reset the unrendered env to frame 0 of `seed` (the proposals read its poses) and return the xy box
        and the bottom height of every movable object."""
        self.state.reset(seed)
        boxes, bottoms = {}, {}
        for name in self.state.movable_objects():
            pts = self.state.collision_points(name)
            boxes[name] = np.stack([pts[:, :2].min(0), pts[:, :2].max(0)])
            bottoms[name] = float(pts[:, 2].min())
        return boxes, bottoms

    def _footprint(self, qpos: np.ndarray, support: float) -> np.ndarray:
        pts = self.state.link_positions(qpos)
        return pts[pts[:, 2] < support + REACH_Z, :2]

    def _place(self, name: str, boxes: dict, footprint: np.ndarray, margin: float, sight: Sight,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
        """A frame-0 pose for `name`, moved in xy only (same height and orientation): in view, `margin` clear of
        the swept region and CLEARANCE clear of every other movable object; with the pose it came from."""
        pose = self.state.object_pose(name)
        box = boxes[name]
        task = np.concatenate([boxes[n] for n in self.spec.objects if n in boxes])
        lo, hi = task.min(0) - LIBERO_AROUND, task.max(0) + LIBERO_AROUND
        others = [b for n, b in boxes.items() if n != name]
        for xy in rng.uniform(lo, hi, size=(PLACEMENT_TRIES, 2)):
            moved = box + (xy - pose[:2])
            to = pose.copy()
            to[:2] = xy
            if (sight(to[:3]) and point_gaps(moved, footprint).min(initial=np.inf) >= margin
                    and all(box_gap(moved, b) >= CLEARANCE for b in others)):
                return pose, to
        return None

    # -- proposals ------------------------------------------------------------------------------
    def distractor(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        objects = self.spec.objects
        if len(objects) >= MAX_OBJECTS:
            return "too_many_objects"
        boxes, bottoms = self._scene(base.seed)
        support = bottoms[self.spec.target]
        candidates = [n for n in bottoms if n not in objects and abs(bottoms[n] - support) <= LIBERO_SUPPORT_TOL]
        if not candidates:
            return "no_distractor_object"
        footprint = self._footprint(base.stack("qpos"), support)
        for i in rng.permutation(len(candidates)):
            name = candidates[i]
            placed = self._place(name, boxes, footprint, DISTRACTOR_MARGIN, sight, rng)
            if placed is not None:
                params = {"kind": "distractor", "object": name, "from": placed[0].tolist(), "pose": placed[1].tolist()}
                return Proposal(source, objects + (name,), name, {name: placed[1]}, params)
        return "no_clear_distractor_placement"

    def false_contact(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        return false_contact(self, base, source, sight)

    def spatial_proximity(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        boxes, bottoms = self._scene(base.seed)
        footprint = self._footprint(base.stack("qpos"), bottoms[self.spec.target])
        placed = self._place(self.spec.target, boxes, footprint, SWEPT_MARGIN, sight, rng)
        if placed is None:
            return "no_clear_placement"
        params = {"kind": "spatial_proximity", "from": placed[0].tolist(), "to": placed[1].tolist()}
        return Proposal(source, self.spec.objects, self.spec.target, {self.spec.target: placed[1]}, params)
