"""Simulator platforms, found by name in `KITS`; this is the one place that registers the built-in ones, and
other distributions add theirs as `PlatformKit` objects through the entry-point group `worldsimprobe.platforms`
(`wsp_eval.registry`). Simulators are imported only inside this package and the source modules, and only when
a platform is first used, so building on one platform never imports the other's simulator.

A `PlatformKit` is what suite builders need from a platform: its benchmark tasks, a verified expert source
per task, a rendering replayer, the joint stream the common validity checks read, and the action bounds
its controller accepts; and what the release stores about it (`info`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from wsp_data.schema import PLATFORM_INFO, PlatformInfo
from wsp_eval.registry import Registry

ARM = 7  # arm joints
BLOCK_RAD = 0.15  # rad an arm joint may lag its target …
BLOCK_STEPS = 10  # … (or the hand stall, on LIBERO) for this many consecutive steps (0.5 s) before the arm counts as blocked
OSC_POS_SCALE = 0.05  # m per unit of LIBERO's OSC position action
OSC_COMMANDED = 0.01  # m per step: an OSC command at least this large …
OSC_STALLED = 0.05  # … achieving less than this fraction of it is a stalled hand (free motion: 0.09–0.36, 5th pct 0.16;
#                     pressed into the table: 0.00–0.03; measured on a libero_object expert rollout)


def joint_blocked(qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
    """Joint-target streams: some arm joint lags its target by more than BLOCK_RAD for BLOCK_STEPS
    consecutive steps (held back by the table, a fixture or a pinned object). `qpos` (T+1, 9)."""
    lag = np.abs(qpos[1:, :ARM] - actions[:, :ARM]).max(axis=1)
    return len(lag) >= BLOCK_STEPS and bool((sliding_window_view(lag, BLOCK_STEPS).min(axis=1) > BLOCK_RAD).any())


def osc_blocked(qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
    """OSC delta streams: for BLOCK_STEPS consecutive steps the hand is commanded to move at least
    OSC_COMMANDED and moves less than OSC_STALLED of it. `tcp_pose` (T+1, 7)."""
    commanded = np.linalg.norm(actions[:, :3] * OSC_POS_SCALE, axis=1)
    achieved = np.linalg.norm(np.diff(tcp_pose[:, :3], axis=0), axis=1)
    stalled = (commanded >= OSC_COMMANDED) & (achieved < OSC_STALLED * commanded)
    return len(stalled) >= BLOCK_STEPS and bool(sliding_window_view(stalled, BLOCK_STEPS).all(axis=1).any())


@dataclass
class Observation:
    """What a platform records after a reset or a step."""

    qpos: np.ndarray  # (9,) float32: 7 arm joints + 2 finger joints
    tcp_pose: np.ndarray  # (7,) float32: end-effector (TCP / grip site) world position + quaternion (wxyz)
    object_poses: np.ndarray  # (MAX_OBJECTS, 7) float32, NaN where the task has fewer objects
    contacts: np.ndarray  # (MAX_OBJECTS,) bool: any robot link touches the object
    success: bool
    rgb: np.ndarray | None = None  # (128, 128, 3) uint8
    mask: np.ndarray | None = None  # (128, 128) uint8 labels: 0 not robot, 1 arm, 2 wrist/hand/fingers


@dataclass
class Rollout:
    """A replayed stream: T native actions, the other stream beside them (ManiSkill: end-effector, column
    `action.ee`; LIBERO: joint, column `action.joint`) and the T+1 observations around them (frame 0 = after
    reset)."""

    task: str
    seed: int
    actions: np.ndarray  # (T, D) float32 native stream as executed
    alt_actions: np.ndarray  # (T, D') float32 the other stream
    observations: list[Observation] = field(default_factory=list)
    intrinsic: np.ndarray | None = None  # (3, 3) OpenCV intrinsics
    extrinsic: np.ndarray | None = None  # (3, 4) OpenCV world→camera

    @property
    def success(self) -> bool:
        return bool(self.observations[-1].success)

    def stack(self, name: str) -> np.ndarray:
        return np.stack([getattr(o, name) for o in self.observations])


class PlatformError(RuntimeError):
    """A task or stream a platform cannot run."""


def checked_stream(actions, dim: int) -> np.ndarray:
    """An action stream as float32 (T, dim), or PlatformError saying what is wrong with it."""
    actions = np.asarray(actions, dtype=np.float32)
    if actions.ndim != 2 or actions.shape[1] != dim or len(actions) == 0:
        raise PlatformError(f"expected a (T, {dim}) action stream, got shape {actions.shape}")
    if not np.isfinite(actions).all():
        raise PlatformError("action stream contains NaN or infinite values")
    return actions


@dataclass(frozen=True)
class PlatformKit:
    name: str
    perturbed_dims: int  # T1: native action dimensions that move the arm (the gripper is never perturbed)
    load_tasks: Callable[[], dict]  # benchmark task name → task spec (`.instruction`, `.objects`)
    make_expert: Callable[[str], object]  # task → source with `.trajectory(seed)`, `.replayer`, `.spec`, `.close()`
    make_renderer: Callable[[str, tuple[str, ...]], object]  # (task, objects) → rendering platform
    joint_stream: Callable[[object], np.ndarray]  # rollout → (T, ≥7) joint targets the limit check reads
    action_bounds: tuple[float, float] | None  # native action range the controller accepts unclipped
    arm_motion: Callable[[np.ndarray], np.ndarray]  # native stream (T, D) → arm motion signal (T, k) (T2 mismatch)
    blocked: Callable[[np.ndarray, np.ndarray, np.ndarray], bool]  # (qpos, tcp_pose, native stream) → arm held back
    gripper_dim: int  # the gripper's index in the native action
    gripper_open: float  # its fully open command
    info: PlatformInfo  # camera, action streams, simulator: what the release stores about the platform

    def tasks(self) -> dict:
        return self.load_tasks()


def _maniskill_tasks() -> dict:
    from wsp_data.platforms.maniskill.experts import TASKS

    return TASKS


def _maniskill_expert(task: str):
    from wsp_data.platforms.maniskill.experts import ExpertSource

    return ExpertSource(task)


def _maniskill_renderer(task: str, objects: tuple[str, ...]):
    from wsp_data.platforms.maniskill.env import ManiSkillPlatform

    return ManiSkillPlatform(task, render=True, objects=objects)


def _libero_tasks() -> dict:
    from wsp_data.platforms.libero.experts import TASKS

    return TASKS


def _libero_expert(task: str):
    from wsp_data.platforms.libero.experts import LiberoExpertSource

    return LiberoExpertSource(task)


def _libero_renderer(task: str, objects: tuple[str, ...]):
    from wsp_data.platforms.libero.env import LiberoPlatform

    return LiberoPlatform(task, render=True, objects=objects)


KITS: Registry[PlatformKit] = Registry("platform", "worldsimprobe.platforms")
KITS.register("maniskill", PlatformKit(
    "maniskill", 7, _maniskill_tasks, _maniskill_expert, _maniskill_renderer,
    joint_stream=lambda ro: ro.actions, action_bounds=None,
    arm_motion=lambda a: np.asarray(a, dtype=np.float64)[:, :ARM], blocked=joint_blocked,
    gripper_dim=7, gripper_open=1.0, info=PLATFORM_INFO["maniskill"]))
# LIBERO's native stream is OSC deltas; the joint stream beside it holds the joint positions reached
KITS.register("libero", PlatformKit(
    "libero", 6, _libero_tasks, _libero_expert, _libero_renderer,
    joint_stream=lambda ro: ro.alt_actions, action_bounds=(-1.0, 1.0),
    # the hand's commanded path (m): cumulative OSC position deltas
    arm_motion=lambda a: np.cumsum(np.asarray(a, dtype=np.float64)[:, :3] * OSC_POS_SCALE, axis=0),
    blocked=osc_blocked, gripper_dim=6, gripper_open=-1.0, info=PLATFORM_INFO["libero"]))


def kit(platform: str) -> PlatformKit:
    """The kit of `platform` (built-in or from an entry point); KeyError naming the known platforms."""
    return KITS[platform]
