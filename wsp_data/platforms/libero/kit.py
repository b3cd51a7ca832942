"""The LIBERO kit: `PlatformKit` hooks for LIBERO (native stream: robosuite OSC_POSE deltas in [-1, 1]; the
joint positions reached are stored beside it).

Every hook imports its simulator modules on call, so importing this module (and registering the kit) imports
no simulator.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from wsp_data.platforms.interface import BLOCK_STEPS, PlatformKit, Rollout
from wsp_data.schema import PLATFORM_INFO

OSC_POS_SCALE = 0.05  # m per unit of LIBERO's OSC position action
OSC_COMMANDED = 0.01  # m per step: an OSC command at least this large …
OSC_STALLED = 0.05  # … achieving less than this fraction of it is a stalled hand (free motion: 0.09–0.36, 5th pct 0.16;
#                     pressed into the table: 0.00–0.03; measured on a libero_object expert rollout)
TAP_MIN_XY = 0.015  # m: T5's tap on LIBERO strikes the task's own low target (`t5_rules`), push's threshold


def osc_blocked(qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
    """OSC delta streams: for BLOCK_STEPS consecutive steps the hand is commanded to move at least
    OSC_COMMANDED and moves less than OSC_STALLED of it. `tcp_pose` (T+1, 7)."""
    commanded = np.linalg.norm(actions[:, :3] * OSC_POS_SCALE, axis=1)
    achieved = np.linalg.norm(np.diff(tcp_pose[:, :3], axis=0), axis=1)
    stalled = (commanded >= OSC_COMMANDED) & (achieved < OSC_STALLED * commanded)
    return len(stalled) >= BLOCK_STEPS and bool(sliding_window_view(stalled, BLOCK_STEPS).all(axis=1).any())


class LiberoKit(PlatformKit):
    name = "libero"
    info = PLATFORM_INFO["libero"]
    perturbed_dims = 6  # OSC position (x0.05 m) and rotation (x0.5 rad) deltas
    action_bounds = (-1.0, 1.0)  # OSC commands beyond are clipped by the controller
    gripper_dim = 6
    gripper_open = -1.0
    default_counts = {"t1": 1000, "t2": 1500, "t3": 1000, "t4": 1000, "t5": 2000}  # paper Table S3 (spec §3)
    rigs_per_worker = 1  # a LIBERO rig (one model: `rig_simulators`) holds ≈ 0.8 GB beside ≈ 1.15 GB that the
    #   first env leaves behind, and takes 2–5 s to create against 20–80 s per slot; a build orders its slots by
    #   task (`wsp_data.build.by_simulator`), so one rig per worker is rarely re-created

    # -- core ---------------------------------------------------------------------------------------------
    def tasks(self) -> dict:
        from wsp_data.platforms.libero.experts import TASKS

        return TASKS

    def make_expert(self, task: str):
        from wsp_data.platforms.libero.experts import LiberoExpertSource

        return LiberoExpertSource(task)

    def make_renderer(self, task: str, objects: Sequence[str]):
        from wsp_data.platforms.libero.env import LiberoPlatform

        return LiberoPlatform(task, render=True, objects=objects)

    def rig_simulators(self, task: str, expert=None):
        # a rig's expert and unrendered replays run on its rendering env with rendering off (the same model: a
        # state-only env would hold a second copy, ≈ 0.55 GB); every replay resets, so sharing changes no rollout
        from wsp_data.platforms.libero.env import LiberoPlatform
        from wsp_data.platforms.libero.experts import LiberoExpertSource, task_spec

        if expert is not None:  # replaced: closed before the new env is made
            expert.close()
        render = LiberoPlatform(task, render=True, objects=task_spec(task).objects)
        return LiberoExpertSource(task, render.unrendered()), render

    def joint_stream(self, rollout: Rollout) -> np.ndarray:
        return rollout.alt_actions  # the native stream is OSC deltas; beside it: the joint positions reached

    def arm_motion(self, actions: np.ndarray) -> np.ndarray:
        # the hand's commanded path (m): cumulative OSC position deltas
        return np.cumsum(np.asarray(actions, dtype=np.float64)[:, :3] * OSC_POS_SCALE, axis=0)

    def blocked(self, qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
        return osc_blocked(qpos, tcp_pose, actions)

    # -- T3 -----------------------------------------------------------------------------------------------
    def t3_tasks(self) -> tuple[str, ...]:
        from wsp_data.platforms.libero.t3 import T3_TASKS

        return T3_TASKS

    def t3_source(self, task: str, group: str, simulator=None):
        from wsp_data.platforms.libero.t3 import LiberoOperatorSource, LiberoPolicySource

        if group.startswith("policy_"):
            return LiberoPolicySource(task, group.removeprefix("policy_"), simulator=simulator)
        return LiberoOperatorSource(task, group, simulator)

    def expert_script(self, task: str) -> str:
        return "libero_experts.PickPlaceScript"  # the released provenance string (the module's former name)

    # -- T4 -----------------------------------------------------------------------------------------------
    def t4_kind_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        # every LIBERO task grasps its target and has scene objects to spare; but open fingers brush a tall
        # target that nearly fills them (measured: the alphabet soup can, 8 of 8 false-contact proposals
        # touched it), so false contact takes the tasks with a low target, as T5's push and tap do
        from wsp_data.platforms.libero.experts import task_spec
        from wsp_data.platforms.libero.primitives import low_target

        tasks = tuple(dict.fromkeys(tasks))
        low = tuple(t for t in tasks if low_target(task_spec(t)))
        return {"distractor": tasks, "false_contact": low, "spatial_proximity": tasks}

    def t4_needs(self, missing: Sequence[str]) -> str:
        return "a task whose target is a bowl or a flat box"

    def t4_rig(self, task: str):
        from wsp_data.platforms.libero.t4 import LiberoTaskRig

        return LiberoTaskRig(task)

    # -- T5 -----------------------------------------------------------------------------------------------
    def t5_primitives(self) -> tuple[str, ...]:
        return ("push", "pull", "tap", "drop")  # no props: a BDDL scene cannot gain a body

    def t5_primitive_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        from wsp_data.platforms.libero.experts import task_spec
        from wsp_data.platforms.libero.primitives import compatible

        return {p: tuple(t for t in tasks if compatible(p, task_spec(t))) for p in self.t5_primitives()}

    def t5_needs(self) -> str:
        return "a task whose target is a bowl or a flat box (push, tap) among the selected ones"

    def t5_rig(self, task: str, scene: Hashable):
        from wsp_data.platforms.libero.t5 import LiberoRig

        return LiberoRig(task)

    def t5_rule_thresholds(self) -> dict[str, float]:
        return {"tap_min_xy": TAP_MIN_XY}

    # -- tools ----------------------------------------------------------------------------------------------
    def render_check(self) -> np.ndarray:
        from wsp_data.platforms.libero.env import LiberoPlatform
        from wsp_data.platforms.libero.experts import TASKS

        with LiberoPlatform(next(iter(TASKS))) as p:
            return p.reset(seed=0).rgb


KIT = LiberoKit()
