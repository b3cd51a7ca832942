"""The one interface every suite builder talks to: `PlatformKit`.

A platform (a simulator with its tasks, expert, action sources and scene edits) is a `PlatformKit` subclass
instance registered in `wsp_data.platforms.KITS` (built-in) or declared through the entry-point group
`worldsimprobe.platforms` (third party). Builders (`wsp_data.builders`) never name a platform: everything
simulator-specific they need comes through the hooks below, and the types the hooks hand out and take back
(rigs, proposals, drop reasons) are in `wsp_data.platforms.contract`, which builders and platforms both import.
docs/guides/adding-a-platform.md walks through them.

Hooks are grouped by the suites that call them:

- core (T1, T2, train, and every other suite): `tasks`, `make_expert`, `make_renderer`, `joint_stream`,
  `arm_motion`, `blocked` and the attributes `name`, `info`, `perturbed_dims`, `action_bounds`, `gripper_dim`,
  `gripper_open`, `arm_joints`, `finger_dims`, `finger_closed_below`;
- T3: `t3_tasks`, `t3_source`, `expert_script`;
- T4: `t4_kind_tasks`, `t4_needs`, `t4_rig`;
- T5: `t5_primitives`, `t5_primitive_tasks`, `t5_needs`, `t5_scene`, `t5_rig`, `t5_rule_thresholds`;
- support: `unsupported(suite)`, which a builder asks first and which, by default, reports the suites
  whose hooks the subclass does not implement;
- tools: `render_check`.

Every hook documents what it returns (Returns), the units (Units, where numbers are physical) and when a
builder calls it (Called). Hooks that create simulators are called once per task (or task and scene) per
build worker and their results are kept for the worker's life, or up to `rigs_per_worker` of them where a
platform's simulators are too large to keep one per task (`wsp_data.builders.rig.RigCache`); the rest are cheap
and may be called per attempt.

Determinism: a build is byte-identical for equal build configs. A hook must therefore depend only on its
arguments (and on the seeds it is given): no wall clock, no global random state, the same order of random
draws and environment resets for the same inputs.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Hashable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from wsp_data.schema import PlatformInfo

if TYPE_CHECKING:  # the contract imports this module: its types are named here for annotations only
    from wsp_data.platforms.contract import ExpertSource, Replayer, T4Rig, T5Rig, TaskSpec
    from wsp_data.platforms.t3_sources import T3Source

ARM = 7  # arm joints
BLOCK_RAD = 0.15  # rad an arm joint may lag its target …
BLOCK_STEPS = 10  # … (or the hand stall, on LIBERO) for this many consecutive steps (0.5 s) before the arm counts as blocked


def joint_blocked(qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
    """Joint-target streams: some arm joint lags its target by more than BLOCK_RAD for BLOCK_STEPS
    consecutive steps (held back by the table, a fixture or a pinned object). `qpos` (T+1, 9)."""
    lag = np.abs(qpos[1:, :ARM] - actions[:, :ARM]).max(axis=1)
    return len(lag) >= BLOCK_STEPS and bool((sliding_window_view(lag, BLOCK_STEPS).min(axis=1) > BLOCK_RAD).any())


@dataclass
class Observation:
    """What a platform records after a reset or a step."""

    qpos: np.ndarray  # (S,) float32, `info.state_names`: the arm joints first (Panda: 7 arm joints + 2 fingers)
    tcp_pose: np.ndarray  # (E,) float32, `info.ee_names`: end-effector (TCP / grip site) world position +
    #                       quaternion (wxyz), one after the other for each arm
    object_poses: np.ndarray  # (MAX_OBJECTS, 7) float32, NaN where the task has fewer objects
    contacts: np.ndarray  # (MAX_OBJECTS,) bool: any robot link touches the object
    success: bool
    rgb: np.ndarray | None = None  # (info.height, info.width, 3) uint8
    mask: np.ndarray | None = None  # (info.height, info.width) uint8 labels: 0 not robot, 1 arm, 2 wrist/hand/fingers
    objects: np.ndarray | None = None  # (info.height, info.width) uint8 labels: k + 1 where tracked object k is the
    #   visible surface, else 0 (exact simulator segmentation). The release stores it per frame beside `mask` (T5
    #   scores the object's motion on it); T4's builder checks with frame 0's that the evaluated object is what the
    #   camera sees at its projected centre.


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


class NotSupported(PlatformError):
    """A platform cannot serve a suite (or a primitive, a kind): the message is the platform's reason."""


def checked_stream(actions, dim: int) -> np.ndarray:
    """An action stream as float32 (T, dim), or PlatformError saying what is wrong with it."""
    actions = np.asarray(actions, dtype=np.float32)
    if actions.ndim != 2 or actions.shape[1] != dim or len(actions) == 0:
        raise PlatformError(f"expected a (T, {dim}) action stream, got shape {actions.shape}")
    if not np.isfinite(actions).all():
        raise PlatformError("action stream contains NaN or infinite values")
    return actions


# the suites whose hooks a subclass must override, and the hooks (`unsupported` checks them)
SUITE_HOOKS: dict[str, tuple[str, ...]] = {
    "t1": (), "t2": (), "train": (),
    "t3": ("t3_tasks", "t3_source", "expert_script"),
    "t4": ("t4_kind_tasks", "t4_rig"),
    "t5": ("t5_primitives", "t5_primitive_tasks", "t5_rig"),
}


class PlatformKit(ABC):
    """What suite builders need from a simulator platform, and what the release stores about it.

    Attributes (class attributes of a subclass):
        `name`: the platform's registry name (`wsp build --platform NAME`, config names `t1_NAME`).
        `info`: `PlatformInfo` (camera, robot, action streams, simulator) the writer stores in the release.
        `perturbed_dims`: T1 perturbs one of the native action dimensions `0 … perturbed_dims-1` (an int) or
            of those listed (a tuple), never a gripper (`t1_dims`).
        `action_bounds`: (low, high) range the controller accepts unclipped, or None (no bound); the common
            validity check drops a stream outside it. Units: native action units.
        `gripper_dim`, `gripper_open`: the gripper's index in the native action (a tuple: one per hand) and
            its fully open command (T4 false contact clamps every gripper open).
        `arm_joints`: the arm joints lead the state (`Observation.qpos`), the joint stream and the joint
            limits; the common validity check reads these columns.
        `finger_dims`, `finger_closed_below`: state columns of finger joints and the |position| below which a
            finger closed on something (m; T4 drops a false contact whose fingers closed).

    Objects the hooks return are the protocols of `wsp_data.platforms.contract` (docs/guides/adding-a-platform.md):
        `TaskSpec` (`tasks`), `ExpertSource` (`make_expert`), `Replayer` (`make_renderer`, an expert source's
        `replayer`), `T4Rig` (`t4_rig`), `T5Rig` (`t5_rig`); what the rigs hand back (`Proposal`, `Branch`,
        `Dropped`) and the helpers they share are in the same module.
    """

    name: ClassVar[str]
    info: ClassVar[PlatformInfo]
    perturbed_dims: ClassVar[int | tuple[int, ...]]
    action_bounds: ClassVar[tuple[float, float] | None] = None
    gripper_dim: ClassVar[int | tuple[int, ...]]
    gripper_open: ClassVar[float]
    arm_joints: ClassVar[int] = ARM
    finger_dims: ClassVar[tuple[int, ...]] = (7, 8)  # Panda's two finger joints …
    finger_closed_below: ClassVar[float] = 0.035  # … open to ±0.04 m
    default_counts: ClassVar[dict[str, int]] = {}  # `wsp build`'s --count when none is given, per suite (the
    #   paper's counts, spec §3); a suite without one defaults to 100 episodes per selected task
    rigs_per_worker: ClassVar[int | None] = None  # task rigs (simulators) a build worker keeps alive at once,
    #   least recently used closed first; None: every task's (`wsp_data.builders.rig.RigCache`)

    def t1_dims(self) -> tuple[int, ...]:
        """The native action dimensions T1 may perturb (`perturbed_dims` as a tuple)."""
        dims = self.perturbed_dims
        return tuple(range(dims)) if isinstance(dims, int) else tuple(dims)

    # -- support -----------------------------------------------------------------------------------------
    def unsupported(self, suite: str) -> str | None:
        """Why this platform cannot serve `suite`, or None when it can.

        Returns:
            None, or a one-line reason the builder puts in its refusal ("t4 cannot be built on NAME: REASON").
        Called:
            by `SuiteBuilder.__init__`, before anything is simulated. The default names the hooks of
            `SUITE_HOOKS[suite]` this subclass does not implement; override it to give a better reason.
        """
        missing = [h for h in SUITE_HOOKS.get(suite, ()) if getattr(type(self), h) is getattr(PlatformKit, h)]
        return f"the platform does not implement {', '.join(missing)}" if missing else None

    # -- core ---------------------------------------------------------------------------------------------
    @abstractmethod
    def tasks(self) -> dict[str, TaskSpec]:
        """The platform's benchmark tasks.

        Returns:
            {task name: task spec}, in a fixed order (the CLI's default task list).
        Called:
            by the CLI to check `--tasks`, and by builders that filter tasks.
        """

    @abstractmethod
    def make_expert(self, task: str) -> ExpertSource:
        """The verified scripted expert of `task`.

        Returns:
            an `ExpertSource`; its trajectories are native action streams (T, D) float32 that replay to task
            success on the unrendered replayer.
            Optionally `.scripted(seed)`: the stream before that verifying replay, for a builder whose next
            step is a rendered replay that checks success itself (train), which then skips the unrendered one.
        Called:
            once per task per build worker (T1, T2, T3, train; T4 and T5 rigs may call it too).
        """

    @abstractmethod
    def make_renderer(self, task: str, objects: Sequence[str]) -> Replayer:
        """A rendering replayer of `task` that records `objects` (pose and contact columns, in order).

        Returns:
            a `Replayer` whose `replay` fills `Observation.rgb` ((H, W, 3) uint8, `info.height` × `info.width`)
            `.mask` ((H, W) uint8: 0 not robot, 1 arm, 2 wrist/hand/fingers) and `.objects` ((H, W) uint8: k + 1
            where recorded object k is the visible surface, else 0) of every frame, and sets the rollout's camera
            `intrinsic` (3, 3) and `extrinsic` (3, 4, OpenCV world→camera, m).
        Called:
            once per task per build worker, after an unrendered replay passed validation.
        """

    def rig_simulators(self, task: str, expert: ExpertSource | None = None) -> tuple[ExpertSource, Replayer]:
        """A task rig's expert and rendering replayer (`wsp_data.platforms.contract.TaskRig`).

        Args:
            expert: the task's expert where the caller has one already (`make_expert(task)`, T2's donor); a
                platform that returns another closes it first, so that the two are never held at once.
        Returns:
            (`expert` or `make_expert(task)`, `make_renderer(task, its spec's objects)`) by default: two
            simulators. A platform whose rendering simulator steps as cheaply as a state-only one when it does
            not render overrides this to run a new expert, and the rig's unrendered replays, on the rendering
            simulator (LIBERO: one MuJoCo model per rig instead of two).
        Called:
            once per task rig (T1, T3, T4, T5, train; T2's receivers).
        """
        expert = expert or self.make_expert(task)
        return expert, self.make_renderer(task, expert.spec.objects)

    @abstractmethod
    def joint_stream(self, rollout: Rollout) -> np.ndarray:
        """The joint targets the common joint-limit check reads.

        Returns:
            (T, ≥arm_joints) float32: the native stream if it is joint targets, else the joint positions
            reached (the arm joints first, in the state's order).
        Units:
            rad (arm joints).
        Called:
            on every replay a builder validates (`wsp_data.platforms.contract.rollout_problem`).
        """

    @abstractmethod
    def arm_motion(self, actions: np.ndarray) -> np.ndarray:
        """The arm motion signal of a native stream, compared across tasks by T2's motion mismatch.

        Returns:
            (T, k) float64.
        Units:
            the platform's own (ManiSkill: rad of joint targets; LIBERO: m of commanded hand path); a config's
            mismatch values are compared only with each other.
        Called:
            by T2 for every expert trajectory that forms a task's typical stream and every donor stream.
        """

    @abstractmethod
    def blocked(self, qpos: np.ndarray, tcp_pose: np.ndarray, actions: np.ndarray) -> bool:
        """Whether the arm was held back by something it collided with.

        Args:
            qpos (T+1, S), tcp_pose (T+1, E) (m, quaternion wxyz), actions (T, D) native.
        Returns:
            True when the arm was blocked (T2 drops the donor replay as `arm_blocked`).
        Called:
            by T2 on every donor replay, unrendered and rendered.
        """

    # -- T3 -----------------------------------------------------------------------------------------------
    def t3_tasks(self) -> tuple[str, ...]:
        """The tasks that have T3 action sources (operator models and trained policies).

        Returns:
            task names; T3 keeps the selected tasks that are among them and refuses a config with none.
        Called:
            once, by `T3Builder.__init__`.
        """
        raise NotSupported(self.unsupported("t3"))

    def t3_source(self, task: str, group: str, simulator=None) -> T3Source:
        """The T3 action source of `group` on `task`.

        Args:
            group: "H1" … "H5" (scripted operator models, whose streams are kept whether they succeed or fail)
                or "policy_early" / "policy_late" (behaviour-cloning checkpoints).
            simulator: an unrendered simulator of `task` (the rig's, `TaskRig.state`: its expert's replayer)
                for the source to run on and leave open; None: the source opens its own. The T3
                builder hands every source of a task the same one, so a worker holds one state-only simulator
                per task, not one per source.
        Returns:
            a `wsp_data.platforms.t3_sources.T3Source`: `.stream(seed) -> SourceStream` (the actions, None when
            the source gives no stream, and the provenance: a JSON-able dict stored as `source_provenance`, whose
            "kind" is `scripted_operator` or `bc_policy`) and `.close()`.
        Called:
            once per (task, group) per build worker, on first use.
        """
        raise NotSupported(self.unsupported("t3"))

    def expert_script(self, task: str) -> str:
        """The name of `task`'s scripted expert, stored in the T3 expert row's provenance ("script").

        Called:
            by T3 for every expert stream.
        """
        raise NotSupported(self.unsupported("t3"))

    # -- T4 -----------------------------------------------------------------------------------------------
    def t4_kind_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        """Which of the selected `tasks` serve each T4 kind.

        Returns:
            {"distractor": …, "false_contact": …, "spatial_proximity": …}: task names in slot order; a kind
            with none makes T4 refuse the config with `t4_needs`.
        Called:
            once, by `T4Builder.__init__`.
        """
        raise NotSupported(self.unsupported("t4"))

    def t4_needs(self, missing: Sequence[str]) -> str:
        """What a task must be to serve the `missing` kinds (the end of T4's refusal message)."""
        return "a task that serves them"

    def t4_rig(self, task: str) -> T4Rig:
        """One task's T4 simulators and scene edits (see docs/guides/adding-a-platform.md, "T4").

        Returns:
            a `T4Rig`: `.kit`, `.spec`, `.expert`, `.state` / `.render` (unrendered / rendered replayers),
            `.invalid(rollout) -> str | None`, `.sight(seed) -> Sight`, `.replay(platform, seed, proposal) ->
            Rollout` and the three kinds' proposals `.distractor / .false_contact / .spatial_proximity(base,
            source, sight, rng) -> Proposal | str` (the drop reason). Placements are world poses (m, wxyz).
        Called:
            once per task per build worker; proposals once per attempt, drawing only from `rng`.
        """
        raise NotSupported(self.unsupported("t4"))

    # -- T5 -----------------------------------------------------------------------------------------------
    def t5_primitives(self) -> tuple[str, ...]:
        """The primitives (a subset of `wsp_data.platforms.contract.PRIMITIVES`) this platform scripts, in slot
        order; T5 balances slots over exactly these.

        Called:
            once, by `T5Builder.__init__`; and by `BuildConfig` when a build names `--primitives`, to check them.
        """
        raise NotSupported(self.unsupported("t5"))

    def t5_primitive_tasks(self, tasks: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
        """Which of the selected `tasks` serve each primitive of `t5_primitives()`, in slot order; a primitive
        with none makes T5 refuse the config with `t5_needs`.

        Called:
            once, by `T5Builder.__init__`.
        """
        raise NotSupported(self.unsupported("t5"))

    def t5_needs(self) -> str:
        """What a task must be to serve a primitive (the end of T5's refusal message)."""
        return "one of its tasks among the selected ones"

    def t5_scene(self, primitive: str) -> Hashable:
        """The scene addition `primitive` needs beside the task's own objects (ManiSkill: a prop), or None.
        T5 keeps one rig per (task, scene).

        Called:
            once per attempt, before `t5_rig`.
        """
        return None

    def t5_rig(self, task: str, scene: Hashable) -> T5Rig:
        """One task's T5 simulators (with the `scene` addition).

        Returns:
            a `T5Rig`: `.spec`, `.objects` (recorded object names), `.state` / `.render`, `.invalid(rollout)`,
            `.base_xy()` (robot base world xy, m, a list of 2 floats) and
            `.branch(primitive, seed) -> Branch | Dropped`: the verified source stream and the branched one,
            or why the attempt is dropped.
        Called:
            once per (task, scene) per build worker.
        """
        raise NotSupported(self.unsupported("t5"))

    def t5_rule_thresholds(self) -> dict[str, float]:
        """Overrides of T5's acceptance thresholds for this platform's scenes, as keyword arguments of
        `wsp_data.builders.t5_rules.check` (e.g. {"tap_min_xy": 0.015}). Units: m. Default: none."""
        return {}

    # -- tools ----------------------------------------------------------------------------------------------
    def render_check(self) -> np.ndarray:
        """Render one frame of the platform's first task on this machine (`python -m
        wsp_data.platforms.render_check`). Returns (info.height, info.width, 3) uint8; raises on a renderer
        failure."""
        raise NotSupported(f"{self.name} has no render check")
