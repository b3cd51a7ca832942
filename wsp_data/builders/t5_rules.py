"""T5 acceptance rules (spec §3.5): did the scripted primitive happen? Pure numpy on stored states.

Every rule reads only the evaluated object's pose sequence (T, 7: xyz + quaternion wxyz, as stored in
`sim.object_poses`), its robot–object contact flags (T,) (`sim.contacts`) and the robot base's
world xy (instance column `robot_base_xy`), so builders, tests and evaluators re-check a reference from the
release alone. `measure` computes the quantities, `passes` applies one primitive's rule to them. The primitives'
names (`PRIMITIVES`), the motion onset and quaternion rotations are shared with the platforms' scripts
(`wsp_data.platforms.contract`).

Thresholds: the paper's for push, drag, rotate, shake, knock-over and drop. ManiSkill has no articulated assets
offline, so pull and tap (paper: task success or articulation change ≥ 0.05) get object-displacement
definitions with the same 0.05 (here metres):
- pull: the object moves ≥ 0.05 m toward the robot base (xy displacement projected on the unit vector from
  its start to the base).
- tap: a brief strike the object answers on its own: it travels ≥ 0.05 m (xy) while the robot touches it on
  at most 6 frames (0.3 s), none of them more than 6 frames after the object starts moving (a push keeps
  contact while the object moves; a tap has withdrawn).
A platform may override a threshold for its scenes (`PlatformKit.t5_rule_thresholds`, keyword arguments of
`check` / `passes`): LIBERO (push, pull, tap, drop; spec §3.5) has no rolling prop, its tap strikes the task's own low
target (a bowl or a flat box), which slides and stops on its own, so its tap needs xy ≥ `tap_min_xy` = 0.015 m
(push's threshold) under the same brief-contact conditions (measured: 0.026–0.047 m with 1–3 contact frames).
LIBERO's tap script checks one more thing itself, from the hand's pose: that its withdrawal lifted the hand
(`primitives.MIN_RISE`, as does its push; where the scene stops it, the same scene is tried from another side).
Two identity conditions keep a primitive's label apart from its neighbours: rotate is in place (xy
displacement ≤ 0.03 m, else it is a push that turned the object), and shake reverses direction at least 4
times (two of its three cycles seen in the object, else it is a drag).
"""

from __future__ import annotations

import numpy as np

from wsp_data.platforms.contract import MOTION_ONSET, PRIMITIVES
from wsp_eval.object_track import rotation_matrices

PUSH_MIN_XY = 0.015  # m
PULL_MIN_TOWARD_BASE = 0.05  # m
DRAG_MIN_XY = 0.025  # m
PLANAR_MAX_Z_RANGE = 0.04  # m (drag, shake)
ROTATE_MIN_YAW = 0.10  # rad
ROTATE_MAX_XY = 0.03  # m: in place
SHAKE_MIN_HORIZONTAL = 0.03  # m
SHAKE_MIN_YAW_RANGE = 0.08  # rad
SHAKE_MIN_REVERSALS = 4
SHAKE_REVERSAL_XY = 0.01  # m a reversal must retreat from the last extreme
SHAKE_REVERSAL_YAW = 0.03  # rad
TAP_MIN_XY = 0.05  # m
TAP_MAX_CONTACT_STEPS = 6  # frames (0.3 s at 20 Hz)
KNOCK_MIN_TILT = 0.50  # rad
KNOCK_MIN_TILT_INCREASE = 0.35  # rad
DROP_MIN_LIFT = 0.04  # m
DROP_MIN_FALL = 0.04  # m


def yaw_track(quat_wxyz: np.ndarray) -> np.ndarray:
    """Unwrapped rotation about the world vertical relative to frame 0 (rad), per frame."""
    r = rotation_matrices(quat_wxyz)
    rel = r @ r[0].T
    return np.unwrap(np.arctan2(rel[:, 1, 0], rel[:, 0, 0]))


def tilt(quat_wxyz: np.ndarray) -> np.ndarray:
    """Angle between the object's local z axis and the world vertical (rad), per frame."""
    return np.arccos(np.clip(rotation_matrices(quat_wxyz)[:, 2, 2], -1.0, 1.0))


def reversals(signal: np.ndarray, hysteresis: float) -> int:
    """Direction reversals of a 1-D signal: times it retreats by ≥ `hysteresis` from its last extreme
    (the first move away from the start is not a reversal)."""
    direction, count = 0, 0
    hi = lo = float(signal[0])
    for v in map(float, signal[1:]):
        hi, lo = (max(hi, v) if direction >= 0 else hi), (min(lo, v) if direction <= 0 else lo)
        if direction >= 0 and v <= hi - hysteresis:
            count += direction == 1
            direction, lo = -1, v
        elif direction <= 0 and v >= lo + hysteresis:
            count += direction == -1
            direction, hi = 1, v
    return count


def _principal_axis_track(xy: np.ndarray) -> np.ndarray:
    """Horizontal positions projected on their principal direction (the shake axis)."""
    centred = xy - xy.mean(axis=0)
    if not np.any(centred):
        return np.zeros(len(xy))
    return centred @ np.linalg.svd(centred, full_matrices=False)[2][0]


def measure(poses: np.ndarray, contacts: np.ndarray, base_xy) -> dict[str, float]:
    """Every quantity the rules use. poses (T, 7) of the evaluated object, contacts (T,) bool, base_xy (2,)."""
    poses = np.asarray(poses, dtype=np.float64)
    contacts = np.asarray(contacts, dtype=bool).reshape(-1)
    if poses.ndim != 2 or poses.shape[1] != 7 or len(poses) < 2 or len(contacts) != len(poses):
        raise ValueError(f"expected poses (T≥2, 7) and contacts (T,), got {poses.shape} and {contacts.shape}")
    if not np.isfinite(poses).all():
        raise ValueError("pose sequence has NaN/inf (is this the evaluated object's column?)")
    xy, z = poses[:, :2], poses[:, 2]
    offset = np.linalg.norm(xy - xy[0], axis=1)
    to_base = np.asarray(base_xy, dtype=np.float64) - xy[0]
    to_base /= max(np.linalg.norm(to_base), 1e-9)
    yaw, tilts = yaw_track(poses[:, 3:]), tilt(poses[:, 3:])
    peak = int(np.argmax(z))
    moved = np.nonzero(offset >= MOTION_ONSET)[0]
    touched = np.nonzero(contacts)[0]
    onset = int(moved[0]) if len(moved) else len(poses)
    return {
        "xy_displacement": float(offset[-1]),
        "horizontal_excursion": float(offset.max()),
        "toward_base": float((xy[-1] - xy[0]) @ to_base),
        "yaw_change": float(abs(yaw[-1])),
        "yaw_range": float(yaw.max() - yaw.min()),
        "z_range": float(z.max() - z.min()),
        "lift": float(z[peak] - z[0]),
        "fall": float(z[peak] - z[peak:].min()),
        "tilt_final": float(tilts[-1]),
        "tilt_increase": float(tilts[-1] - tilts[0]),
        "reversals": max(reversals(_principal_axis_track(xy), SHAKE_REVERSAL_XY),
                         reversals(yaw, SHAKE_REVERSAL_YAW)),
        "contact_steps": int(len(touched)),
        "contact_after_onset": int(max(0, touched[-1] - onset)) if len(touched) else 0,
    }


def passes(primitive: str, m: dict[str, float], tap_min_xy: float = TAP_MIN_XY) -> bool:
    """The acceptance rule of `primitive` on quantities from `measure` (`tap_min_xy`: a platform's override of
    TAP_MIN_XY, m)."""
    if primitive == "push":
        return m["xy_displacement"] >= PUSH_MIN_XY
    if primitive == "pull":
        return m["toward_base"] >= PULL_MIN_TOWARD_BASE
    if primitive == "drag":
        return m["xy_displacement"] >= DRAG_MIN_XY and m["z_range"] <= PLANAR_MAX_Z_RANGE
    if primitive == "rotate":
        return m["yaw_change"] >= ROTATE_MIN_YAW and m["xy_displacement"] <= ROTATE_MAX_XY
    if primitive == "shake":
        moved = m["horizontal_excursion"] >= SHAKE_MIN_HORIZONTAL or m["yaw_range"] >= SHAKE_MIN_YAW_RANGE
        return moved and m["z_range"] <= PLANAR_MAX_Z_RANGE and m["reversals"] >= SHAKE_MIN_REVERSALS
    if primitive == "tap":
        return (m["xy_displacement"] >= tap_min_xy and m["contact_steps"] <= TAP_MAX_CONTACT_STEPS
                and m["contact_after_onset"] <= TAP_MAX_CONTACT_STEPS)
    if primitive == "knock-over":
        return m["tilt_final"] >= KNOCK_MIN_TILT and m["tilt_increase"] >= KNOCK_MIN_TILT_INCREASE
    if primitive == "drop":
        return m["lift"] >= DROP_MIN_LIFT and m["fall"] >= DROP_MIN_FALL
    raise KeyError(f"unknown primitive {primitive!r}; known: {', '.join(PRIMITIVES)}")


def check(primitive: str, poses: np.ndarray, contacts: np.ndarray, base_xy,
          tap_min_xy: float = TAP_MIN_XY) -> tuple[bool, dict[str, float]]:
    """Measure and apply `primitive`'s rule: (passed, quantities)."""
    m = measure(poses, contacts, base_xy)
    return passes(primitive, m, tap_min_xy), m
