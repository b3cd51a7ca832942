"""T4 Interaction grounding (SPEC §3 T4): validated no-contact rollouts of three kinds, balanced by slot.

- distractor: one primitive from `PALETTE` (built by the scene loader, so segmentation ids of the task stay
  the same) is put where the task's target lay in a same-task donor episode (another seed); the original
  expert actions are replayed. Kept if it is in view, clear of the task objects and of the robot's swept
  region, never contacted nor displaced, and the task still succeeds. Evaluated object: the distractor.
- false_contact: the expert's arm trajectory with the gripper command clamped open (+1) throughout. Kept if
  both fingers stay open and nothing is ever touched (so the target stays put). Evaluated object: the target.
- spatial_proximity: the target is moved, at rest, outside the swept region of the original rollout; the
  same actions are replayed. Kept if it is in view, clear of the other objects, never touched nor displaced.
  Evaluated object: the target.
Every proposal is validated unrendered first (common validity + the kind's rule over the whole rollout);
only then is it rendered, checked again, and tracked with `wsp_eval.tracking`: the reference gate must reach
`GATE_MIN_REFERENCE`, the object must be trackable, and the reference must score 100.
Thresholds and task choices are documented in docs/t4.md. On LIBERO (`_LiberoTaskRig`) a BDDL scene cannot
gain a body, so the distractor is one of the scene's own movable objects the task does not use, relocated to a
free place in view; placements are measured against every movable object of the scene (docs/libero.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wsp_data.builders.base import BuildConfig, Dropped, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache, TaskRig, rollout_problem
from wsp_data.platforms import kit
from wsp_data.schema import IMAGE_SIZE, MAX_OBJECTS, SEED_BASE, SEED_SPAN, SOURCE_ROLE
from wsp_data.staging import RolloutArrays
from wsp_eval.tracking import (
    GATE_MIN_REFERENCE, LK_WINDOW, MOTION_MAX, QUERY_RADIUS, SCORING_SIZE, motion_gate, object_motion, project,
    scoring_frames, scoring_mask, t4_score,
)

KINDS = ("distractor", "false_contact", "spatial_proximity")
# Which tasks serve which kind (docs/t4.md): false contact needs an expert that grasps the target; spatial
# proximity needs a single dominant target whose removal leaves the robot nothing else to touch.
KIND_TASKS: dict[str, tuple[str, ...]] = {
    "distractor": ("PickCube", "PushCube", "PullCube", "StackCube", "PlaceSphere", "LiftPegUpright", "RollBall"),
    "false_contact": ("PickCube", "StackCube", "PlaceSphere", "LiftPegUpright"),
    "spatial_proximity": ("PickCube", "PushCube", "PullCube", "StackCube", "PlaceSphere", "LiftPegUpright",
                          "RollBall"),
}

POS_TOL = 0.005  # m: an object that never strays this far from its frame-0 position "stays put"
ROT_TOL = 0.05  # rad: … and never turns this far
FINGER_OPEN = 0.035  # m: each Panda finger joint opens to 0.04; below this the gripper closed on something
SWEPT_MARGIN = 0.10  # m: a moved target's footprint keeps this far from every low robot link origin
DISTRACTOR_MARGIN = 0.05  # m: the same for a distractor (a prefilter only: the contact check decides)
REACH_Z = 0.12  # m: link origins above this height cannot touch a tabletop object (≤ 5 cm tall)
CLEARANCE = 0.02  # m: gap between a placed object and any other task object (xy bounding boxes)
WORKSPACE = ((-0.35, 0.25), (-0.35, 0.35))  # m: x and y ranges a target may be moved to (on the table, in view)
VIEW_MARGIN = QUERY_RADIUS + LK_WINDOW // 2 + 1  # px: the query grid and its windows stay inside the frame
ROBOT_CLEARANCE = QUERY_RADIUS + 1  # px: no query point on the robot's silhouette at frame 0
DONOR_TRIES = 12  # donor episodes tried for a distractor placement
PLACEMENT_TRIES = 256  # random target placements tried for spatial proximity
MIN_TEXTURED = 5  # of the 9 query points must carry texture at frame 0
MIN_VISIBLE = 0.5  # fraction of reference frames in which the evaluated object must be tracked
REFERENCE_D_MAX = MOTION_MAX / 2  # px: the reference's own d must leave a faithful generation this much headroom

_YELLOW, _PURPLE, _CYAN = (0.95, 0.8, 0.1, 1.0), (0.55, 0.25, 0.75, 1.0), (0.1, 0.75, 0.8, 1.0)
PALETTE_SPECS = (  # ManiSkill distractors: (shape, half size, colour)
    ("box", 0.02, _YELLOW), ("box", 0.025, _PURPLE), ("box", 0.02, _CYAN),
    ("sphere", 0.02, _PURPLE), ("sphere", 0.025, _CYAN), ("sphere", 0.02, _YELLOW),
)
# LIBERO scenes are compiled from BDDL, so a body cannot be added without changing the model: its distractor
# is one of the scene's own movable objects that the task does not involve, relocated (docs/libero.md).
LIBERO_SUPPORT_TOL = 0.01  # m: a LIBERO distractor candidate rests on the same surface as the task's target
LIBERO_AROUND = 0.25  # m: LIBERO placements are drawn this far around the task objects' xy box


@dataclass
class Proposal:
    """What to replay: actions, placements after reset, the recorded objects and the evaluated one."""

    actions: np.ndarray
    objects: tuple[str, ...]
    evaluated: str
    placements: dict[str, np.ndarray]
    params: dict

    @property
    def index(self) -> int:
        return self.objects.index(self.evaluated)


def _rotation(q: np.ndarray) -> np.ndarray:
    import sapien  # ManiSkill's pose convention (float32), as its placements were always computed

    return sapien.Pose(q=np.asarray(q, np.float64)).to_transformation_matrix()[:3, :3]


def _box_xy(vertices: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """xy bounding box [[x0, y0], [x1, y1]] of local mesh vertices placed at a world pose (xyz, wxyz)."""
    world = vertices @ _rotation(pose[3:]).T + pose[:3]
    return np.stack([world[:, :2].min(0), world[:, :2].max(0)])


def _gap(box: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each xy point (N, 2) to an xy box."""
    d = np.maximum(box[0] - points, 0) + np.maximum(points - box[1], 0)
    return np.linalg.norm(d, axis=-1)


def _box_gap(a: np.ndarray, b: np.ndarray) -> float:
    d = np.maximum(np.maximum(a[0] - b[1], b[0] - a[1]), 0)
    return float(np.linalg.norm(d))


def static(poses: np.ndarray) -> bool:
    """(T, 7) poses never leave frame 0's by POS_TOL (m) or ROT_TOL (rad)."""
    dp = np.linalg.norm(poses[:, :3] - poses[0, :3], axis=1)
    dq = 2 * np.arccos(np.clip(np.abs(poses[:, 3:] @ poses[0, 3:]), 0, 1))
    return bool(dp.max() < POS_TOL and dq.max() < ROT_TOL)


def fingers_closed(qpos: np.ndarray) -> bool:
    """Some frame has a finger joint nearer than FINGER_OPEN to closed (ManiSkill's fingers open to +0.04,
    LIBERO's to +0.04 and −0.04)."""
    return bool((np.abs(qpos[:, 7:9]) < FINGER_OPEN).any())


def false_contact(rig, base, source: np.ndarray, sight: _Sight) -> Proposal | str:
    """The expert's stream with the gripper command clamped fully open throughout (the platform's own
    gripper dimension and open value)."""
    dim, opened = rig.kit.gripper_dim, rig.kit.gripper_open
    if not (source[:, dim] != opened).any():
        return "source_never_closes"
    if not sight(base.observations[0].object_poses[0, :3]):
        return "object_out_of_sight"
    actions = source.copy()
    actions[:, dim] = opened
    return Proposal(actions, rig.spec.objects, rig.spec.target, {}, {"kind": "false_contact", "gripper": opened})


class _TaskRig:
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

    def sight(self, seed: int) -> _Sight:
        """What the camera sees at frame 0 of `seed` (one rendered reset: the robot's rest silhouette)."""
        return _Sight(self.intrinsic, self.extrinsic, self.render.reset(seed).mask)

    # -- proposals ------------------------------------------------------------------------------
    def distractor(self, base, source: np.ndarray, sight: _Sight, rng: np.random.Generator) -> Proposal | str:
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
            if (sight(pose[:3]) and _gap(box, footprint).min(initial=np.inf) >= DISTRACTOR_MARGIN
                    and all(_box_gap(box, b) >= CLEARANCE for b in boxes)):
                params = {"kind": "distractor", "donor_seed": int(donor), "shape": extra.shape,
                          "half_size": h, "color": list(extra.color), "pose": pose.tolist()}
                return Proposal(source, objects + (extra.name,), extra.name, {extra.name: pose}, params)
        return "no_clear_donor_placement"

    def false_contact(self, base, source: np.ndarray, sight: _Sight, rng: np.random.Generator) -> Proposal | str:
        return false_contact(self, base, source, sight)

    def spatial_proximity(self, base, source: np.ndarray, sight: _Sight, rng: np.random.Generator) -> Proposal | str:
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
            if (sight(pose[:3]) and _gap(moved, footprint).min(initial=np.inf) >= SWEPT_MARGIN
                    and all(_box_gap(moved, b) >= CLEARANCE for b in others)):
                params = {"kind": "spatial_proximity", "from": poses[0].tolist(), "to": pose.tolist()}
                return Proposal(source, objects, target, {target: pose}, params)
        return "no_clear_placement"


class _LiberoTaskRig(TaskRig):
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

    def sight(self, seed: int) -> _Sight:
        return _Sight(self.intrinsic, self.extrinsic, self.render.reset(seed).mask)

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

    def _place(self, name: str, boxes: dict, footprint: np.ndarray, margin: float, sight: _Sight,
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
            if (sight(to[:3]) and _gap(moved, footprint).min(initial=np.inf) >= margin
                    and all(_box_gap(moved, b) >= CLEARANCE for b in others)):
                return pose, to
        return None

    # -- proposals ------------------------------------------------------------------------------
    def distractor(self, base, source: np.ndarray, sight: _Sight, rng: np.random.Generator) -> Proposal | str:
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

    def false_contact(self, base, source: np.ndarray, sight: _Sight, rng: np.random.Generator) -> Proposal | str:
        return false_contact(self, base, source, sight)

    def spatial_proximity(self, base, source: np.ndarray, sight: _Sight, rng: np.random.Generator) -> Proposal | str:
        boxes, bottoms = self._scene(base.seed)
        footprint = self._footprint(base.stack("qpos"), bottoms[self.spec.target])
        placed = self._place(self.spec.target, boxes, footprint, SWEPT_MARGIN, sight, rng)
        if placed is None:
            return "no_clear_placement"
        params = {"kind": "spatial_proximity", "from": placed[0].tolist(), "to": placed[1].tolist()}
        return Proposal(source, self.spec.objects, self.spec.target, {self.spec.target: placed[1]}, params)


class _Sight:
    """Frame-0 visibility of a world point: `VIEW_MARGIN` px inside the frame and `ROBOT_CLEARANCE` px clear
    of the robot's silhouette (the frame every model shares)."""

    def __init__(self, intrinsic: np.ndarray, extrinsic: np.ndarray, robot_mask: np.ndarray):
        self.intrinsic, self.extrinsic = intrinsic, extrinsic
        free = (scoring_mask(robot_mask) == 0).astype(np.uint8)
        self.clearance = cv2.distanceTransform(free, cv2.DIST_L2, 5)  # px to the nearest robot pixel

    def __call__(self, xyz: np.ndarray) -> bool:
        try:
            x, y = project(xyz, self.intrinsic, self.extrinsic, IMAGE_SIZE)
        except ValueError:
            return False
        inside = VIEW_MARGIN <= min(x, y) and max(x, y) <= SCORING_SIZE - 1 - VIEW_MARGIN
        return bool(inside and self.clearance[int(round(y)), int(round(x))] >= ROBOT_CLEARANCE)


class T4Builder(SuiteBuilder):
    suite = "t4"
    title = "T4 Interaction grounding"
    description = ("Validated no-contact rollouts, balanced over three kinds (`kind`): a distractor inserted where "
                   "the target lay in a same-task donor episode (LIBERO: a scene object the task does not use, "
                   "relocated; task still succeeds), false contact (expert arm "
                   "path, gripper clamped open), spatial proximity (target moved outside the robot's swept region). "
                   "The evaluated object never moves: `evaluated_object` (index `evaluated_object_index` in "
                   "`objects`), its frame-0 pixel `object_pixel_256` in the 256x256 scoring frame, and the "
                   "reference motion gate `gate_reference` (px). Score: tracked object displacement <= 10 px "
                   "behind a distal-arm motion gate.")
    roles = ("reference",)
    platforms = frozenset({"maniskill", "libero"})

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        if config.platform == "libero":
            # every LIBERO task grasps its target and has scene objects to spare; but open fingers brush a tall
            # target that nearly fills them (measured: the alphabet soup can, 8 of 8 false-contact proposals
            # touched it), so false contact takes the tasks with a low target, as T5's push and tap do
            from wsp_data.platforms.libero.experts import task_spec
            from wsp_data.platforms.libero.primitives import low_target

            tasks = tuple(dict.fromkeys(config.tasks))
            low = tuple(t for t in tasks if low_target(task_spec(t)))
            self.kind_tasks = {"distractor": tasks, "false_contact": low, "spatial_proximity": tasks}
        else:
            self.kind_tasks = {k: tuple(t for t in config.tasks if t in KIND_TASKS[k]) for k in KINDS}
        missing = [k for k, ts in self.kind_tasks.items() if not ts]
        if missing:
            allowed = ("a task whose target is a bowl or a flat box" if config.platform == "libero" else
                       "; ".join(f"{k}: {', '.join(KIND_TASKS[k])}" for k in missing))
            raise ValueError(f"t4: no selected task serves kind(s) {', '.join(missing)}; needs {allowed}")
        self.rig = RigCache(_LiberoTaskRig if config.platform == "libero" else _TaskRig)

    def plan(self, slot: int) -> SlotPlan:
        kind = KINDS[slot % len(KINDS)]
        tasks = self.kind_tasks[kind]
        return SlotPlan(tasks[(slot // len(KINDS)) % len(tasks)], kind)

    def close(self) -> None:
        self.rig.close()

    # -- validation -----------------------------------------------------------------------------
    def violation(self, rig, kind: str, p: Proposal, ro) -> str | None:
        """The first failed check of a rollout: common validity (SPEC §5), then the kind's rule."""
        poses, contacts = ro.stack("object_poses"), ro.stack("contacts")
        if (why := rig.invalid(ro)):
            return why
        k = p.index
        if contacts[:, k].any():
            return "evaluated_object_contacted"
        if not static(poses[:, k].astype(np.float64)):
            return "evaluated_object_moved"
        if kind == "distractor":
            return None if ro.success else "task_failed"
        if contacts.any():
            return "other_object_contacted"
        if kind == "false_contact" and fingers_closed(ro.stack("qpos")):
            return "gripper_closed"
        return None

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        rig, kind = self.rig(plan.task), plan.group
        source = rig.expert.trajectory(seed)
        if source is None:
            return Dropped("source_failed")
        original = Proposal(source, rig.spec.objects, rig.spec.target, {}, {})
        base = rig.replay(rig.state, seed, original)  # the original rollout: swept region and object geometry
        simulated = len(source)
        proposal = getattr(rig, kind)(base, source, rig.sight(seed), rng)
        if isinstance(proposal, str):
            return Dropped(proposal, simulated_steps=simulated)
        ro = rig.replay(rig.state, seed, proposal)
        simulated += len(source)
        if (why := self.violation(rig, kind, proposal, ro)) is not None:
            return Dropped(why, simulated_steps=simulated)
        ref = rig.replay(rig.render, seed, proposal)  # only validated proposals are rendered
        rendered = len(source)
        if (why := self.violation(rig, kind, proposal, ref)) is not None:
            return Dropped(why, rendered, simulated)
        k = proposal.index
        pixel = project(ref.observations[0].object_poses[k, :3], ref.intrinsic, ref.extrinsic, IMAGE_SIZE)
        rgb, mask0 = ref.stack("rgb"), ref.observations[0].mask
        grey = scoring_frames(rgb)
        gate = motion_gate(grey, mask0)
        if gate < GATE_MIN_REFERENCE:
            return Dropped("gate_too_small", rendered, simulated, {"gate": gate})
        motion = object_motion(grey, pixel)
        if motion.textured_points < MIN_TEXTURED or motion.visible_fraction < MIN_VISIBLE:
            return Dropped("object_untrackable", rendered, simulated,
                           {"textured": motion.textured_points, "visible": motion.visible_fraction})
        score = t4_score(rgb, pixel, mask0, gate)
        if score.score != 100.0:
            return Dropped("reference_fails_tracker", rendered, simulated, {"d": score.displacement})
        if score.displacement > REFERENCE_D_MAX:
            return Dropped("reference_tracking_drifts", rendered, simulated, {"d": score.displacement})
        row = {
            "task": plan.task, "seed": seed, "instruction": rig.spec.instruction, "objects": list(proposal.objects),
            "source": "scripted_expert", "kind": kind, "evaluated_object": proposal.evaluated,
            "evaluated_object_index": k, "object_pixel_256": [float(x) for x in pixel], "gate_reference": gate,
            "displacement_reference": score.displacement, "object_visible_fraction": motion.visible_fraction,
            "interventions": {"reference": proposal.params},
        }
        src = rig.replay(rig.render, seed, original)  # the unperturbed source rollout
        return Kept(row, [RolloutArrays.from_rollout("reference", ref), RolloutArrays.from_rollout(SOURCE_ROLE, src)],
                    rendered + len(source), simulated)
