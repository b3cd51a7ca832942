"""Scripted end-effector skills without mplib.

A `SkillScript` drives a state-only ManiSkill env under `pd_ee_pose` (its IK runs on the CPU) and records,
after every step, the arm controller's IK joint targets plus the gripper command: an 8-D `pd_joint_pos`
stream. Replaying that stream under `pd_joint_pos` reproduces the rollout (verified per trajectory by
`verify`). Skills are small composable motions in world coordinates: approach, grasp, lift, place, push…
"""

from __future__ import annotations

import math

import numpy as np
import sapien
import torch

from wsp_data.platforms.maniskill.env import (
    GRIPPER_CLOSED, GRIPPER_OPEN, ManiSkillPlatform, euler_xyz, to_numpy,
)

STEP_M = 0.012  # TCP translation per control step (0.24 m/s at 20 Hz)
STEP_RAD = 0.08  # TCP rotation per control step


def slerp(q0: np.ndarray, q1: np.ndarray, t: float) -> np.ndarray:
    """The unit quaternion (wxyz) a fraction `t` of the way from `q0` to `q1` along the shorter arc."""
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + t * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - t) * th) * q0 + math.sin(t * th) * q1) / math.sin(th)


def angle_between(q0: np.ndarray, q1: np.ndarray) -> float:
    """The rotation angle (rad) between two unit quaternions."""
    return 2 * math.acos(min(1.0, abs(float(np.dot(q0, q1)))))


class SkillScript:
    """End-effector scripting on one task; `actions` accumulates the recorded joint stream."""

    def __init__(self, task: str, objects: tuple[str, ...]):
        self.platform = ManiSkillPlatform(task, render=False, control_mode="pd_ee_pose", objects=objects)
        self.u = self.platform.u
        self.actions: list[np.ndarray] = []
        self.grip = GRIPPER_OPEN
        self._target: sapien.Pose | None = None

    def close(self) -> None:
        self.platform.close()

    def reset(self, seed: int) -> None:
        self.platform.reset(seed)
        self.actions, self.grip, self._target = [], GRIPPER_OPEN, self.tcp

    # -- scene queries ---------------------------------------------------------------------------
    @property
    def tcp(self) -> sapien.Pose:
        return self.u.agent.tcp.pose.sp

    def pose(self, actor: str) -> sapien.Pose:
        return self.platform.actor(actor).pose.sp

    def success(self) -> bool:
        return bool(to_numpy(self.u.evaluate()["success"]).reshape(-1)[0])

    # -- primitive step -------------------------------------------------------------------------
    def _command(self, target: sapien.Pose) -> None:
        rel = self.u.agent.robot.pose.sp.inv() * target
        cmd = np.array([*rel.p, *euler_xyz(rel.q), self.grip], dtype=np.float32)
        self.platform.env.step(torch.as_tensor(cmd)[None])
        q = to_numpy(self.u.agent.controller.controllers["arm"]._target_qpos[0])
        self.actions.append(np.array([*q, self.grip], dtype=np.float32))
        self._target = target

    # -- skills ---------------------------------------------------------------------------------
    def move(self, target: sapien.Pose, *, settle: int = 2, speed: float = 1.0) -> None:
        """Straight-line TCP motion (slerp for rotation) from the last commanded pose to `target`."""
        start = self._target
        n = max(3, math.ceil(max(np.linalg.norm(target.p - start.p) / (STEP_M * speed),
                                 angle_between(start.q, target.q) / (STEP_RAD * speed))))
        for i in range(1, n + 1):
            t = i / n
            self._command(sapien.Pose(start.p + t * (target.p - start.p), slerp(start.q, target.q, t)))
        self.hold(settle)

    def hold(self, steps: int) -> None:
        for _ in range(steps):
            self._command(self._target)

    def set_gripper(self, value: float, steps: int = 6) -> None:
        self.grip = float(value)
        self.hold(steps)

    def open_gripper(self, steps: int = 6) -> None:
        self.set_gripper(GRIPPER_OPEN, steps)

    def close_gripper(self, steps: int = 6) -> None:
        self.set_gripper(GRIPPER_CLOSED, steps)

    def approach(self, grasp: sapien.Pose, clearance: float = 0.06) -> None:
        """Move above a grasp pose (backed off along its approach axis), then straight down onto it."""
        self.move(grasp * sapien.Pose([0, 0, -clearance]))
        self.move(grasp, speed=0.6)

    def grasp(self, grasp: sapien.Pose, clearance: float = 0.06) -> None:
        self.approach(grasp, clearance)
        self.close_gripper()

    def lift(self, height: float) -> None:
        self.move(sapien.Pose([0, 0, height]) * self._target)

    def place(self, target: sapien.Pose, clearance: float = 0.06) -> None:
        """Carry the grasped object over `target` (a TCP pose), lower onto it, release and back off."""
        self.move(sapien.Pose([0, 0, clearance]) * target)
        self.move(target, speed=0.5)
        self.open_gripper()
        self.move(sapien.Pose([0, 0, clearance]) * target)

    def push(self, start: sapien.Pose, end: sapien.Pose, clearance: float = 0.06, speed: float = 0.6) -> None:
        """Closed-gripper planar push: come down beside the object at `start`, slide to `end`."""
        self.grip = GRIPPER_CLOSED
        self.move(sapien.Pose([0, 0, clearance]) * start)
        self.move(start, speed=0.6)
        self.move(end, speed=speed)

    def trajectory(self) -> np.ndarray:
        return np.stack(self.actions).astype(np.float32)


def verify(platform: ManiSkillPlatform, seed: int, actions: np.ndarray) -> bool:
    """Replay a recorded joint stream under `pd_joint_pos` and report task success at the end."""
    platform.reset(seed)
    ob = None
    for a in actions:
        ob = platform.step(a)
    return bool(ob is not None and ob.success)
