"""T4 on ManiSkill: which tasks serve which kind, the distractor palette, and the task rig that proposes the
three kinds' scene edits, for the platform-free builder `wsp_data/builders/t4.py` (docs/suites/t4.md), through
`wsp_data.platforms.contract`.
Placements are computed in SAPIEN's pose convention (float32)."""

from __future__ import annotations

import numpy as np

from wsp_data.platforms import kit
from wsp_data.platforms.contract import (
    CLEARANCE, DISTRACTOR_MARGIN, DONOR_TRIES, PLACEMENT_TRIES, REACH_Z, SWEPT_MARGIN, WORKSPACE, Proposal, Sight,
    box_gap, false_contact, point_gaps, rollout_problem,
)
from wsp_data.schema import MAX_OBJECTS, SEED_BASE, SEED_SPAN

# Which tasks serve which kind (docs/suites/t4.md): false contact needs an expert that grasps the target; spatial
# proximity needs a single dominant target whose removal leaves the robot nothing else to touch.
KIND_TASKS: dict[str, tuple[str, ...]] = {
    "distractor": ("PickCube", "PushCube", "PullCube", "StackCube", "PlaceSphere", "LiftPegUpright", "RollBall"),
    "false_contact": ("PickCube", "StackCube", "PlaceSphere", "LiftPegUpright"),
    "spatial_proximity": ("PickCube", "PushCube", "PullCube", "StackCube", "PlaceSphere", "LiftPegUpright",
                          "RollBall"),
}

_YELLOW, _PURPLE, _CYAN = (0.95, 0.8, 0.1, 1.0), (0.55, 0.25, 0.75, 1.0), (0.1, 0.75, 0.8, 1.0)
PALETTE_SPECS = (  # ManiSkill distractors: (shape, half size, colour)
    ("box", 0.02, _YELLOW), ("box", 0.025, _PURPLE), ("box", 0.02, _CYAN),
    ("sphere", 0.02, _PURPLE), ("sphere", 0.025, _CYAN), ("sphere", 0.02, _YELLOW),
)


def _rotation(q: np.ndarray) -> np.ndarray:
    import sapien  # ManiSkill's pose convention (float32), as its placements were always computed

    return sapien.Pose(q=np.asarray(q, np.float64)).to_transformation_matrix()[:3, :3]


def _box_xy(vertices: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """xy bounding box [[x0, y0], [x1, y1]] of local mesh vertices placed at a world pose (xyz, wxyz)."""
    world = vertices @ _rotation(pose[3:]).T + pose[:3]
    return np.stack([world[:, :2].min(0), world[:, :2].max(0)])


class TaskRig:
    """One ManiSkill task's simulators in one worker: expert source, unrendered and rendered replays (with the
    palette), and the three kinds' proposals."""

    def __init__(self, task: str):
        from wsp_data.platforms.maniskill.env import ExtraActor, ManiSkillPlatform
        from wsp_data.platforms.maniskill.experts import ExpertSource

        self.palette = tuple(ExtraActor(f"distractor_{i}", shape, (h, h, h), color)
                             for i, (shape, h, color) in enumerate(PALETTE_SPECS))
        self.kit = kit("maniskill")
        self.expert = ExpertSource(task)
        self.spec = self.expert.spec
        self.state = ManiSkillPlatform(task, render=False, objects=self.spec.objects, extras=self.palette)
        self.render = ManiSkillPlatform(task, render=True, objects=self.spec.objects, extras=self.palette)
        self.qlimits = self.state.qlimits
        self.intrinsic, self.extrinsic = self.state.camera_params()
        self._pin = self.state.robot._objs[0].create_pinocchio_model()

    def close(self) -> None:
        self.expert.close()
        self.state.close()
        self.render.close()

    def replay(self, platform, seed: int, p: Proposal):
        platform.object_names = p.objects
        return platform.replay(seed, p.actions, p.placements)

    def invalid(self, ro) -> str | None:
        return rollout_problem(self.kit, self.qlimits, ro)

    def footprint(self, qpos: np.ndarray) -> np.ndarray:
        """xy of every robot link origin below REACH_Z over a rollout (forward kinematics of its qpos): the
    robot's swept region, before the margin (the base link, at table height, is always in it)."""
        base = self.state.robot.pose.sp
        links = range(len(self.state.robot.get_links()))
        pts = []
        for q in qpos.astype(np.float64):
            self._pin.compute_forward_kinematics(q)
            pts.extend((base * self._pin.get_link_pose(i)).p for i in links)
        pts = np.asarray(pts)
        return pts[pts[:, 2] < REACH_Z, :2]

    def local_vertices(self, name: str) -> np.ndarray:
        """Collision mesh vertices of a task object in its own frame (the scene of the last reset)."""
        return np.asarray(self.state.actor(name).get_first_collision_mesh(to_world_frame=False).vertices)

    def sight(self, seed: int) -> Sight:
        """What the camera sees at frame 0 of `seed` (one rendered reset: the robot's rest silhouette)."""
        return Sight(self.intrinsic, self.extrinsic, self.render.reset(seed).mask)

    # -- proposals ------------------------------------------------------------------------------
    def distractor(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        objects = self.spec.objects
        if len(objects) >= MAX_OBJECTS:
            return "too_many_objects"
        extra = self.palette[int(rng.integers(len(self.palette)))]
        boxes = [_box_xy(self.local_vertices(n), base.observations[0].object_poses[i]) for i, n in enumerate(objects)]
        footprint = self.footprint(base.stack("qpos"))
        h = extra.half_size[0]
        r = float(np.hypot(h, h)) if extra.shape == "box" else h
        self.state.object_names = objects
        for donor in rng.integers(SEED_BASE["t4"], SEED_BASE["t4"] + SEED_SPAN, size=DONOR_TRIES):
            donor_pose = self.state.reset(int(donor)).object_poses[0].astype(np.float64)
            yaw = np.arctan2(*_rotation(donor_pose[3:])[[1, 0], 0])
            pose = np.array([*donor_pose[:2], h, np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])
            box = np.stack([pose[:2] - r, pose[:2] + r])
            if (sight(pose[:3]) and point_gaps(box, footprint).min(initial=np.inf) >= DISTRACTOR_MARGIN
                    and all(box_gap(box, b) >= CLEARANCE for b in boxes)):
                params = {"kind": "distractor", "donor_seed": int(donor), "shape": extra.shape,
                          "half_size": h, "color": list(extra.color), "pose": pose.tolist()}
                return Proposal(source, objects + (extra.name,), extra.name, {extra.name: pose}, params)
        return "no_clear_donor_placement"

    def false_contact(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        return false_contact(self, base, source, sight)

    def spatial_proximity(self, base, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        objects, target = self.spec.objects, self.spec.target
        poses = base.observations[0].object_poses.astype(np.float64)
        box = _box_xy(self.local_vertices(target), poses[0])
        others = [_box_xy(self.local_vertices(n), poses[i]) for i, n in enumerate(objects) if i > 0]
        footprint = self.footprint(base.stack("qpos"))
        lo, hi = np.array(WORKSPACE).T
        for xy in rng.uniform(lo, hi, size=(PLACEMENT_TRIES, 2)):
            moved = box + (xy - poses[0, :2])
            pose = poses[0].copy()
            pose[:2] = xy
            if (sight(pose[:3]) and point_gaps(moved, footprint).min(initial=np.inf) >= SWEPT_MARGIN
                    and all(box_gap(moved, b) >= CLEARANCE for b in others)):
                params = {"kind": "spatial_proximity", "from": poses[0].tolist(), "to": pose.tolist()}
                return Proposal(source, objects, target, {target: pose}, params)
        return "no_clear_placement"
