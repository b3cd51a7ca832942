"""The ALOHA kit: `PlatformKit` hooks for the bimanual ALOHA (two ViperX 300 arms) on plain MuJoCo, with
RoboTwin 2.0's action interface (native stream: 14-D absolute joint targets, 6 per arm + a normalised gripper
each). It stands in for RoboTwin's embodiment class (dual arm, head camera), whose assets no machine here can
download; it is not RoboTwin (docs/platforms/aloha.md).

Every hook imports its simulator modules on call, so importing this module (and registering the kit) imports
no simulator.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from wsp_data.platforms.interface import BLOCK_RAD, BLOCK_STEPS, PlatformKit, Rollout
from wsp_data.schema import FPS, PlatformInfo

_ARM = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate")
_POSE = ("x", "y", "z", "qw", "qx", "qy", "qz")
JOINT_DIMS = (0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12)  # the 12 arm joint targets of the native stream
GRIPPER_DIMS = (6, 13)  # left, right gripper (0 closed … 1 open)

INFO = PlatformInfo(
    "aloha", FPS, 320, 240, "head", "aloha_vx300s_bimanual",
    "absolute joint position targets, RoboTwin's layout: left arm 6 (rad), left gripper (0 closed ... 1 open), "
    "right arm 6 (rad), right gripper",
    tuple(f"l_{j}" for j in _ARM) + ("l_gripper",) + tuple(f"r_{j}" for j in _ARM) + ("r_gripper",),
    "action.ee", "per arm (left, then right): the gripper point's world position (m) and XYZ Euler angles (rad) "
    "that the joint targets reach (forward kinematics), and the gripper command",
    tuple(f"{s}_{c}" for s in "lr" for c in ("x", "y", "z", "rx", "ry", "rz", "gripper")),
    "MuJoCo 3.8.1 with the gym-aloha 0.1.5 scene assets (two ViperX 300 arms); a stand-in for RoboTwin 2.0's "
    "Aloha-AgileX embodiment class, not RoboTwin",
    state_names=tuple(f"{s}_{j}" for s in "lr" for j in _ARM) + ("l_finger", "r_finger"),
    ee_names=tuple(f"{s}_{c}" for s in "lr" for c in _POSE),
    state_text="robot joint positions (2 × 6 arm joints, rad + one finger slide per hand, m)",
)


class AlohaKit(PlatformKit):
    name = "aloha"
    info = INFO
    perturbed_dims = JOINT_DIMS  # any arm joint of either arm, never a gripper
    action_bounds = (np.array([-np.inf] * 6 + [0.0] + [-np.inf] * 6 + [0.0], np.float32),
                     np.array([np.inf] * 6 + [1.0] + [np.inf] * 6 + [1.0], np.float32))  # grippers in [0, 1]
    gripper_dim = GRIPPER_DIMS
    gripper_open = 1.0
    arm_joints = 12  # the state's and the joint stream's first 12 columns: left arm 6, right arm 6
    finger_dims = (12, 13)  # one finger slide per hand: 0.021 m closed … 0.057 m open
    finger_closed_below = 0.05  # m: a 4 cm cube stops the fingers at ≈ 0.0425 m
    default_counts = {"t1": 419, "t2": 1575, "t3": 1000, "t4": 640, "t5": 8 * 233}  # RoboTwin's (spec §3)

    # -- core ---------------------------------------------------------------------------------------------
    def tasks(self) -> dict:
        from wsp_data.platforms.aloha.env import TASKS

        return TASKS

    def make_expert(self, task: str):
        from wsp_data.platforms.aloha.experts import AlohaExpertSource

        return AlohaExpertSource(task)

    def make_renderer(self, task: str, objects: Sequence[str]):
        from wsp_data.platforms.aloha.env import AlohaPlatform

        return AlohaPlatform(task, render=True, objects=objects)

    def joint_stream(self, rollout: Rollout) -> np.ndarray:
        return np.asarray(rollout.actions)[:, JOINT_DIMS]  # left 6, right 6: the state's order

    def arm_motion(self, actions: np.ndarray) -> np.ndarray:
        return np.asarray(actions, dtype=np.float64)[:, JOINT_DIMS]  # rad

    def blocked(self, qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
        """Some arm joint lags its target by more than BLOCK_RAD for BLOCK_STEPS consecutive steps."""
        lag = np.abs(qpos[1:, :12] - np.asarray(actions)[:, JOINT_DIMS]).max(axis=1)
        return len(lag) >= BLOCK_STEPS and bool((sliding_window_view(lag, BLOCK_STEPS).min(axis=1) > BLOCK_RAD).any())

    # -- T3 -----------------------------------------------------------------------------------------------
    def t3_tasks(self) -> tuple[str, ...]:
        from wsp_data.platforms.aloha.t3 import T3_TASKS

        return T3_TASKS

    def t3_source(self, task: str, group: str, simulator=None):
        from wsp_data.platforms.aloha.t3 import AlohaOperatorSource, AlohaPolicySource

        if group.startswith("policy_"):
            return AlohaPolicySource(task, group.removeprefix("policy_"), simulator=simulator)
        return AlohaOperatorSource(task, group, simulator)

    def expert_script(self, task: str) -> str:
        from wsp_data.platforms.aloha.t3 import expert_script

        return expert_script(task)

    # -- T4 -----------------------------------------------------------------------------------------------
    def t4_kind_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        from wsp_data.platforms.aloha.t4 import kind_tasks

        return kind_tasks(tasks)

    def t4_needs(self, missing: Sequence[str]) -> str:
        from wsp_data.platforms.aloha.t4 import needs

        return needs(missing)

    def t4_rig(self, task: str):
        from wsp_data.platforms.aloha.t4 import AlohaTaskRig

        return AlohaTaskRig(task)

    # -- T5 -----------------------------------------------------------------------------------------------
    def t5_primitives(self) -> tuple[str, ...]:
        from wsp_data.platforms.contract import PRIMITIVES

        return PRIMITIVES  # all eight; knock-over on a prop (`t5_scene`)

    def t5_primitive_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        # every selected task but measured (primitive, task) misfits (`t5.EXCLUDED`): the peg and the bar are
        # too long to straddle for a pull, slip or swing in a one-hand shake, and the peg sinks on a drop
        from wsp_data.platforms.aloha.t5 import primitive_tasks

        return primitive_tasks(tasks)

    def t5_needs(self) -> str:
        from wsp_data.platforms.aloha.t5 import needs

        return needs()

    def t5_scene(self, primitive: str) -> Hashable:
        from wsp_data.platforms.aloha.primitives import PROP

        return PROP if primitive == "knock-over" else None  # a 3 × 3 × 10 cm block beside the target

    def t5_rig(self, task: str, scene: Hashable):
        from wsp_data.platforms.aloha.t5 import AlohaT5Rig

        return AlohaT5Rig(task, scene)

    # no t5_rule_thresholds: the paper's thresholds hold (tap: the jab slides a cube 0.053-0.097 m, measured)

    # -- tools ----------------------------------------------------------------------------------------------
    def render_check(self) -> np.ndarray:
        from wsp_data.platforms.aloha.env import AlohaPlatform

        p = AlohaPlatform(next(iter(self.tasks())), render=True)
        try:
            return p.reset(0).rgb
        finally:
            p.close()


KIT = AlohaKit()
