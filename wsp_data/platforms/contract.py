"""The contract between suite builders (`wsp_data.builders`) and platforms: every type, constant and helper that
passes between a builder and a platform's kit, rigs and scripts. Builders and platforms both import this module;
it imports no builder and no simulator.

- What the hooks hand out (`PlatformKit`, interface.py): a task spec (`TaskSpec`), replayers (`Replayer`), an
  expert source (`ExpertSource`), T4's rig (`T4Rig`) and T5's rig (`T5Rig`).
- What an attempt hands back: `Dropped` (a rejected proposal and why), T4's `Proposal`, T5's `Branch`.
- The rig every suite starts from: `TaskRig` (one task's expert, unrendered and rendered replayers) and the
  common validity check of a platform rollout, `rollout_problem` (spec §5, `wsp_data.platforms.validity`).
- T4 (docs/suites/t4.md): the kinds (`KINDS`), frame-0 visibility (`Sight`), the margins a platform's scene edits
  keep, the xy geometry they are measured with (`point_gaps`, `box_gap`) and the false-contact proposal, the same
  on every platform (`false_contact`).
- T5 (docs/suites/t5.md): the primitives (`PRIMITIVES`), the branch point (`BACKOFF` steps before
  `first_contact`, which counts motion from `MOTION_ONSET`), the untouched-prop check (`max_shift`,
  `SOURCE_PROP_MAX_SHIFT`); quaternion rotations are `wsp_eval.object_track.rotation_matrices`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import cv2
import numpy as np

from wsp_data.platforms import kit
from wsp_data.platforms.interface import Observation, PlatformKit, Rollout
from wsp_data.platforms.validity import check_rollout
from wsp_eval.tracking import LK_WINDOW, QUERY_RADIUS, SCORING_SIZE, frame_size, project, scoring_mask


# -- what the hooks hand out ----------------------------------------------------------------------------------
class TaskSpec(Protocol):
    """One task of a platform (`PlatformKit.tasks`)."""

    name: str
    instruction: str
    objects: tuple[str, ...]  # the recorded objects, target first: pose, contact and mask columns follow this order
    target: str


class Replayer(Protocol):
    """A platform replaying one task, unrendered or rendered (`PlatformKit.make_renderer`, an expert source's
    `replayer`, a rig's `state` / `render`)."""

    qlimits: np.ndarray  # (S, 2) lower and upper limits of the state's columns (rad / m)

    def replay(self, seed: int, actions: np.ndarray, placements: dict[str, np.ndarray] | None = None) -> Rollout:
        """Reset to scene `seed`, move objects to `placements` ({name: world pose, m and wxyz}), step every
        action and record the T + 1 observations."""

    def reset(self, seed: int) -> Observation:
        """Reset to scene `seed`; frame 0."""

    def camera_params(self) -> tuple[np.ndarray, np.ndarray]:
        """The camera's OpenCV intrinsic (3, 3) and world→camera extrinsic (3, 4, m)."""

    def close(self) -> None:
        """Release the simulator."""


class ExpertSource(Protocol):
    """A task's verified scripted expert (`PlatformKit.make_expert`)."""

    spec: TaskSpec
    replayer: Replayer  # unrendered

    def trajectory(self, seed: int) -> np.ndarray | None:
        """A native stream (T, D) float32 verified by replay to end in task success; None when the seed has none."""

    def close(self) -> None:
        """Release the simulators."""


class T4Rig(Protocol):
    """One task's T4 simulators and scene edits (`PlatformKit.t4_rig`). The three kinds' proposals draw only from
    `rng` and return a `Proposal`, or the drop reason; placements are world poses (m, wxyz)."""

    kit: PlatformKit
    spec: TaskSpec
    expert: ExpertSource
    state: Replayer  # unrendered
    render: Replayer

    def invalid(self, rollout: Rollout) -> str | None:
        """The common validity check (`rollout_problem`): the first failed check's name, or None."""

    def sight(self, seed: int) -> Sight:
        """Frame-0 visibility in scene `seed` (from the rendered frame-0 robot mask)."""

    def replay(self, platform: Replayer, seed: int, proposal: Proposal) -> Rollout:
        """`proposal` replayed on `platform` (`state` or `render`), recording `proposal.objects`."""

    def distractor(self, base: Rollout, source: np.ndarray, sight: Sight, rng: np.random.Generator) -> Proposal | str:
        """A distractor placed where the task's target lay in a same-task donor episode (`base`: the original
        rollout of the expert's `source` stream)."""

    def false_contact(self, base: Rollout, source: np.ndarray, sight: Sight,
                      rng: np.random.Generator) -> Proposal | str:
        """The expert's stream with every gripper clamped open (`false_contact`)."""

    def spatial_proximity(self, base: Rollout, source: np.ndarray, sight: Sight,
                          rng: np.random.Generator) -> Proposal | str:
        """The target moved, at rest, out of the robot's swept region in `base`."""

    def close(self) -> None:
        """Release the simulators."""


class T5Rig(Protocol):
    """One task's T5 simulators, with the scene addition it was made for (`PlatformKit.t5_rig`)."""

    spec: TaskSpec
    objects: tuple[str, ...]  # the recorded objects: the task's, then the scene addition's
    state: Replayer  # unrendered
    render: Replayer

    def invalid(self, rollout: Rollout) -> str | None:
        """The common validity check (`rollout_problem`): the first failed check's name, or None."""

    def base_xy(self) -> list[float]:
        """The robot base's world xy (m): what pull moves the object toward."""

    def branch(self, primitive: str, seed: int) -> Branch | Dropped:
        """The verified source stream and the stream branched `BACKOFF` steps before first contact and continued
        by `primitive`, or why the attempt is dropped."""

    def close(self) -> None:
        """Release the simulators."""


# -- what an attempt hands back -------------------------------------------------------------------------------
@dataclass
class Dropped:
    """A rejected proposal and why (a key of the build report)."""

    reason: str
    rendered_steps: int = 0
    simulated_steps: int = 0
    detail: dict = field(default_factory=dict)


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


@dataclass
class Branch:
    """What a platform's T5 rig hands back for validation (`rig.branch(primitive, seed)`): the verified source
    stream, the branched stream (source up to `branch`, then the primitive), the scene placements both replay
    with (None: none), the branch and first-contact steps, the evaluated object's name, and the unrendered
    simulator steps spent so far."""

    source: np.ndarray
    stream: np.ndarray
    placements: dict | None
    branch: int
    contact: int
    evaluated: str
    simulated: int


# -- the rig every suite starts from --------------------------------------------------------------------------
def rollout_problem(k: PlatformKit, qlimits: np.ndarray, ro: Rollout) -> str | None:
    """The common validity checks (spec §5) of a platform rollout, read the way its platform needs."""
    return check_rollout(ro.stack("qpos"), ro.stack("tcp_pose"), ro.stack("object_poses"), k.joint_stream(ro),
                         qlimits, ro.actions, k.action_bounds, k.arm_joints)


class TaskRig:
    """The simulator resources of one task in one worker: expert source, unrendered and rendered replays."""

    def __init__(self, task: str, platform: str):
        self.kit = kit(platform)
        self.expert, self.render = self.kit.rig_simulators(task)
        self.spec = self.expert.spec
        self.state = self.expert.replayer
        self.qlimits = self.state.qlimits

    def close(self) -> None:
        self.expert.close()
        self.render.close()

    def invalid(self, ro: Rollout) -> str | None:
        return rollout_problem(self.kit, self.qlimits, ro)


# -- T4 -------------------------------------------------------------------------------------------------------
KINDS = ("distractor", "false_contact", "spatial_proximity")

SWEPT_MARGIN = 0.10  # m: a moved target's footprint keeps this far from every low robot link origin
DISTRACTOR_MARGIN = 0.05  # m: the same for a distractor (a prefilter only: the contact check decides)
REACH_Z = 0.12  # m: link origins above this height cannot touch a tabletop object (≤ 5 cm tall)
CLEARANCE = 0.02  # m: gap between a placed object and any other task object (xy bounding boxes)
WORKSPACE = ((-0.35, 0.25), (-0.35, 0.35))  # m: x and y ranges a target may be moved to (on the table, in view)
VIEW_MARGIN = QUERY_RADIUS + LK_WINDOW // 2 + 1  # px: the query grid and its windows stay inside the frame
ROBOT_CLEARANCE = QUERY_RADIUS + 1  # px: no query point on the robot's silhouette at frame 0
DONOR_TRIES = 12  # donor episodes tried for a distractor placement
PLACEMENT_TRIES = 256  # random target placements tried for spatial proximity


def point_gaps(box: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each xy point (N, 2) to an xy box [[x0, y0], [x1, y1]]."""
    d = np.maximum(box[0] - points, 0) + np.maximum(points - box[1], 0)
    return np.linalg.norm(d, axis=-1)


def box_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between two xy boxes [[x0, y0], [x1, y1]] (0 where they overlap)."""
    d = np.maximum(np.maximum(a[0] - b[1], b[0] - a[1]), 0)
    return float(np.linalg.norm(d))


class Sight:
    """Frame-0 visibility of a world point: `VIEW_MARGIN` px inside the frame and `ROBOT_CLEARANCE` px clear
    of the robot's silhouette (the frame every model shares)."""

    def __init__(self, intrinsic: np.ndarray, extrinsic: np.ndarray, robot_mask: np.ndarray):
        self.intrinsic, self.extrinsic, self.size = intrinsic, extrinsic, frame_size(robot_mask)
        free = (scoring_mask(robot_mask) == 0).astype(np.uint8)
        self.clearance = cv2.distanceTransform(free, cv2.DIST_L2, 5)  # px to the nearest robot pixel

    def __call__(self, xyz: np.ndarray) -> bool:
        try:
            x, y = project(xyz, self.intrinsic, self.extrinsic, self.size)
        except ValueError:
            return False
        inside = VIEW_MARGIN <= min(x, y) and max(x, y) <= SCORING_SIZE - 1 - VIEW_MARGIN
        return bool(inside and self.clearance[int(round(y)), int(round(x))] >= ROBOT_CLEARANCE)


def false_contact(rig: T4Rig, base: Rollout, source: np.ndarray, sight: Sight) -> Proposal | str:
    """The expert's stream with every gripper command clamped fully open throughout (the platform's own
    gripper dimensions and open value)."""
    dim, opened = list(np.atleast_1d(rig.kit.gripper_dim)), rig.kit.gripper_open
    if not (source[:, dim] != opened).any():
        return "source_never_closes"
    if not sight(base.observations[0].object_poses[0, :3]):
        return "object_out_of_sight"
    actions = source.copy()
    actions[:, dim] = opened
    return Proposal(actions, rig.spec.objects, rig.spec.target, {}, {"kind": "false_contact", "gripper": opened})


# -- T5 -------------------------------------------------------------------------------------------------------
PRIMITIVES = ("push", "pull", "drag", "rotate", "shake", "tap", "knock-over", "drop")

BACKOFF = 4  # steps (0.2 s) before first contact
MOTION_ONSET = 0.002  # m: the object "starts moving" once it is this far from its start
SOURCE_PROP_MAX_SHIFT = 0.001  # m: a prop must rest untouched through the source trajectory


def first_contact(poses: np.ndarray, contacts: np.ndarray) -> int | None:
    """First frame where the robot touches the object or the object has moved `MOTION_ONSET` from its start."""
    moved = np.linalg.norm(poses[:, :3] - poses[0, :3], axis=1) >= MOTION_ONSET
    hits = np.nonzero(contacts | moved)[0]
    return int(hits[0]) if len(hits) else None


def max_shift(poses: np.ndarray) -> float:
    """Largest distance of an object from its frame-0 position, (T, 7) poses."""
    return float(np.linalg.norm(poses[:, :3] - poses[0, :3], axis=1).max())


