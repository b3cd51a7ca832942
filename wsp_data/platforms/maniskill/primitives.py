"""Scripted T5 interaction primitives (spec §3.5) and the branching of an expert script.

`BranchScript` is a `SkillScript` that can carry extra scene actors (`PROPS`: knock-over's tall box and tap's
ball, set beside the task's target by `prop_placement`), place actors after reset, and re-run an expert
solver only up to a branch step; a primitive then continues from the exact simulator state the expert left
there, so the recorded stream is the expert's prefix followed by the primitive.

Each primitive `fn(s, target, others)` moves from wherever the branch left the hand (straight on when the
way is clear of every object, else up, over and down) and ends with the hand withdrawn and the scene at
rest. Directions are set by the scene: `u` is the horizontal unit vector from the robot base to the object,
`v` the horizontal perpendicular on the side with more room (away from other objects, toward the robot's
centre line).
- push: closed hand, flat face leading, comes down 2.5 cm short of the object's base side and travels
  0.12 m along `u` (the object slides ≈ 9 cm).
- pull: the same from the far side, 0.15 m back toward the base (−`u`; the object comes ≈ 12 cm). Where the camera
  looks from the hand's side (every task but PullCube, whose camera sits by the base), the hand ends between the
  camera and the cube, and a 6 cm rise left its fingers over the cube in the image in about one pull in five: there
  it rises `PULL_RISE`, well clear of the cube; elsewhere 6 cm, as every other primitive.
- drag: top grasp, 5 mm off the table, carried 0.10 m along `v`, released.
- rotate: top grasp, 5 mm off the table, turned 0.6 rad about the vertical through the hand, released.
- shake: top grasp, lifted 0.02 m, three fast cycles of ±0.06 m along `v`, set down, released.
- tap: closed hand at the ball's centre height jabs 3.5 cm past first touch along `u` at 0.24 m/s and
  withdraws at once; the ball rolls on by itself.
- knock-over: closed hand strikes the tall box 2.5 cm below its top along `u` and follows through 6 cm.
- drop: top grasp, lifted 0.10 m, released in the air; the object falls back.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import sapien
import sapien.physx as physx
from mani_skill.utils.geometry.trimesh_utils import get_component_mesh

from wsp_data.platforms.maniskill.env import CAMERA, GRIPPER_CLOSED, GRIPPER_OPEN, ExtraActor, ManiSkillPlatform
from wsp_data.platforms.maniskill.experts import rotated, top_grasp, turn_closing_to
from wsp_data.platforms.maniskill.skills import SkillScript

TALL_BOX = ExtraActor("tall_box", "box", (0.02, 0.02, 0.07), color=(0.95, 0.75, 0.1, 1.0), sleeps=False)
TAP_BALL = ExtraActor("tap_ball", "sphere", (0.035, 0.035, 0.035), color=(0.1, 0.3, 0.9, 1.0), sleeps=False)
PROPS = {"knock-over": TALL_BOX, "tap": TAP_BALL}  # primitives acting on a prop added beside the target
PROP_OFFSET = 0.13  # m beside the task's target, across `u`
CLEARANCE = 0.06  # m the hand travels above an object's top
FINGER_HALF_WIDTH = 0.01  # m from the TCP to the closed fingers' flat front face
STROKE_GAP = 0.025  # m short of first touch where a side stroke starts
PUSH_TRAVEL, PULL_TRAVEL = 0.12, 0.15  # m of hand travel from the stroke's start
PULL_RISE = 0.14  # m the hand rises after a pull seen from the hand's side (`camera_on_side`)
DRAG_DISTANCE, DRAG_LIFT = 0.10, 0.005
ROTATE_ANGLE = 0.6  # rad
SHAKE_AMPLITUDE, SHAKE_CYCLES, SHAKE_LIFT = 0.06, 3, 0.02
TAP_GAP, TAP_PRESS, TAP_SPEED = 0.04, 0.035, 1.0  # m before / past first touch; × the skills' 0.24 m/s
KNOCK_BELOW_TOP, KNOCK_FOLLOW = 0.025, 0.06
DROP_HEIGHT = 0.10


class _Branched(Exception):
    """Raised inside an expert solver when the branch step is reached."""


class BranchScript(SkillScript):
    """A `SkillScript` with scene extras and placements that can stop an expert solver at a branch step."""

    def __init__(self, task: str, objects: tuple[str, ...], extras: tuple[ExtraActor, ...] = ()):
        # SkillScript's own constructor cannot add extras: build the same state-only pd_ee_pose platform here
        self.platform = ManiSkillPlatform(task, render=False, control_mode="pd_ee_pose", objects=objects, extras=extras)
        self.u = self.platform.u
        self.actions, self.grip, self._target = [], GRIPPER_OPEN, None
        self._stop_at: int | None = None

    def reset(self, seed: int, placements: dict[str, np.ndarray] | None = None) -> None:
        self.platform.reset(seed, placements)
        self.actions, self.grip, self._target = [], GRIPPER_OPEN, self.tcp

    def _command(self, target: sapien.Pose) -> None:
        super()._command(target)
        if self._stop_at is not None and len(self.actions) >= self._stop_at:
            raise _Branched

    def run_until(self, solve: Callable[[SkillScript], None], steps: int) -> None:
        """Run `solve` from the current state and stop it after `steps` recorded actions."""
        self._stop_at = steps
        try:
            solve(self)
        except _Branched:
            return
        finally:
            self._stop_at = None
        raise ValueError(f"the expert ended after {len(self.actions)} steps, before the branch step {steps}")


# -- scene geometry -------------------------------------------------------------------------------
def _vertices(s: SkillScript, actor: str) -> np.ndarray:
    """The actor's collision mesh vertices in the world frame."""
    body = s.platform.actor(actor)._objs[0].find_component_by_type(physx.PhysxRigidDynamicComponent)
    return np.asarray(get_component_mesh(body, to_world_frame=True).vertices, dtype=np.float64)


def top_z(s: SkillScript, actor: str) -> float:
    return float(_vertices(s, actor)[:, 2].max())


def extent_along(s: SkillScript, actor: str, d) -> float:
    """How far the actor reaches from its origin in direction `d` (its support distance)."""
    return float(((_vertices(s, actor) - s.pose(actor).p) @ np.asarray(d, dtype=np.float64)).max())


def _radius_xy(s: SkillScript, actor: str) -> float:
    """The actor's horizontal reach from its origin, in any direction."""
    return float(np.linalg.norm((_vertices(s, actor) - s.pose(actor).p)[:, :2], axis=1).max())


def _path_clear(s: SkillScript, a: np.ndarray, b: np.ndarray, avoid: tuple[str, ...], margin: float = 0.03) -> bool:
    """Whether the horizontal segment a→b stays `margin` clear of every actor in `avoid`."""
    ab = (b - a)[:2]
    for name in avoid:
        p = s.pose(name).p[:2]
        t = np.clip((p - a[:2]) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        if np.linalg.norm(a[:2] + t * ab - p) < _radius_xy(s, name) + margin:
            return False
    return True


def away_from_base(s: SkillScript, actor: str) -> np.ndarray:
    """Horizontal unit vector from the robot base to the actor."""
    d = (s.pose(actor).p - s.u.agent.robot.pose.sp.p) * [1, 1, 0]
    return d / np.linalg.norm(d)


def lateral(s: SkillScript, actor: str, others: tuple[str, ...], reach: float = 0.12) -> np.ndarray:
    """The horizontal perpendicular to `away_from_base` on the side with more room: farther from the other
    objects, then nearer the robot's centre line."""
    u = away_from_base(s, actor)
    v = np.array([-u[1], u[0], 0.0])
    base = s.u.agent.robot.pose.sp
    left = base.to_transformation_matrix()[:3, 1]
    p = s.pose(actor).p

    def score(side: float) -> tuple[float, float]:
        end = p + side * reach * v
        room = min((np.linalg.norm((s.pose(o).p - end)[:2]) for o in others), default=np.inf)
        return -room, abs(float((end - base.p) @ left))

    return min((1.0, -1.0), key=score) * v


def camera_on_side(s: SkillScript, actor: str, d: np.ndarray) -> bool:
    """Whether the evaluated camera looks at the actor from the side `d` points to (horizontally)."""
    eye = s.u.scene.sensors[CAMERA].camera.global_pose.sp.p
    return float(((eye - s.pose(actor).p) * [1, 1, 0]) @ np.asarray(d, dtype=np.float64)) > 0.0


def facing(s: SkillScript, d: np.ndarray) -> np.ndarray:
    """Hand orientation with the closing axis across `d`: the closed fingers' flat face leads."""
    return rotated(s._target, [0, 0, 1], turn_closing_to(s, [-d[1], d[0], 0.0])).q


def prop_placement(s: SkillScript, prop: ExtraActor, target: str, others: tuple[str, ...]
                   ) -> dict[str, np.ndarray] | None:
    """Where a prop rests: `PROP_OFFSET` beside the target (across `u`), on the table, yawed with `u`, on the
    side farther from the hand (out of the expert's way in); None when both sides come within 8 cm of
    another object."""
    u = away_from_base(s, target)
    v = np.array([-u[1], u[0], 0.0])
    sides = [s.pose(target).p + side * PROP_OFFSET * v for side in (1.0, -1.0)]
    sides = [p for p in sides if all(np.linalg.norm((s.pose(o).p - p)[:2]) >= 0.08 for o in others)]
    if not sides:
        return None
    p = max(sides, key=lambda p: float(np.linalg.norm((p - s.tcp.p)[:2])))
    yaw = float(np.arctan2(u[1], u[0]))
    return {prop.name: np.array([p[0], p[1], prop.half_size[2], np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])}


# -- shared motions -------------------------------------------------------------------------------
def _lift_to(s: SkillScript, z: float) -> None:
    """Raise the hand straight up to height `z` (no-op when already there)."""
    if s._target.p[2] < z - 1e-3:
        s.move(sapien.Pose([*s._target.p[:2], z], s._target.q), settle=0)


def _reach(s: SkillScript, pose: sapien.Pose, avoid: tuple[str, ...], grip: float) -> None:
    """Go straight to `pose` when the way is clear of `avoid`; else lift above them, set the gripper, travel
    over `pose` and come down onto it."""
    if _path_clear(s, s._target.p, pose.p, avoid):
        s.grip = grip
        s.move(pose, speed=0.6, settle=0)
        return
    clear_z = max(top_z(s, a) for a in avoid) + CLEARANCE
    _lift_to(s, clear_z)
    s.grip = grip
    s.move(sapien.Pose([*pose.p[:2], max(clear_z, s._target.p[2])], pose.q), settle=0)
    s.move(pose, speed=0.6, settle=0)


def _withdraw(s: SkillScript, height: float = CLEARANCE, hold: int = 8) -> None:
    s.move(sapien.Pose([0, 0, height]) * s._target, settle=0)
    s.hold(hold)


def _grasp(s: SkillScript, actor: str) -> sapien.Pose:
    """Top grasp: close right away when the branch left the open hand over the grasp, else come from above."""
    g = top_grasp(s, actor)
    off = s._target.p - g.p
    if not (np.linalg.norm(off[:2]) < 0.005 and -0.005 < off[2] < 0.07 and s.grip == GRIPPER_OPEN):
        _lift_to(s, top_z(s, actor) + CLEARANCE)
        s.grip = GRIPPER_OPEN
        s.move(g * sapien.Pose([0, 0, -CLEARANCE]), settle=0)
    s.move(g, speed=0.6)
    s.close_gripper()
    return g


def _stroke(s: SkillScript, actor: str, d: np.ndarray, z: float, gap: float, avoid: tuple[str, ...]) -> sapien.Pose:
    """Closed hand, flat face leading along `d`, brought `gap` short of first touch with the actor at height
    `z` (first touch: the fingers' front face, `FINGER_HALF_WIDTH` ahead of the TCP, meets the actor)."""
    c = s.pose(actor).p
    p = c - (extent_along(s, actor, -d) + FINGER_HALF_WIDTH + gap) * d
    start = sapien.Pose([p[0], p[1], z], facing(s, d))
    _reach(s, start, (actor, *avoid), GRIPPER_CLOSED)
    return start


def _moved(s: SkillScript, delta, speed: float = 0.5, settle: int = 0) -> None:
    s.move(sapien.Pose(s._target.p + np.asarray(delta, dtype=np.float64), s._target.q), speed=speed, settle=settle)


def _side_height(s: SkillScript, actor: str) -> float:
    """Where a closed hand meets an object from the side: its centre, at least 1.5 cm off the table."""
    return max(float(s.pose(actor).p[2]), 0.015)


# -- the primitives -------------------------------------------------------------------------------
def push(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    u = away_from_base(s, target)
    _stroke(s, target, u, _side_height(s, target), STROKE_GAP, others)
    _moved(s, PUSH_TRAVEL * u, speed=0.5, settle=2)
    _withdraw(s)


def pull(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    u = away_from_base(s, target)
    _stroke(s, target, -u, _side_height(s, target), STROKE_GAP, others)
    _moved(s, -PULL_TRAVEL * u, speed=0.5, settle=2)
    _withdraw(s, height=PULL_RISE if camera_on_side(s, target, u) else CLEARANCE)


def _release(s: SkillScript) -> None:
    s.open_gripper()
    _withdraw(s)


def drag(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    v = lateral(s, target, others)
    _grasp(s, target)
    _moved(s, [0, 0, DRAG_LIFT], speed=0.3)
    _moved(s, DRAG_DISTANCE * v, speed=0.5, settle=2)
    _release(s)


def rotate(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    _grasp(s, target)
    _moved(s, [0, 0, DRAG_LIFT], speed=0.3)
    sign = 1.0 if s.actions[-1][6] > 0 else -1.0  # turn joint 7 back toward the middle of its range
    s.move(rotated(s._target, [0, 0, 1], sign * ROTATE_ANGLE), speed=0.5, settle=2)
    _release(s)


def shake(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    v = lateral(s, target, others)
    _grasp(s, target)
    _moved(s, [0, 0, SHAKE_LIFT], speed=0.5)
    centre = s._target.p.copy()
    for _ in range(SHAKE_CYCLES):
        for side in (1, -1):
            s.move(sapien.Pose(centre + side * SHAKE_AMPLITUDE * v, s._target.q), speed=1.5, settle=0)
    s.move(sapien.Pose(centre, s._target.q), speed=1.5, settle=2)
    _moved(s, [0, 0, -SHAKE_LIFT + 0.003], speed=0.5, settle=2)
    _release(s)


def tap(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    ball = TAP_BALL.name
    u = away_from_base(s, ball)
    start = _stroke(s, ball, u, _side_height(s, ball), TAP_GAP, (target, *others))
    s.hold(2)
    _moved(s, (TAP_GAP + TAP_PRESS) * u, speed=TAP_SPEED, settle=1)
    s.move(start, speed=TAP_SPEED, settle=0)
    _withdraw(s, hold=12)


def knock_over(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    box = TALL_BOX.name
    u = away_from_base(s, box)
    _stroke(s, box, u, top_z(s, box) - KNOCK_BELOW_TOP, STROKE_GAP, (target, *others))
    _moved(s, (STROKE_GAP + KNOCK_FOLLOW) * u, speed=1.0)
    _moved(s, -0.04 * u, speed=1.0)
    _withdraw(s, hold=12)


def drop(s: SkillScript, target: str, others: tuple[str, ...]) -> None:
    _grasp(s, target)
    _moved(s, [0, 0, DROP_HEIGHT], speed=0.8, settle=2)
    s.open_gripper(steps=4)
    s.hold(10)
    _withdraw(s, height=0.04)


SCRIPTS: dict[str, Callable[[SkillScript, str, tuple[str, ...]], None]] = {
    "push": push, "pull": pull, "drag": drag, "rotate": rotate, "shake": shake, "tap": tap,
    "knock-over": knock_over, "drop": drop,
}
