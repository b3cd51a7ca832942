"""The ManiSkill kit: `PlatformKit` hooks for ManiSkill 3 (native stream `pd_joint_pos` joint targets).

Every hook imports its simulator modules on call, so importing this module (and registering the kit) imports
no simulator.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np

from wsp_data.platforms.interface import ARM, PlatformError, PlatformKit, Rollout, joint_blocked
from wsp_data.schema import PLATFORM_INFO


class ManiSkillKit(PlatformKit):
    name = "maniskill"
    info = PLATFORM_INFO["maniskill"]
    perturbed_dims = 7  # the 7 arm joint targets (rad)
    action_bounds = None  # joint targets: the limit check reads them directly
    gripper_dim = 7
    gripper_open = 1.0
    default_counts = {"t1": 1000, "t2": 1500, "t3": 750, "t4": 1000, "t5": 2360}  # paper Table S3 (spec §3)

    # -- core ---------------------------------------------------------------------------------------------
    def tasks(self) -> dict:
        from wsp_data.platforms.maniskill.experts import TASKS

        return TASKS

    def make_expert(self, task: str):
        from wsp_data.platforms.maniskill.experts import ExpertSource

        return ExpertSource(task)

    def make_renderer(self, task: str, objects: Sequence[str]):
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform

        return ManiSkillPlatform(task, render=True, objects=objects)

    def joint_stream(self, rollout: Rollout) -> np.ndarray:
        return rollout.actions  # the native stream is the joint targets

    def arm_motion(self, actions: np.ndarray) -> np.ndarray:
        return np.asarray(actions, dtype=np.float64)[:, :ARM]  # the 7 joint targets, rad

    def blocked(self, qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
        return joint_blocked(qpos, tcp_pose, actions)

    # -- T3 -----------------------------------------------------------------------------------------------
    def t3_tasks(self) -> tuple[str, ...]:
        from wsp_data.platforms.maniskill.t3 import T3_TASKS

        return T3_TASKS

    def t3_source(self, task: str, group: str, simulator=None):
        if group.startswith("policy_"):
            from wsp_data.platforms.maniskill.t3 import PolicySource

            return PolicySource(task, group.removeprefix("policy_"), simulator=simulator)
        from wsp_data.platforms.maniskill.t3 import OperatorSource

        return OperatorSource(task, group, simulator)

    def expert_script(self, task: str) -> str:
        return f"experts.{task}"

    # -- T4 -----------------------------------------------------------------------------------------------
    def t4_kind_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        from wsp_data.platforms.contract import KINDS
        from wsp_data.platforms.maniskill.t4 import KIND_TASKS

        return {k: tuple(t for t in tasks if t in KIND_TASKS[k]) for k in KINDS}

    def t4_needs(self, missing: Sequence[str]) -> str:
        from wsp_data.platforms.maniskill.t4 import KIND_TASKS

        return "; ".join(f"{k}: {', '.join(KIND_TASKS[k])}" for k in missing)

    def t4_rig(self, task: str):
        from wsp_data.platforms.maniskill.t4 import TaskRig

        return TaskRig(task)

    # -- T5 -----------------------------------------------------------------------------------------------
    def t5_primitives(self) -> tuple[str, ...]:
        from wsp_data.platforms.contract import PRIMITIVES

        return PRIMITIVES  # all eight

    def t5_primitive_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        from wsp_data.platforms.maniskill.t5 import PRIMITIVE_TASKS

        return {p: tuple(t for t in PRIMITIVE_TASKS[p] if t in tasks) for p in self.t5_primitives()}

    def t5_needs(self) -> str:
        from wsp_data.platforms.maniskill.t5 import PRIMITIVE_TASKS

        return "one of its tasks among the selected ones; tasks per primitive: " + "; ".join(
            f"{p}: {', '.join(PRIMITIVE_TASKS[p])}" for p in self.t5_primitives())

    def t5_scene(self, primitive: str) -> Hashable:
        from wsp_data.platforms.maniskill.primitives import PROPS

        return PROPS.get(primitive)  # knock-over and tap: a prop beside the target

    def t5_rig(self, task: str, scene: Hashable):
        from wsp_data.platforms.maniskill.t5 import Rig

        return Rig(task, scene)

    # -- tools ----------------------------------------------------------------------------------------------
    def render_check(self) -> np.ndarray:
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform
        from wsp_data.platforms.maniskill.runtime import LAVAPIPE_ICD, configure_cpu_rendering

        configure_cpu_rendering()
        if not LAVAPIPE_ICD.exists():
            raise PlatformError(f"{LAVAPIPE_ICD} missing; install mesa-vulkan-drivers 25 (scripts/setup.sh)")
        with ManiSkillPlatform("PickCube") as p:
            return p.reset(seed=0).rgb


KIT = ManiSkillKit()
