"""Common reference validity (spec §5), checked from simulator state only.

`check_rollout` returns None for a valid rollout or the name of the first failed check, which becomes a
drop reason in the build report. Thresholds:
- `nonfinite_state`: any NaN/inf in robot state, TCP pose or task-object poses.
- `joint_limit`: an arm joint target outside the robot's limits, or a joint position beyond them by more
  than 0.01 rad (the controller would clip or fight the limit).
- `instability`: a task object moving faster than 3 m/s between frames, leaving the workspace
  (|x|, |y| > 1.5 m) or sinking below the table (z < −0.05 m); a robot joint faster than 10 rad/s.
- `incomplete`: fewer frames than actions + 1.
- `action_limit`: a native action outside the range its controller accepts unclipped (LIBERO's OSC: [−1, 1]).
"""

from __future__ import annotations

import numpy as np

from wsp_data.schema import FPS

MAX_OBJECT_SPEED = 3.0  # m/s
MAX_JOINT_SPEED = 10.0  # rad/s
WORKSPACE_XY = 1.5  # m
MIN_OBJECT_Z = -0.05  # m
JOINT_LIMIT_TOL = 0.01  # rad


def check_rollout(qpos: np.ndarray, tcp_pose: np.ndarray, object_poses: np.ndarray, actions: np.ndarray,
                  qlimits: np.ndarray, native: np.ndarray | None = None,
                  bounds: tuple[float, float] | None = None, arm: int = 7) -> str | None:
    """qpos (T+1, S) with the `arm` arm joints first (Panda: 7 arm joints + 2 fingers), tcp_pose (T+1, ≥7),
    object_poses (T+1, K, 7) NaN-padded, actions (T, ≥arm) joint targets (on LIBERO: the joint positions
    reached), qlimits (S, 2) lower/upper; `native` (T, D) with `bounds`: the native stream and the range its
    controller accepts."""
    if len(qpos) != len(actions) + 1:
        return "incomplete"
    if native is not None and bounds is not None and ((native < bounds[0]).any() or (native > bounds[1]).any()):
        return "action_limit"
    used = ~np.isnan(object_poses[0, :, 0])
    objs = object_poses[:, used]
    if not (np.isfinite(qpos).all() and np.isfinite(tcp_pose).all() and np.isfinite(objs).all()):
        return "nonfinite_state"
    lo, hi = qlimits[:arm, 0], qlimits[:arm, 1]
    if (actions[:, :arm] < lo).any() or (actions[:, :arm] > hi).any():
        return "joint_limit"
    if (qpos < qlimits[:, 0] - JOINT_LIMIT_TOL).any() or (qpos > qlimits[:, 1] + JOINT_LIMIT_TOL).any():
        return "joint_limit"
    if len(qpos) > 1 and (np.abs(np.diff(qpos[:, :arm], axis=0)) * FPS > MAX_JOINT_SPEED).any():
        return "instability"
    if objs.size:
        pos = objs[..., :3]
        if len(pos) > 1 and (np.linalg.norm(np.diff(pos, axis=0), axis=-1) * FPS > MAX_OBJECT_SPEED).any():
            return "instability"
        if (np.abs(pos[..., :2]) > WORKSPACE_XY).any() or (pos[..., 2] < MIN_OBJECT_Z).any():
            return "instability"
    return None
