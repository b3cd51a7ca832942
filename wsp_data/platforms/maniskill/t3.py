"""T3's action sources on ManiSkill (spec §3.3): scripted operator models H1–H5 and behaviour-cloned policy
checkpoints.

Operators. A release must be buildable with nobody at the keyboard, so the five T3 "operators" are scripted
models that imitate the expert: each runs the task's own expert solver (`experts.TASKS[task].solve`), but on an
`OperatorScript`, a `SkillScript` whose motions carry a style. The strategy (what to grasp, where to put it)
is the expert's; the execution (speed, settling, smoothness, pauses, corrections, approach path) is the
operator's. Every style is a frozen `OperatorStyle`, so provenance records each parameter.

- H1 slow and careful: half speed, twice the settling plus two steps, a look before every descent, a slow
  gripper.
- H2 fast: 1.6× speed, half the settling, a quick gripper.
- H3 jerky: seeded random offsets (σ 6 mm, clipped to 2σ; half that while the gripper is closed, since a
  full 6 mm made the held peg of LiftPegUpright slip in 9 of 10 seeds) on every intermediate TCP target and
  uneven step sizes (each step 0.25×–1.75× the mean), so the hand trembles and surges along each path; the
  end point of every motion is exact.
- H4 hesitant, at 0.9× speed: pauses before half of its motions and stops in the middle of a third of
  them; misses the first approach of every grasp and push (comes down 2.5 cm off, halfway, stops, backs
  up, comes down again), overshoots long carries by 3 cm and comes back, and re-grasps once (closes,
  opens, closes; grasping tasks only).
- H5 different strategy: twice the clearance, an angled pre-grasp 6 cm to the side (toward the robot) with
  the hand turned 0.6 rad, a slanted descent that turns into the grasp, arcs raised 5 cm over every long
  carry and a 4 cm higher lift.

Randomness (H3 jitter and step sizes, H4's pauses and miss directions) comes from a generator seeded by
(task, operator, scene seed): the same triple always gives the same stream.

`OperatorSource(task, operator).attempt(seed)` scripts a seed, replays the recorded 8-D `pd_joint_pos`
stream in a fresh `pd_joint_pos` env and returns the stream and whether the replay ended in task success
(an `OperatorAttempt`): T3 keeps failures too (`stream(seed)`, the T3 source protocol of
`wsp_data.platforms.t3_sources`), so the caller decides. `trajectory(seed)` is the `ExpertSource`-compatible
form (the stream only when it succeeds, else None).

    python -m wsp_data.platforms.maniskill.t3 --seeds 10 [--tasks …] [--operators …]

measures success and the style measures of `stream_metrics` per task × operator (and the expert, whose
neutral `EXPERT_STYLE` reproduces `ExpertSource`'s stream bit for bit) as Markdown tables.

Policies. For each T3 task a small MLP was trained (`scripts/train_bc_policies.py --platform maniskill`, CPU,
fixed seeds) on replay-verified scripted expert trajectories of training seeds (`ExpertSource`) plus
noise-injected re-executions of them, and two checkpoints were kept: an *early* one (10% of training) and the
*late* (final) one; docs/guides/policies.md has their measured success. `PolicySource(task, stage)` loads
`wsp_data/platforms/maniskill/checkpoints/<task>_<stage>.pt` and runs the policy closed-loop in its own
state-only `ManiSkillPlatform`; the returned stream is a plain `pd_joint_pos` stream that
`ManiSkillPlatform.replay` reproduces state for state (every episode starts from a rebuilt scene, and CPU
PhysX is deterministic).

State features (`features`), all from the platform's `Observation` plus the episode's goal and the step:
  qpos (9) · TCP position (3) · TCP rotation as the first two columns of its matrix (6) · per task object:
  position (3), rotation 6-D (6), position relative to the TCP (3) · for tasks with a goal that the
  observation does not hold (PickCube's goal site, Push/PullCube's goal region): goal position (3) and goal
  relative to the first object (3) · phase = step / the expert's mean length (1).
Target: arm joint targets relative to the current arm qpos (7) and the gripper command (1); at run time the
arm part is added back to qpos and clipped to the joint limits, and the gripper is snapped to ±1.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import sapien

from wsp_data.platforms.bc_policy import BCPolicySource, rot6d
from wsp_data.platforms.maniskill.env import GRIPPER_CLOSED, ManiSkillPlatform
from wsp_data.platforms.maniskill.experts import task_spec
from wsp_data.platforms.maniskill.skills import STEP_M, STEP_RAD, SkillScript, angle_between, slerp
from wsp_data.platforms.t3_sources import OperatorAttempt, ScriptedOperatorSource, operator_style

T3_TASKS = ("PickCube", "PushCube", "PullCube", "PlaceSphere", "LiftPegUpright")
CONTROL_HZ = 20  # ManiSkill's control frequency for these tasks
LONG_MOVE_M = 0.08  # horizontal travel from which a motion counts as a carry (H4 overshoot, H5 arc)
CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"

# The goal the observation does not carry: task → env attribute holding a (static) goal actor.
GOAL_ATTR = {"PickCube": "goal_site", "PushCube": "goal_region", "PullCube": "goal_region"}


@dataclass(frozen=True)
class OperatorStyle:
    """How an operator executes the expert's plan. Neutral values (the defaults) reproduce the expert."""

    name: str
    description: str
    speed: float = 1.0  # × every motion's speed (the skills' 1.2 cm / 0.08 rad per step at speed 1)
    settle_scale: float = 1.0  # × every hold / settle the expert asks for (rounded) ...
    settle_extra: int = 0  # ... plus this many steps (only where the expert holds at all)
    gripper_steps: int | None = None  # steps to open / close the gripper (None: the expert's 6)
    pre_grasp_pause: int = 0  # steps of stillness above a grasp or push start before coming down
    jitter_m: float = 0.0  # σ of the random offset on each intermediate TCP target (clipped to 2σ) ...
    closed_jitter_scale: float = 1.0  # ... × this while the gripper is closed (holding or pushing)
    speed_unevenness: float = 0.0  # step sizes drawn from (1 ± this) × the mean, then rescaled to the path
    hesitation_steps: int = 0  # length of one pause
    pause_prob: float = 0.0  # chance that a motion starts with a pause
    mid_pause_prob: float = 0.0  # chance that a motion stops for a pause somewhere in its middle
    re_approaches: int = 0  # missed approaches (come down off target, stop, back up) before the real one
    miss_m: float = 0.0  # horizontal miss of such an approach
    overshoot_m: float = 0.0  # long carries overshoot by this much and come back
    regrasp: bool = False  # the first grasp is closed, opened and closed again
    clearance_scale: float = 1.0  # × the expert's clearance above a grasp, push start or place target
    approach_offset: float = 0.0  # m the pre-grasp / pre-push pose is set to the side (slanted descent)
    approach_yaw: float = 0.0  # rad the hand is turned about the vertical at that pose
    detour_m: float = 0.0  # long carries arc this much above the straight line (through a raised midpoint)
    lift_extra: float = 0.0  # m added to every lift

    @property
    def parameters(self) -> dict:
        return asdict(self)


EXPERT_STYLE = OperatorStyle("expert", "the expert's own execution (neutral parameters)")

OPERATORS: dict[str, OperatorStyle] = {s.name: s for s in (
    OperatorStyle(
        "H1", "slow and careful: half speed, double settling (+2 steps), looks before each descent, slow gripper",
        speed=0.5, settle_scale=2.0, settle_extra=2, gripper_steps=10, pre_grasp_pause=6),
    OperatorStyle(
        "H2", "fast: 1.6x speed, half the settling, quick gripper",
        speed=1.6, settle_scale=0.5, gripper_steps=5),
    OperatorStyle(
        "H3", "jerky: seeded 6 mm jitter on every intermediate TCP target (3 mm with the gripper closed), "
              "uneven step sizes (0.25x-1.75x)",
        jitter_m=0.006, closed_jitter_scale=0.5, speed_unevenness=0.75),
    OperatorStyle(
        "H4", "hesitant (0.9x speed): pauses, stops mid-motion, misses the first approach and re-approaches, "
              "overshoots carries and corrects back, re-grasps once",
        speed=0.9, hesitation_steps=6, pause_prob=0.5, mid_pause_prob=0.3, pre_grasp_pause=4,
        re_approaches=1, miss_m=0.025, overshoot_m=0.03, regrasp=True),
    OperatorStyle(
        "H5", "different approach: double clearance, angled pre-grasp 6 cm to the side with the hand turned "
              "0.6 rad, slanted descent, carries arced 5 cm higher, higher lift",
        clearance_scale=2.0, approach_offset=0.06, approach_yaw=0.6, detour_m=0.05, lift_extra=0.04),
)}


def _yaw_turn(q: np.ndarray, yaw: float) -> np.ndarray:
    """Quaternion `q` turned by `yaw` about the world vertical."""
    r = sapien.Pose(q=[math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)])
    return (r * sapien.Pose(q=q)).q


def _horizontal(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64) * [1, 1, 0]
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else np.zeros(3)


class OperatorScript(SkillScript):
    """A `SkillScript` that executes every skill in an `OperatorStyle`; expert solvers run on it unchanged."""

    def __init__(self, task: str, objects: tuple[str, ...], style: OperatorStyle):
        super().__init__(task, objects)
        self.task, self.style = task, style
        self.rng = np.random.default_rng(0)
        self._stroke = False  # inside a push stroke: no overshoot, no arc
        self._grasps = 0

    def reset(self, seed: int) -> None:
        super().reset(seed)
        self.rng = np.random.default_rng([zlib.crc32(self.task.encode()), zlib.crc32(self.style.name.encode()),
                                          int(seed)])
        self._stroke, self._grasps = False, 0

    # -- timing -----------------------------------------------------------------------------------
    def _raw_hold(self, steps: int) -> None:
        SkillScript.hold(self, steps)

    def hold(self, steps: int) -> None:
        """A hold the expert asked for, scaled by the style's settling."""
        if steps > 0:
            self._raw_hold(max(0, round(steps * self.style.settle_scale)) + self.style.settle_extra)

    def _maybe_pause(self, prob: float) -> None:
        if self.style.hesitation_steps and prob > 0 and self.rng.random() < prob:
            self._raw_hold(self.style.hesitation_steps)

    def set_gripper(self, value: float, steps: int = 6) -> None:
        steps = self.style.gripper_steps if self.style.gripper_steps is not None else steps
        self.grip = float(value)
        self._raw_hold(steps)
        if self.style.regrasp and value == GRIPPER_CLOSED and self._grasps == 0:
            self._grasps += 1  # not satisfied with the first grasp: open, wait, close again
            self.grip = -GRIPPER_CLOSED
            self._raw_hold(steps)
            self._maybe_pause(1.0)
            self.grip = float(value)
            self._raw_hold(steps)

    # -- motion -------------------------------------------------------------------------------------
    def _path(self, target: sapien.Pose, speed: float) -> None:
        """One straight TCP path (slerp for rotation) to `target`, in the style's speed, step sizes and jitter."""
        st, start = self.style, self._target
        v = speed * st.speed
        n = max(3, math.ceil(max(np.linalg.norm(target.p - start.p) / (STEP_M * v),
                                 angle_between(start.q, target.q) / (STEP_RAD * v))))
        if st.speed_unevenness > 0:
            w = 1.0 + st.speed_unevenness * self.rng.uniform(-1.0, 1.0, n)
            ts = np.cumsum(w) / w.sum()
        else:
            ts = np.arange(1, n + 1) / n
        jitter = st.jitter_m * (st.closed_jitter_scale if self.grip == GRIPPER_CLOSED else 1.0)
        pause_at = -1
        if st.hesitation_steps and n >= 6 and st.mid_pause_prob > 0 and self.rng.random() < st.mid_pause_prob:
            pause_at = int(self.rng.integers(n // 3, 2 * n // 3 + 1))
        for i, t in enumerate(ts, 1):
            t = 1.0 if i == n else float(t)
            p = start.p + t * (target.p - start.p)
            if i < n and jitter > 0:
                p = p + np.clip(self.rng.normal(0.0, jitter, 3), -2 * jitter, 2 * jitter)
            self._command(sapien.Pose(p, slerp(start.q, target.q, t)))
            if i == pause_at:
                self._raw_hold(st.hesitation_steps)

    def move(self, target: sapien.Pose, *, settle: int = 2, speed: float = 1.0) -> None:
        st, start = self.style, self._target
        self._maybe_pause(st.pause_prob)
        d = (target.p - start.p) * [1, 1, 0]
        carry = not self._stroke and float(np.linalg.norm(d)) > LONG_MOVE_M
        if carry and st.detour_m > 0:  # arc over the straight line through a raised midpoint
            mid = sapien.Pose((start.p + target.p) / 2 + [0, 0, st.detour_m], slerp(start.q, target.q, 0.5))
            self._path(mid, speed)
        if carry and st.overshoot_m > 0:  # overshoot, stop, come back
            self._path(sapien.Pose(target.p + st.overshoot_m * _horizontal(d), target.q), speed)
            self._raw_hold(max(2, st.hesitation_steps // 2))
            self._path(target, 0.5 * speed)
        else:
            self._path(target, speed)
        self.hold(settle)

    def _descend(self, pre: sapien.Pose, goal: sapien.Pose, side: np.ndarray, speed: float) -> None:
        """From `pre` (already reached) down onto `goal`: pause, missed tries, then the real descent."""
        st = self.style
        if st.pre_grasp_pause:
            self._raw_hold(st.pre_grasp_pause)
        for _ in range(st.re_approaches):
            sign = 1.0 if self.rng.random() < 0.5 else -1.0
            miss = sapien.Pose(pre.p + 0.5 * (goal.p - pre.p) + sign * st.miss_m * side, goal.q)
            self.move(miss, speed=speed)
            self._raw_hold(max(2, st.hesitation_steps))
            self.move(pre, speed=speed)
        self.move(goal, speed=speed)

    def _pre_pose(self, goal: sapien.Pose, up: float, side: np.ndarray) -> sapien.Pose:
        """The pose `up` above `goal` (straight above, or, for H5, set aside along `side` and turned)."""
        st = self.style
        p = goal.p + [0, 0, up] + st.approach_offset * side
        return sapien.Pose(p, _yaw_turn(goal.q, st.approach_yaw) if st.approach_yaw else goal.q)

    def approach(self, grasp: sapien.Pose, clearance: float = 0.06) -> None:
        c = clearance * self.style.clearance_scale
        # side steps (H5's slanted approach, H4's misses) go along the grasp's local x, perpendicular to the
        # fingers' closing axis (local y), so the open fingers never come down on the object; toward the base
        side = _horizontal(grasp.to_transformation_matrix()[:3, 0])
        if side @ (self.u.agent.robot.pose.sp.p - grasp.p) < 0:
            side = -side
        if self.style.approach_offset == 0 and self.style.approach_yaw == 0:
            pre = grasp * sapien.Pose([0, 0, -c])  # the expert's: backed off along the approach axis
        else:
            pre = self._pre_pose(grasp, c, side)
        self.move(pre)
        self._descend(pre, grasp, side, speed=0.6)

    def lift(self, height: float) -> None:
        super().lift(height + self.style.lift_extra)

    def place(self, target: sapien.Pose, clearance: float = 0.06) -> None:
        c = clearance * self.style.clearance_scale
        above = sapien.Pose([0, 0, c]) * target
        self.move(above)
        if self.style.pre_grasp_pause:
            self._raw_hold(self.style.pre_grasp_pause)
        self.move(target, speed=0.5)
        self.open_gripper()
        self.move(above)

    def push(self, start: sapien.Pose, end: sapien.Pose, clearance: float = 0.06, speed: float = 0.6) -> None:
        self.grip = GRIPPER_CLOSED
        c = clearance * self.style.clearance_scale
        # a slanted descent comes from behind the stroke (away from the object); misses fall across it
        back = -_horizontal(end.p - start.p)
        across = np.array([-back[1], back[0], 0.0])
        pre = self._pre_pose(start, c, back)
        self.move(pre)
        if self.style.pre_grasp_pause:
            self._raw_hold(self.style.pre_grasp_pause)
        for _ in range(self.style.re_approaches):
            sign = 1.0 if self.rng.random() < 0.5 else -1.0
            self.move(sapien.Pose(pre.p + 0.5 * (start.p - pre.p) + sign * self.style.miss_m * across, start.q),
                      speed=0.6)
            self._raw_hold(max(2, self.style.hesitation_steps))
            self.move(pre, speed=0.6)
        self.move(start, speed=0.6)
        self._stroke = True
        try:
            self.move(end, speed=speed)
        finally:
            self._stroke = False


# -- the operator source -------------------------------------------------------------------------
class OperatorSource(ScriptedOperatorSource):
    """Scripted operator trajectories for one task, replayed and judged under `pd_joint_pos`."""

    def __init__(self, task: str, operator: str, simulator: ManiSkillPlatform | None = None):
        self.style = EXPERT_STYLE if operator == EXPERT_STYLE.name else operator_style(OPERATORS, operator)
        self.spec = task_spec(task)
        self.script = OperatorScript(self.spec.name, self.spec.objects, self.style)
        self._owns = simulator is None
        self.replayer = (ManiSkillPlatform(self.spec.name, render=False, objects=self.spec.objects) if self._owns
                         else simulator)

    def close(self) -> None:
        self.script.close()
        if self._owns:
            self.replayer.close()

    @property
    def provenance(self) -> dict:
        return {
            "kind": "scripted_operator", "operator": self.style.name, "task": self.spec.name,
            "imitates": f"expert solver {self.spec.solve.__name__}", "parameters": self.style.parameters,
            "randomness": "numpy default_rng([crc32(task), crc32(operator), scene seed])",
            "control_mode": "pd_joint_pos",
        }

    def attempt(self, seed: int) -> OperatorAttempt:
        """Script `seed`, replay the stream under `pd_joint_pos` and report it with its success, kept or not."""
        self.script.reset(seed)
        try:
            self.spec.solve(self.script)
        except Exception as e:  # noqa: BLE001 - an unsolvable seed (IK or geometry failure) is a failed run
            return OperatorAttempt(None, False, f"{type(e).__name__}: {e}")
        actions = self.script.trajectory()
        ob = self.replayer.reset(seed)
        for a in actions:
            ob = self.replayer.step(a)
        return OperatorAttempt(actions, bool(ob.success))

    def trajectory(self, seed: int) -> np.ndarray | None:
        """The (T, 8) stream when its replay succeeds, else None (`ExpertSource`'s contract)."""
        run = self.attempt(seed)
        return run.actions if run.success else None


# -- policies: checkpoints and state features -----------------------------------------------------
def checkpoint_path(task: str, stage: str, directory: Path | str | None = None) -> Path:
    return Path(directory or CHECKPOINT_DIR) / f"{task}_{stage}.pt"


def num_objects(task: str) -> int:
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


# -- the policy source ---------------------------------------------------------------------------
class PolicySource(BCPolicySource):
    """One checkpoint (task × stage) of a behaviour-cloned policy, run closed-loop in a state-only ManiSkill env;
    actions are `pd_joint_pos` (8,): arm targets = qpos + the network's deltas, clipped to the joint limits,
    and the gripper snapped to ±1."""

    PLATFORM = "maniskill"
    TASKS = T3_TASKS
    checkpoint_path = staticmethod(checkpoint_path)

    def __init__(self, task: str, stage: str, checkpoint_dir: Path | str | None = None,
                 simulator: ManiSkillPlatform | None = None):
        super().__init__(task, stage, checkpoint_dir, simulator)
        self._limits = np.asarray(self.meta["arm_limits"], dtype=np.float64)  # (7, 2) rad
        self.goal: np.ndarray | None = None  # the goal of the current episode of the own platform

    def feature_names(self) -> list[str]:
        return feature_names(self.task)

    def open_platform(self) -> ManiSkillPlatform:
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


# -- operator measurement ------------------------------------------------------------------------
def stream_metrics(actions: np.ndarray, platform: ManiSkillPlatform | None = None) -> dict:
    """Style measures of one (T, 8) stream, on the 7 arm joint targets:
    - `length`: steps;
    - `joint_speed`: mean over steps of the L2 norm of the first difference, × 20 Hz (rad/s);
    - `jerk`: mean absolute third difference (rad/step³);
    - `idle`: fraction of steps whose first difference is below 1e-3 rad (pauses, settling, gripper waits);
    and, given a platform for forward kinematics, the TCP target's path length `path_m` (m) and its peak
    height above the robot base `peak_z` (m)."""
    q = np.asarray(actions, dtype=np.float64)[:, :7]
    step = np.linalg.norm(np.diff(q, axis=0), axis=1)
    d3 = np.diff(q, n=3, axis=0)
    out = dict(length=len(q), joint_speed=float(step.mean() * CONTROL_HZ) if len(step) else 0.0,
               jerk=float(np.abs(d3).mean()) if len(d3) else 0.0,
               idle=float((step < 1e-3).mean()) if len(step) else 0.0)
    if platform is not None:
        xyz = np.stack([platform.ee_action(a)[:3] for a in np.asarray(actions)])
        out.update(path_m=float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum()), peak_z=float(xyz[:, 2].max()))
    return out


METRICS = ("length", "joint_speed", "jerk", "idle", "path_m", "peak_z")


def measure(tasks: Sequence[str], operators: Sequence[str], seeds: Sequence[int], progress: bool = True
            ) -> list[dict]:
    """One row per task × operator: successes, and the mean metrics over every scripted stream (failed
    replays included; a script that raised has no stream and counts as a failure)."""
    rows = []
    for task in tasks:
        for op in operators:
            src = OperatorSource(task, op)
            runs, t0 = [], time.perf_counter()
            try:
                for seed in seeds:
                    runs.append(src.attempt(seed))
                seconds = (time.perf_counter() - t0) / max(1, len(runs))
                streams = [stream_metrics(r.actions, src.replayer) for r in runs if r.actions is not None]
            finally:
                src.close()
            mean = {k: float(np.mean([m[k] for m in streams])) if streams else float("nan") for k in METRICS}
            rows.append(dict(task=task, operator=op, seeds=len(runs), successes=sum(r.success for r in runs),
                             scripted=len(streams), **mean,
                             seconds=seconds))
            if progress:
                r = rows[-1]
                print(f"{task} {op}: {r['successes']}/{r['seeds']} len {r['length']:.1f} "
                      f"speed {r['joint_speed']:.3f} jerk {r['jerk']:.2e} ({r['seconds']:.1f} s/run)",
                      file=sys.stderr, flush=True)
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| task | operator | success | length (steps) | joint speed (rad/s) | jerk (1e-4 rad/step³) | idle | "
             "TCP path (m) | peak TCP z (m) | s / run |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['task']} | {r['operator']} | {r['successes']}/{r['seeds']} | {r['length']:.1f} | "
                     f"{r['joint_speed']:.3f} | {1e4 * r['jerk']:.1f} | {r['idle']:.2f} | {r['path_m']:.2f} | "
                     f"{r['peak_z']:.2f} | {r['seconds']:.1f} |")
    return "\n".join(lines)


def summary(rows: list[dict]) -> str:
    """Per operator, over tasks: total successes and each measure as the mean ratio to the expert's (needs
    the expert's rows)."""
    expert = {r["task"]: r for r in rows if r["operator"] == EXPERT_STYLE.name}
    lines = ["| operator | success | length | joint speed | jerk | idle (abs.) | TCP path | peak TCP z |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for op in dict.fromkeys(r["operator"] for r in rows):
        rs = [r for r in rows if r["operator"] == op and r["task"] in expert]
        if not rs:
            continue
        ratio = {k: np.mean([r[k] / expert[r["task"]][k] for r in rs]) for k in METRICS}
        lines.append(f"| {op} | {sum(r['successes'] for r in rs)}/{sum(r['seeds'] for r in rs)} | "
                     f"{ratio['length']:.2f}x | {ratio['joint_speed']:.2f}x | {ratio['jerk']:.2f}x | "
                     f"{np.mean([r['idle'] for r in rs]):.2f} | {ratio['path_m']:.2f}x | {ratio['peak_z']:.2f}x |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 (training range)")
    ap.add_argument("--tasks", nargs="+", default=list(T3_TASKS))
    ap.add_argument("--operators", nargs="+", default=["expert", *OPERATORS])
    args = ap.parse_args(argv)
    rows = measure(args.tasks, args.operators, range(args.seeds))
    print(table(rows))
    if EXPERT_STYLE.name in args.operators:
        print()
        print(summary(rows))


if __name__ == "__main__":
    main()
