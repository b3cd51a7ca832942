"""Learned policy sources for T3: behaviour-cloned MLPs from simulator state to the 8-D joint action.

For each T3 task a small MLP was trained (`scripts/train_policies.py`, CPU, fixed seeds) on replay-verified
scripted expert trajectories of training seeds (`ExpertSource`) plus noise-injected re-executions of them,
and two checkpoints were kept: an *early* one (10% of training) and the *late* (final) one; docs/guides/policies.md
has their measured success. `PolicySource(task, stage)` loads
`wsp_data/platforms/maniskill/checkpoints/<task>_<stage>.pt` and runs the policy closed-loop in its own state-only
`ManiSkillPlatform`; the returned stream is a plain `pd_joint_pos` stream that `ManiSkillPlatform.replay`
reproduces state for state (every episode starts from a rebuilt scene, and CPU PhysX is deterministic).

State features (`features`), all from the platform's `Observation` plus the episode's goal and the step:
  qpos (9) · TCP position (3) · TCP rotation as the first two columns of its matrix (6) · per task object:
  position (3), rotation 6-D (6), position relative to the TCP (3) · for tasks with a goal that the
  observation does not hold (PickCube's goal site, Push/PullCube's goal region): goal position (3) and goal
  relative to the first object (3) · phase = step / the expert's mean length (1).
Target: arm joint targets relative to the current arm qpos (7) and the gripper command (1); at run time the
arm part is added back to qpos and clipped to the joint limits, and the gripper is snapped to ±1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_data.platforms.bc_policy import BCPolicySource, rot6d

T3_TASKS = ("PickCube", "PushCube", "PullCube", "PlaceSphere", "LiftPegUpright")
CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"
TRAIN_SCRIPT = "scripts/train_policies.py"

# The goal the observation does not carry: task → env attribute holding a (static) goal actor.
GOAL_ATTR = {"PickCube": "goal_site", "PushCube": "goal_region", "PullCube": "goal_region"}


def checkpoint_path(task: str, stage: str, directory: Path | str | None = None) -> Path:
    return Path(directory or CHECKPOINT_DIR) / f"{task}_{stage}.pt"


# -- features ---------------------------------------------------------------------------------------
def num_objects(task: str) -> int:
    from wsp_data.platforms.maniskill.experts import task_spec

    return len(task_spec(task).objects)


def feature_names(task: str) -> list[str]:
    names = [f"qpos{i}" for i in range(9)] + ["tcp_x", "tcp_y", "tcp_z"] + [f"tcp_r{i}" for i in range(6)]
    for k in range(num_objects(task)):
        names += [f"obj{k}_{a}" for a in "xyz"] + [f"obj{k}_r{i}" for i in range(6)]
        names += [f"obj{k}_rel_tcp_{a}" for a in "xyz"]
    if task in GOAL_ATTR:
        names += [f"goal_{a}" for a in "xyz"] + [f"goal_rel_obj0_{a}" for a in "xyz"]
    return names + ["phase"]


def features(task: str, observation, step: int, goal: np.ndarray | None, ref_length: float) -> np.ndarray:
    """The policy input of one observation (see the module docstring); NaN-padded object slots are dropped."""
    tcp = np.asarray(observation.tcp_pose, dtype=np.float64)
    parts = [np.asarray(observation.qpos, dtype=np.float64)[:9], tcp[:3], rot6d(tcp[3:7])]
    poses = np.nan_to_num(np.asarray(observation.object_poses, dtype=np.float64))
    for k in range(num_objects(task)):
        p = poses[k]
        q = p[3:7] if np.any(p[3:7]) else np.array([1.0, 0, 0, 0])
        parts += [p[:3], rot6d(q), p[:3] - tcp[:3]]
    if task in GOAL_ATTR:
        if goal is None:
            raise ValueError(f"{task} policies need the episode's goal position")
        g = np.asarray(goal, dtype=np.float64).reshape(3)
        parts += [g, g - poses[0, :3]]
    parts.append(np.array([step / ref_length]))
    return np.concatenate(parts).astype(np.float32)


def action_target(observation, action: np.ndarray) -> np.ndarray:
    """The regression target of an expert action: arm targets relative to the arm qpos, gripper as is."""
    a = np.asarray(action, dtype=np.float64)
    return np.concatenate([a[:7] - np.asarray(observation.qpos, dtype=np.float64)[:7], a[7:8]]).astype(np.float32)


def read_goal(platform, task: str) -> np.ndarray | None:
    """The episode's goal position (world xyz) from the platform's env, for tasks whose goal the observation
    does not hold; None for the others."""
    attr = GOAL_ATTR.get(task)
    if attr is None:
        return None
    return getattr(platform.u, attr).pose.p[0].detach().cpu().numpy().astype(np.float32)


# -- the source ------------------------------------------------------------------------------------
class PolicySource(BCPolicySource):
    """One checkpoint (task × stage) of a behaviour-cloned policy, run closed-loop in a state-only ManiSkill env;
    actions are `pd_joint_pos` (8,): arm targets = qpos + the network's deltas, clipped to the joint limits,
    and the gripper snapped to ±1."""

    PLATFORM = "maniskill"
    TASKS = T3_TASKS
    TRAIN_SCRIPT = TRAIN_SCRIPT
    DOCS = "docs/guides/policies.md"
    checkpoint_path = staticmethod(checkpoint_path)

    def __init__(self, task: str, stage: str, checkpoint_dir: Path | str | None = None):
        super().__init__(task, stage, checkpoint_dir)
        self._limits = np.asarray(self.meta["arm_limits"], dtype=np.float64)  # (7, 2) rad
        self.goal: np.ndarray | None = None  # the goal of the current episode of the own platform

    def feature_names(self) -> list[str]:
        return feature_names(self.task)

    def open_platform(self):
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform
        from wsp_data.platforms.maniskill.experts import task_spec

        return ManiSkillPlatform(self.task, render=False, objects=task_spec(self.task).objects)

    def on_reset(self, observation) -> None:
        self.goal = read_goal(self.platform, self.task)

    def act(self, observation, step: int = 0, goal: np.ndarray | None = None) -> np.ndarray:
        """The deterministic (8,) float32 `pd_joint_pos` action for an observation at `step` of an episode.
        `goal` (PickCube, PushCube, PullCube) defaults to the goal of the own platform's current episode."""
        if goal is None and self.task in GOAL_ATTR:
            if self.goal is None:
                raise ValueError(f"{self.task} needs a goal: pass goal= or run trajectory() first")
            goal = self.goal
        y = self.network(features(self.task, observation, step, goal, self.ref_length))
        arm = np.asarray(observation.qpos, dtype=np.float64)[:7] + y[:7]
        arm = np.clip(arm, self._limits[:, 0], self._limits[:, 1])
        grip = 1.0 if y[7] >= 0 else -1.0
        return np.array([*arm, grip], dtype=np.float32)
