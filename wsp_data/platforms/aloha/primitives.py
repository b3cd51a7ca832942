"""T5's scripted primitives on ALOHA (spec §3.5), closed-loop in end-effector space like the experts
(`experts.Script`: grip point, pitch, roll, gripper per arm, closed-form IK). Each continues a `Script` that
replayed the expert's stream up to the branch step (`BranchScript`) and acts on the task's target with the arm
the expert uses first on it (`ACTING_ARM`); the other arm holds its command (lifted to 15 cm first where it was
reaching down too: peg_insertion, two_arm_lift). Every hand stays vertical. `w` is the target's horizontal y
axis (the closing axis of the expert's grasp, across a peg or a bar), signed to the side with more room from
the other objects and the table's edges (`_side`); "toward the base" is the horizontal unit vector from the
target to the acting arm's base (what the pull rule measures against).

- push: the open hand straddles the target, fingers closing along `w` (where the branch left them), and moves
  `PUSH_TRAVEL` along `w`: the rear finger's flat inner face pushes, as push_cube's expert does; then up.
- pull: the same straddle re-oriented above the target to close toward the base, `PULL_TRAVEL` toward it: the
  far finger draws the target in.
- drag: the expert's grasp, 5 mm off the table, `DRAG_TRAVEL` along `w`, set down, released.
- rotate: the expert's grasp, 5 mm off the table, the wrist turned `ROTATE_ANGLE` toward its middle, set down,
  released.
- shake: a grasp closing along the object's horizontal axis nearer the arm's radial direction (`_shake_axis`),
  lifted `SHAKE_LIFT`, `SHAKE_CYCLES` fast cycles of ±`SHAKE_AMPLITUDE` along that axis, set down, released.
- tap: the straddle along `w`, then one jab at constant speed (`TAP_TRAVEL` in `TAP_STEPS` steps) and straight
  up at once: the target slides on alone.
- knock-over: a `PROP` (3 × 3 × 10 cm block) stands `PROP_DISTANCE` from the target toward the acting arm's
  base, else beside it (`prop_placements`); the closed hand strikes it `KNOCK_BELOW_TOP` below its top, across
  the line to the base on the side with room for it to fall (`fall_direction`), and follows through.
- drop: the expert's grasp, lifted `DROP_LIFT`, opened in the air.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from wsp_data.platforms.aloha.env import OBJECTS, AlohaPlatform
from wsp_data.platforms.aloha.experts import (
    ARM_NAMES, FINGERTIP, PUSH_HEIGHT, V, ArmIK, Hand, OutOfTime, Script, cube_yaw,
)
from wsp_data.platforms.contract import box_gap

# the arm that first touches each task's target in its expert (measured; two_arm_lift's arms touch the bar on
# the same step: the right one acts, as on every other task but hand_over)
ACTING_ARM = {"transfer_cube": 1, "peg_insertion": 1, "lift_cube": 1, "push_cube": 1, "cube_in_bin": 1,
              "stack_cubes": 1, "hand_over": 0, "two_arm_lift": 1}
PROP = "tall_block"  # knock-over's prop (`env.PROPS`)
TABLE = ((-0.28, 0.28), (0.30, 0.70))  # m: x, y ranges an object may be moved to or placed in (in view, reach)
CLEAR = 0.03  # m the fingertips pass above an object's top
STEP = 0.012  # m of hand travel per step on free moves (0.24 m/s)
TURN = 0.12  # rad of wrist pitch or roll per step on free moves (2.4 rad/s)
PUSH_TRAVEL = 0.06  # m of hand travel (the object ≈ 1.5 cm less: the open fingers' gap)
PULL_TRAVEL = 0.10
DRAG_TRAVEL, DRAG_LIFT = 0.08, 0.005
ROTATE_ANGLE = 0.6  # rad
SHAKE_AMPLITUDE, SHAKE_CYCLES, SHAKE_LIFT, SHAKE_STEPS = 0.04, 3, 0.02, 4  # m, -, m, steps per half cycle
TAP_TRAVEL, TAP_STEPS = 0.085, 3
KNOCK_BELOW_TOP, KNOCK_GAP, KNOCK_FOLLOW = 0.025, 0.03, 0.06  # m
PROP_DISTANCE = (0.12, 0.09)  # m from the target toward the acting arm's base, tried in order
PROP_AREA = ((-0.33, 0.33), (0.30, 0.70))  # m: where the prop may stand (in view: 0.35 m projects inside)
PROP_BASE_CLEARANCE = 0.15  # m from the acting arm's base
FALL_LENGTH = 0.12  # m a struck prop's box travels as it falls (its 10 cm length and a slide)
FALL_AREA = ((-0.35, 0.35), (0.28, 0.80))  # m: where a fallen prop may lie (on the table, in view)
DROP_LIFT = 0.10
HOLD = 4  # steps held at the end, so the scene is recorded at rest
_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))


class BranchScript(Script):
    """A `Script` resumed from a replayed stream prefix: the hands' commands are read back from its last
    action (the IK inverted: pitch = shoulder + elbow + wrist angle, roll = wrist rotate)."""

    def __init__(self, p: AlohaPlatform, seed: int, prefix: np.ndarray, placements: dict | None = None):
        super().__init__(p, seed, placements)
        for a in prefix:
            self.actions.append(np.asarray(a, dtype=np.float32))
            self.observation = p.step(a)
        if len(prefix):
            a, ee = np.asarray(prefix[-1], dtype=np.float64), p.ee_action(prefix[-1]).astype(np.float64)
            self.hand = [Hand(ee[7 * k:7 * k + 3], float(a[7 * k + 1] + a[7 * k + 2] + a[7 * k + 4]),
                              float(a[7 * k + 5]), float(a[7 * k + 6])) for k in (0, 1)]


# -- scene geometry -------------------------------------------------------------------------------------------
def corners(p: AlohaPlatform, name: str, offset=(0.0, 0.0)) -> np.ndarray:
    """World corners (N, 3) of an object's box parts, shifted by an xy `offset`."""
    pose, R = p.object_pose(name), p.body_rotation(name)
    local = np.concatenate([np.asarray(q.pos) + _CORNERS * q.half for q in OBJECTS[name].parts])
    return pose[:3] + local @ R.T + [*offset, 0.0]


def xy_box(p: AlohaPlatform, name: str, offset=(0.0, 0.0)) -> np.ndarray:
    xy = corners(p, name, offset)[:, :2]
    return np.stack([xy.min(0), xy.max(0)])


def _inside(box: np.ndarray, area=TABLE) -> float:
    """How far an xy box lies inside `area` (default `TABLE`; negative: outside)."""
    lo, hi = np.array([area[0][0], area[1][0]]), np.array([area[0][1], area[1][1]])
    return float(min((box[0] - lo).min(), (hi - box[1]).min()))


def room(p: AlohaPlatform, name: str, d: np.ndarray, reach: float, others: tuple[str, ...]) -> float:
    """The least clearance of `name`'s xy box moved up to `reach` along `d`: from the other objects' boxes and
    from the edges of `TABLE`."""
    boxes = [xy_box(p, o) for o in others]
    gaps = []
    for t in np.linspace(0.0, reach, 6):
        moved = xy_box(p, name, t * d[:2])
        gaps += [_inside(moved), *(box_gap(moved, b) for b in boxes)]
    return min(gaps)


def top(p: AlohaPlatform, name: str) -> float:
    return float(corners(p, name)[:, 2].max())


def base_xy(p: AlohaPlatform, arm: int) -> np.ndarray:
    return ArmIK(p, arm).base[:2]


def toward_base(p: AlohaPlatform, arm: int, name: str) -> np.ndarray:
    """Horizontal unit vector from the object to the arm's base."""
    d = np.r_[base_xy(p, arm) - p.object_pose(name)[:2], 0.0]
    return d / np.linalg.norm(d)


def _side(p: AlohaPlatform, name: str, reach: float, others: tuple[str, ...]) -> np.ndarray:
    """The object's horizontal y axis, signed to the side with more room over `reach`."""
    y = p.body_rotation(name)[:, 1] * [1, 1, 0]
    y /= np.linalg.norm(y)
    return max((y, -y), key=lambda d: room(p, name, d, reach, others))


def _yaw(d: np.ndarray) -> float:
    return float(np.arctan2(d[1], d[0]))


# -- shared motions -------------------------------------------------------------------------------------------
def _go(s: Script, arm: int, steps: int, **fields) -> None:
    s.go(max(1, steps), **{ARM_NAMES[arm]: fields})


def _move(s: Script, arm: int, pos, step: float = STEP, **fields) -> None:
    """To `pos` (and the other `fields`) at about `step` m and at most `TURN` rad of pitch or roll per action,
    at least 3 actions."""
    pos, h = np.asarray(pos, dtype=np.float64), s.hand[arm]
    turn = max([abs(fields[k] - getattr(h, k)) for k in ("pitch", "roll") if k in fields], default=0.0)
    _go(s, arm, max(3, int(np.ceil(np.linalg.norm(pos - h.pos) / step)), int(np.ceil(turn / TURN))), pos=pos,
        **fields)


def _lift(s: Script, arm: int, z: float) -> None:
    if s.hand[arm].pos[2] < z - 1e-3:
        _move(s, arm, [*s.hand[arm].pos[:2], z])


def _clear_other(s: Script, arm: int, z: float = 0.15) -> None:
    """Lift the other hand straight up to `z` when it reached down (two_arm_lift, peg_insertion)."""
    if s.hand[1 - arm].pos[2] < z:
        _lift(s, 1 - arm, z)


def _withdraw(s: Script, arm: int, up: float = 0.08) -> None:
    _move(s, arm, s.hand[arm].pos + [0, 0, up])
    s.hold(HOLD)


def _straddle(s: Script, arm: int, name: str, d: np.ndarray, others: tuple[str, ...]) -> None:
    """The open hand around `name`'s centre at push height, fingers closing along `d`; re-oriented above every
    object when the hand is not already so (the branch leaves it around the target, closing along its y)."""
    c = s.obj(name)
    pos = np.array([c[0], c[1], PUSH_HEIGHT])
    roll = s.grasp_roll(arm, pos, _yaw(d))
    h = s.hand[arm]
    if abs(roll - h.roll) > 0.05 or np.linalg.norm(h.pos[:2] - c[:2]) > 0.01 or h.grip < 0.9:
        clear = max(top(s.p, o) for o in (name, *others)) + FINGERTIP + CLEAR
        _lift(s, arm, clear)
        _move(s, arm, [*c[:2], clear], pitch=V, roll=roll, grip=1.0)
    _move(s, arm, pos, step=0.008)


def _stroke(s: Script, arm: int, name: str, d: np.ndarray, travel: float, steps: int) -> None:
    """Move the straddling hand `travel` along `d` (smoothly), keeping `name`'s centre between the fingers."""
    start = s.hand[arm].pos.copy()
    for i in range(1, steps + 1):
        f = i / steps
        pos = start + travel * f * f * (3 - 2 * f) * d
        e = (s.obj(name) - pos) * [1, 1, 0]
        s.hand[arm] = replace(s.hand[arm], pos=pos + e - (e @ d) * d)  # follow the object across `d`
        s.act()


def _grasp(s: Script, arm: int, name: str, yaw: float | None = None) -> None:
    """A vertical grasp at `name`'s centre, closing along world yaw `yaw` (default: the expert's, across the
    object's y axis): closed at once when the branch left the open hand there, else over it, down and closed
    (`Script.pick`)."""
    g = s.grip_point(name)
    yaw = cube_yaw(s.p, name) + np.pi / 2 if yaw is None else yaw
    h = s.hand[arm]
    there = (np.linalg.norm(h.pos[:2] - g[:2]) < 0.005 and -0.002 < h.pos[2] - g[2] < 0.01 and h.grip > 0.9
             and abs(s.grasp_roll(arm, g, yaw) - h.roll) < 0.05 and abs(h.pitch - V) < 0.05)
    if there:
        _go(s, arm, 5, grip=0.0)
        s.hold(1)
    else:
        s.pick({arm: (g, yaw)})


def _release(s: Script, arm: int, down: float) -> None:
    """Set the held object down by `down`, open, withdraw."""
    if down > 0:
        _move(s, arm, s.hand[arm].pos - [0, 0, down], step=0.005)
    _go(s, arm, 4, grip=1.0)
    _withdraw(s, arm)


# -- the primitives -------------------------------------------------------------------------------------------
def push(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    d = _side(s.p, name, PUSH_TRAVEL, others)
    _straddle(s, arm, name, d, others)
    _stroke(s, arm, name, d, PUSH_TRAVEL, 12)
    _withdraw(s, arm)


def pull(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    d = toward_base(s.p, arm, name)
    _straddle(s, arm, name, d, others)
    _stroke(s, arm, name, d, PULL_TRAVEL, 18)
    _withdraw(s, arm)


def drag(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    d = _side(s.p, name, DRAG_TRAVEL, others)
    _grasp(s, arm, name)
    _move(s, arm, s.hand[arm].pos + [0, 0, DRAG_LIFT], step=0.005)
    _go(s, arm, 14, pos=s.hand[arm].pos + DRAG_TRAVEL * d)
    _release(s, arm, DRAG_LIFT)


def rotate(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    _grasp(s, arm, name)
    _move(s, arm, s.hand[arm].pos + [0, 0, DRAG_LIFT], step=0.005)
    roll = s.hand[arm].roll
    _go(s, arm, 12, roll=roll - np.copysign(ROTATE_ANGLE, roll))  # toward the wrist's middle
    _release(s, arm, DRAG_LIFT)


def _shake_axis(s: Script, arm: int, name: str, others: tuple[str, ...]) -> np.ndarray:
    """Of the object's horizontal x and y axes, the one nearer the arm's radial direction if it has room for
    the shake both ways, else the other (a grip closing across the radial direction lets the object turn about
    the pads as the wrist pitch lags: measured 0.8-1.6 rad in three cycles)."""
    R, u = s.p.body_rotation(name), toward_base(s.p, arm, name)
    axes = sorted((R[:, 0] * [1, 1, 0], R[:, 1] * [1, 1, 0]), key=lambda a: -abs(a @ u) / np.linalg.norm(a))
    axes = [a / np.linalg.norm(a) for a in axes]
    free = [min(room(s.p, name, a, SHAKE_AMPLITUDE, others), room(s.p, name, -a, SHAKE_AMPLITUDE, others))
            for a in axes]
    return axes[0] if free[0] >= 0.02 or free[0] >= free[1] else axes[1]


def shake(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    d = _shake_axis(s, arm, name, others)
    _grasp(s, arm, name, _yaw(d))
    _move(s, arm, s.hand[arm].pos + [0, 0, SHAKE_LIFT], step=0.006)
    centre = s.hand[arm].pos.copy()
    for _ in range(SHAKE_CYCLES):
        for side in (1.0, -1.0):
            _go(s, arm, SHAKE_STEPS, pos=centre + side * SHAKE_AMPLITUDE * d)
    _go(s, arm, SHAKE_STEPS, pos=centre)
    _release(s, arm, SHAKE_LIFT)


def tap(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    d = _side(s.p, name, TAP_TRAVEL, others)
    _straddle(s, arm, name, d, others)
    start = s.hand[arm].pos.copy()
    for i in range(1, TAP_STEPS + 1):  # constant speed in, then straight up
        s.hand[arm] = replace(s.hand[arm], pos=start + TAP_TRAVEL * i / TAP_STEPS * d)
        s.act()
    _go(s, arm, 3, pos=s.hand[arm].pos + [0, 0, 0.06])
    _withdraw(s, arm, 0.04)


def fall_direction(p: AlohaPlatform, arm: int, xy: np.ndarray, objects: tuple[str, ...]) -> tuple[np.ndarray, float]:
    """Where a prop standing at `xy` is struck toward: across the line to the arm's base, on the side where its
    fallen length stays farther from the `objects` and inside `FALL_AREA`; and that clearance (m)."""
    u = np.r_[base_xy(p, arm) - xy, 0.0]
    u /= np.linalg.norm(u)
    half = np.asarray(OBJECTS[PROP].parts[0].half)[:2]
    boxes = [xy_box(p, o) for o in objects]

    def clearance(d: np.ndarray) -> float:
        gaps = []
        for t in np.linspace(0.0, FALL_LENGTH, 6):
            box = np.stack([xy - half, xy + half]) + t * d[:2]
            gaps += [_inside(box, FALL_AREA), *(box_gap(box, b) for b in boxes)]
        return min(gaps)

    across = np.array([-u[1], u[0], 0.0])
    d = max((across, -across), key=clearance)
    return d, clearance(d)


def knock_over(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    """`name` is the task's target, the struck object the prop (`others` holds the other task objects)."""
    objects = (name, *others)
    c = s.obj(PROP)
    d, _ = fall_direction(s.p, arm, c[:2], objects)
    half = float(np.abs(xy_box(s.p, PROP) - c[:2]).max())
    start = c - (half + KNOCK_GAP) * d
    start[2] = top(s.p, PROP) - KNOCK_BELOW_TOP + FINGERTIP
    clear = max(top(s.p, o) for o in (PROP, *objects)) + FINGERTIP + CLEAR
    _lift(s, arm, clear)
    _move(s, arm, [*start[:2], clear], pitch=V, roll=s.grasp_roll(arm, start, _yaw(d) + np.pi / 2), grip=0.0)
    _move(s, arm, start, step=0.008)
    _go(s, arm, 6, pos=start + (KNOCK_GAP + KNOCK_FOLLOW) * d)
    _withdraw(s, arm)
    s.hold(8)


def drop(s: Script, arm: int, name: str, others: tuple[str, ...]) -> None:
    _grasp(s, arm, name)
    _go(s, arm, 10, pos=s.hand[arm].pos + [0, 0, DROP_LIFT])
    _go(s, arm, 3, grip=1.0)
    s.hold(12)  # let it land
    _withdraw(s, arm, 0.04)


SCRIPTS: dict[str, Callable[[Script, int, str, tuple[str, ...]], None]] = {
    "push": push, "pull": pull, "drag": drag, "rotate": rotate, "shake": shake, "tap": tap,
    "knock-over": knock_over, "drop": drop,
}


def prop_placements(p: AlohaPlatform, task: str, seed: int) -> list[dict[str, np.ndarray]]:
    """Where knock-over's prop may stand in scene `seed`, in order of preference: `PROP_DISTANCE` from the target
    toward the acting arm's base (under the arm, out of the expert's way), then as far beside it (across that
    line); each in `PROP_AREA`, `PROP_BASE_CLEARANCE` from the arm's base and 4 cm clear of every task object."""
    p.reset(seed)
    spec, arm = p.spec, ACTING_ARM[task]
    u, c = toward_base(p, arm, spec.target), p.object_pose(spec.target)
    across = np.array([-u[1], u[0], 0.0])
    half = np.asarray(OBJECTS[PROP].parts[0].half)[:2]
    out = []
    for xy in [c[:2] + dist * u[:2] for dist in PROP_DISTANCE] + [c[:2] + s * PROP_DISTANCE[0] * across[:2]
                                                                   for s in (1.0, -1.0)]:
        box = np.stack([xy - half, xy + half])
        if (_inside(box, PROP_AREA) >= 0 and np.linalg.norm(xy - base_xy(p, arm)) >= PROP_BASE_CLEARANCE
                and all(box_gap(box, xy_box(p, o)) >= 0.04 for o in spec.objects)
                and fall_direction(p, arm, xy, spec.objects)[1] >= 0.02):
            out.append({PROP: np.array([*xy, OBJECTS[PROP].rest_z, 1.0, 0.0, 0.0, 0.0])})
    return out


def branch_stream(p: AlohaPlatform, task: str, seed: int, source: np.ndarray, branch: int, primitive: str,
                  placements: dict | None = None) -> np.ndarray | None:
    """The expert's stream up to step `branch` (replayed), then `primitive` by the acting arm, closed-loop; None
    if it runs out of steps."""
    spec, arm = p.spec, ACTING_ARM[task]
    s = BranchScript(p, seed, source[:branch], placements)
    try:
        _clear_other(s, arm)
        SCRIPTS[primitive](s, arm, spec.target, tuple(o for o in spec.objects if o != spec.target))
    except OutOfTime:
        return None
    return np.stack(s.actions)
