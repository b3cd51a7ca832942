"""T5's scripted primitives on LIBERO (spec §3.5: push, pull, tap, drop), closed-loop in LIBERO's OSC action
space on simulator state. Each continues a `PickPlaceScript` that replayed the expert's stream up to the
branch step, and acts on the task's target.

- push: the closed fingers as a paddle, lowered beside the target and driven `PUSH_TRAVEL` through it along
  a horizontal side (of ±x, ±y), then withdrawn upward.
- pull: the expert's grasp, then the target slid `PULL_TRAVEL` toward the robot base at table height, released.
- tap: the closed fingers beside the target strike it once at full speed (`TAP_REACH` past first contact)
  and withdraw at once: back out, then lift.
- drop: the expert's grasp, a `DROP_LIFT` lift, the fingers opened in the air.

Push and tap act along the side with the most free room from the other objects. The room is weighed from
movable objects only, so that side can lead the hand under a fixture (e.g. `KITCHEN_SCENE10`'s cabinet top),
which then stops its lift: a hand left low beside the object at the end, what a push looks like and not spec §3.5's
press-and-retract, and a push unlike every other task's. So each checks its own lift, which must raise the hand
`MIN_RISE`; where it does not, the same scene is tried from the side with the next most room, and only when
every side is stopped is the proposal dropped (`push_not_withdrawn`, `tap_not_withdrawn`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wsp_data.platforms.libero.env import GRIPPER_CLOSED, GRIPPER_OPEN, LiberoPlatform
from wsp_data.platforms.libero.experts import LiberoTaskSpec, OutOfTime, PickPlaceScript

# Push and tap need a target the hand can pass over: the Panda hand's collision body sits ~2 cm above the
# fingertips, so beside a tall can or carton it hits the top (measured: the alphabet soup never moved; the
# milk carton toppled). Bowls and flat boxes (≤ 5 cm) slide cleanly.
LOW_TARGETS = ("bowl", "cream_cheese", "butter", "chocolate_pudding")
STANDOFF = 0.035  # m between the fingers and the target's side before a push or tap
PUSH_TRAVEL = 0.10  # m the fingers move past the standoff
PUSH_SPEED = 0.35  # OSC units (×0.05 m per step commanded)
PULL_TRAVEL = 0.12  # m toward the robot base
TAP_REACH = 0.02  # m the strike aims past the target's side
DROP_LIFT = 0.12  # m
WITHDRAW_LIFT = 0.10  # m
MIN_RISE = 0.05  # m a push's or tap's withdrawal must lift the hand (half of WITHDRAW_LIFT; measured: 0.094-0.111 m
# when free, 0.017-0.027 m under KITCHEN_SCENE10's cabinet top)
CLEAR = 0.05  # m above the target's top when moving over it
HAND_CLEARANCE = 0.04  # m: fingertips at most this far below a target's top, so the hand passes over it
DIRECTIONS = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])


def _side(s: PickPlaceScript, rank: int) -> np.ndarray:
    """Of ±x, ±y, the push direction with the `rank`-th most room (0: the most): room is how far its path
    (0.15 m beyond the target) and its approach side (the opposite one) keep from every other scene object's box.
    Ties keep the order of `DIRECTIONS`."""
    lo, hi = s.g.box(s.spec.target)
    centre = (lo + hi) / 2
    others = [s.g.box(n) for n in s.p.u.objects_dict if n != s.spec.target]

    def room(d: np.ndarray) -> float:
        pts = [centre + d * t for t in np.linspace(-0.12, 0.15, 10)]
        gaps = [np.linalg.norm(np.maximum(np.maximum(b[0][:2] - p[:2], p[:2] - b[1][:2]), 0)) for b in others
                for p in pts]
        return min(gaps, default=1.0)

    return sorted(DIRECTIONS, key=room, reverse=True)[rank]


def _beside(s: PickPlaceScript, d: np.ndarray) -> np.ndarray:
    """The point `STANDOFF` before the target's side along `d`, at finger height."""
    lo, hi = s.g.box(s.spec.target)
    centre = (lo + hi) / 2
    half = float(np.abs(d[:2]) @ ((hi - lo)[:2] / 2))
    # fingertips low enough to meet the side, the hand body (~5 cm above them) clear of a tall object's top
    z = max(lo[2] + min(0.025, 0.5 * (hi[2] - lo[2])), hi[2] - HAND_CLEARANCE)
    start = centre - d * (half + STANDOFF)
    start[2] = z
    return start


def _approach(s: PickPlaceScript, point: np.ndarray) -> None:
    """Rise clear of the target with the fingers as they are, close them, come down at `point`."""
    top = s.g.box(s.spec.target)[1][2] + CLEAR
    s.move([*s.g.ee()[:2], max(s.g.ee()[2], top)], max_steps=30)
    s.gripper(GRIPPER_CLOSED, 6)
    s.move([*point[:2], top], max_steps=60)
    s.move(point, max_steps=40)


def _withdraw(s: PickPlaceScript) -> None:
    s.move(s.g.ee() + [0, 0, WITHDRAW_LIFT], max_steps=25)


class Blocked(Exception):
    """The scene stopped a primitive's scripted motion; `reason` is the drop reason."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


def _withdraw_clear(s: PickPlaceScript, primitive: str) -> None:
    """`_withdraw`, which must lift the hand at least `MIN_RISE`; else `Blocked`."""
    low = s.g.ee()[2]
    _withdraw(s)
    if s.g.ee()[2] - low < MIN_RISE:
        raise Blocked(f"{primitive}_not_withdrawn")


def push(s: PickPlaceScript, rank: int = 0) -> None:
    d = _side(s, rank)
    start = _beside(s, d)
    _approach(s, start)
    goal = start + d * (STANDOFF + PUSH_TRAVEL)
    for _ in range(80):
        err = goal - s.g.ee()
        if np.linalg.norm(err[:2]) < 0.005:
            break
        a = np.zeros(7)
        a[:3] = np.clip(s.gain * err, -PUSH_SPEED, PUSH_SPEED)
        a[6] = GRIPPER_CLOSED
        s.act(a)
    _withdraw_clear(s, "push")


def pull(s: PickPlaceScript) -> None:
    s.grasp()
    base = s.p.base_xy()
    here = s.g.ee()
    toward = np.r_[base - here[:2], 0.0]
    toward /= np.linalg.norm(toward)
    s.move(here + [0, 0, 0.004], max_steps=10)
    s.move(here + toward * PULL_TRAVEL + [0, 0, 0.004], max_steps=80)
    s.gripper(GRIPPER_OPEN, 8)
    _withdraw(s)


def tap(s: PickPlaceScript, rank: int = 0) -> None:
    d = _side(s, rank)
    start = _beside(s, d)
    _approach(s, start)
    s.move(start, tol=0.003, max_steps=20)
    strike = start + d * (STANDOFF + TAP_REACH)
    for _ in range(6):  # full speed in, then straight back out
        if (strike - s.g.ee())[:2] @ d[:2] <= 0:
            break
        s.act(np.r_[d * 1.0, 0, 0, 0, GRIPPER_CLOSED])
    s.move(start - d * 0.02, max_steps=20)
    _withdraw_clear(s, "tap")


def drop(s: PickPlaceScript) -> None:
    s.grasp()
    s.move(s.g.ee() + [0, 0, DROP_LIFT], max_steps=50)
    s.gripper(GRIPPER_OPEN, 8)
    for _ in range(20):  # let it land
        s.act(np.array([0, 0, 0, 0, 0, 0, GRIPPER_OPEN]))


SCRIPTS: dict[str, Callable[..., None]] = {"push": push, "pull": pull, "tap": tap, "drop": drop}
SIDED = ("push", "tap")  # take the side's rank (`_side`) as a second argument


def low_target(spec: LiberoTaskSpec) -> bool:
    """Whether the task's target is low enough for the hand to pass over it (a bowl or a flat box)."""
    return any(k in spec.target for k in LOW_TARGETS)


def compatible(primitive: str, spec: LiberoTaskSpec) -> bool:
    """Whether `primitive` can act on the task's target."""
    if primitive not in SCRIPTS:
        raise KeyError(f"LIBERO has no primitive {primitive!r}; it uses {', '.join(SCRIPTS)}")
    return primitive in ("pull", "drop") or low_target(spec)


def branch_stream(platform: LiberoPlatform, spec: LiberoTaskSpec, seed: int, source: np.ndarray, branch: int,
                  primitive: str) -> np.ndarray | str:
    """The expert's stream up to step `branch` (replayed: identical to re-running its script), then
    `primitive`, closed-loop; a push or tap from its next side while the scene stops its withdrawal. Or why not:
    `primitive_out_of_time`, or the `Blocked` reason of the last side tried."""
    reason = ""
    for rank in range(len(DIRECTIONS) if primitive in SIDED else 1):
        s = PickPlaceScript(platform, spec, seed)
        for a in source[:branch]:
            s.act(a)
        try:
            if primitive in SIDED:
                SCRIPTS[primitive](s, rank)
            else:
                SCRIPTS[primitive](s)
        except OutOfTime:
            return "primitive_out_of_time"
        except Blocked as e:
            reason = e.reason
            continue
        return np.stack(s.actions)
    return reason
