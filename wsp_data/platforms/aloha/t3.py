"""T3's action sources on ALOHA: scripted operator models H1–H5 and behaviour-cloned policy checkpoints.

Tasks (`T3_TASKS`): the right-to-left hand-over, the one-arm lift, the push, the cube into the bin and the stack:
a two-arm exchange, a grasp, a non-prehensile push and two place tasks, over one and two objects. Left out:
hand_over (transfer_cube mirrored), two_arm_lift (its bar is laid out in a 6 × 10 cm box: nearly one scene)
and peg_insertion (its expert is a servo loop on the peg's measured axis, not a sequence of moves a style can
stretch).

Every source answers the T3 source protocol, `stream(seed)` (`wsp_data.platforms.t3_sources`).

Operators (`AlohaOperatorSource`) are the task's expert script (`experts.SCRIPTS`) run with a documented style,
every parameter in the provenance, recorded as the same 14-D joint-target stream:
- H1 slow: every segment (move, hold, push) takes 2× its planned steps.
- H2 fast: every segment takes 0.55× its planned steps (at least 1).
- H3 jerky: i.i.d. Gaussian noise (σ = 6 mm, seeded by the scene seed) on each hand's commanded grip point,
  every step, before the inverse kinematics.
- H4 hesitant: every move of a hand's position planned over ≥ 8 steps stops at 60% of the way, idles 6 steps,
  backs off 2 cm upward (4 steps) and completes the move.
- H5 another approach path: every move of a hand's position planned over ≥ 14 steps follows a quadratic Bézier
  curve whose control point is 10 cm toward the camera (−y) and 10 cm above the straight path's midpoint (the
  path bows out by 5 cm each way) instead of the straight line.
Their step budget is 2.5× the expert's (`experts.MAX_STEPS`); an attempt that runs out of it stops there. Joint
targets are clipped to the joint limits. Failures are kept (the T3 builder records success).

Policies (`AlohaPolicySource`): an MLP (`bc_model.MLPPolicy`) from simulator state to the 14-D
joint-target action, trained by behaviour cloning on scripted-expert trajectories of training seeds plus
noise-injected re-runs labelled with the script's clean action (`scripts/train_bc_policies.py --platform aloha`);
an early (200 of 20,000 steps: measured, the 10% checkpoint already solves 17–20 of 20 held-out scenes of every
task) and a late (final) checkpoint per task in `wsp_data/platforms/aloha/checkpoints/`. Features: qpos (14:
both arms' 6 joints, both finger slides), per grip point position (3) and rotation 6-D (6), per task object
position (3), rotation 6-D (6) and position relative to each grip point (3 + 3), phase = step / the expert's mean
length (1). Output: the 12 arm joint targets relative to the current arm joints (added back, each step's change
bounded to ±`MAX_DELTA` rad and the result clipped to the joint limits) and both gripper commands (snapped to 0
closed or 1 open at 0.5).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from wsp_data.platforms.aloha import experts as ax
from wsp_data.platforms.aloha.env import AlohaPlatform, aloha_task
from wsp_data.platforms.aloha.experts import SCRIPTS, Hand, OutOfTime, Script
from wsp_data.platforms.bc_policy import BCPolicySource, rot6d
from wsp_data.platforms.t3_sources import OperatorAttempt, ScriptedOperatorSource, operator_style

T3_TASKS = ("transfer_cube", "lift_cube", "push_cube", "cube_in_bin", "stack_cubes")
OPERATOR_STEP_BUDGET = 2.5  # × the expert's MAX_STEPS
CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"
MAX_DELTA = 0.3  # rad: bound on a policy's arm target relative to the current joint positions
ARM_ACTION = (0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12)  # native dims of the 12 arm joints (qpos columns 0–11)
GRIP_ACTION = (6, 13)

OPERATORS: dict[str, dict] = {
    "H1": {"style": "slow", "time": 2.0},
    "H2": {"style": "fast", "time": 0.55},
    "H3": {"style": "jerky", "noise_m": 0.006},
    "H4": {"style": "hesitant", "stop_short": 0.6, "idle": 6, "back_off_m": 0.02, "back_off_steps": 4,
           "min_move_steps": 8},
    "H5": {"style": "another approach path", "bow_control_m": [0.0, -0.10, 0.10], "min_move_steps": 14},
}


def _smooth(f: float) -> float:
    return f * f * (3 - 2 * f)


class OperatorScript(Script):
    """The task's expert script with an operator's style (`OPERATORS`)."""

    def __init__(self, p: AlohaPlatform, seed: int, style: dict):
        super().__init__(p, seed)
        self.style = style
        self.max_steps = int(ax.MAX_STEPS * OPERATOR_STEP_BUDGET)
        self.rng = np.random.default_rng([seed, 7])
        self.qlimits = p.qlimits[:12]

    def duration(self, steps: int) -> int:
        return max(1, round(steps * self.style.get("time", 1.0)))

    def command(self, hands: list[Hand]) -> np.ndarray:
        if "noise_m" in self.style:
            hands = [replace(h, pos=h.pos + self.rng.normal(0.0, self.style["noise_m"], 3)) for h in hands]
        a = super().command(hands)
        a[list(ARM_ACTION)] = np.clip(a[list(ARM_ACTION)], self.qlimits[:, 0], self.qlimits[:, 1])
        return a

    def hold(self, steps: int) -> None:
        super().hold(self.duration(steps))

    def _goal(self, left: dict | None, right: dict | None) -> list[Hand]:
        return [replace(h, **{k: np.asarray(v, dtype=np.float64) if k == "pos" else float(v) for k, v in c.items()})
                if c else h for h, c in zip(self.hand, (left, right))]

    def _move(self, goal: list[Hand], steps: int, bow: np.ndarray | None = None) -> None:
        start = list(self.hand)
        for i in range(1, steps + 1):
            f = _smooth(i / steps)
            hands = []
            for a, b in zip(start, goal):
                h = ax.lerp(a, b, f)
                if bow is not None and not np.array_equal(a.pos, b.pos):  # quadratic Bézier through a bowed point
                    c = (a.pos + b.pos) / 2 + bow
                    h = replace(h, pos=(1 - f) ** 2 * a.pos + 2 * f * (1 - f) * c + f * f * b.pos)
                hands.append(h)
            self.hand = hands
            self.act()

    def go(self, steps: int, left: dict | None = None, right: dict | None = None) -> None:
        s = self.style
        goal = self._goal(left, right)
        moving = [not np.array_equal(a.pos, b.pos) for a, b in zip(self.hand, goal)]
        n = self.duration(steps)
        if any(moving) and steps >= s.get("min_move_steps", math.inf):
            if "stop_short" in s:  # stop short, idle, back off upward, complete the move
                k = max(1, round(n * s["stop_short"]))
                self._move([ax.lerp(a, b, s["stop_short"]) for a, b in zip(self.hand, goal)], k)
                super().hold(s["idle"])
                self._move([replace(h, pos=h.pos + [0, 0, s["back_off_m"]]) if m else h
                            for h, m in zip(self.hand, moving)], s["back_off_steps"])
                self._move(goal, max(1, n - k))
                return
            if "bow_control_m" in s:
                self._move(goal, n, np.asarray(s["bow_control_m"], dtype=np.float64))
                return
        self._move(goal, n)


class AlohaOperatorSource(ScriptedOperatorSource):
    """One scripted operator model (H1–H5) on one ALOHA task, on a state-only platform: `simulator` (the
    caller's, left open) or its own."""

    def __init__(self, task: str, operator: str, simulator: AlohaPlatform | None = None):
        style = operator_style(OPERATORS, operator)
        if task not in T3_TASKS:
            raise KeyError(f"no operator models for task {task!r}; T3 tasks: {', '.join(T3_TASKS)}")
        self.task, self.operator, self.style = task, operator, style
        self.spec = aloha_task(task)
        self._owns = simulator is None
        self.platform = AlohaPlatform(task, render=False, objects=self.spec.objects) if self._owns else simulator

    def attempt(self, seed: int) -> OperatorAttempt:
        """The operator's (T, 14) float32 stream from scene `seed` (cut at its step budget) and whether it ends
        in success."""
        s = OperatorScript(self.platform, seed, self.style)
        try:
            SCRIPTS[self.task](s)
            s.hold(ax.HOLD)
        except OutOfTime:
            pass
        return OperatorAttempt(np.stack(s.actions), bool(s.observation.success))

    @property
    def provenance(self) -> dict:
        return {"kind": "scripted_operator", "operator": self.operator, "platform": "aloha",
                "model": "wsp_data.platforms.aloha.t3.OperatorScript", "script": expert_script(self.task),
                "step_budget": int(ax.MAX_STEPS * OPERATOR_STEP_BUDGET), **self.style}

    def close(self) -> None:
        if self._owns:
            self.platform.close()


def expert_script(task: str) -> str:
    """The released name of `task`'s expert script."""
    return f"wsp_data.platforms.aloha.experts.SCRIPTS[{task!r}]"


# -- policies ---------------------------------------------------------------------------------------
def feature_names(task: str) -> list[str]:
    names = [f"q{i}" for i in range(14)]
    for s in "lr":
        names += [f"{s}_tcp_{k}" for k in ("x", "y", "z", *(f"r{i}" for i in range(6)))]
    for obj in aloha_task(task).objects:
        names += [f"{obj}_{k}" for k in ("x", "y", "z", *(f"r{i}" for i in range(6)))]
        names += [f"{obj}_{s}_d{a}" for s in "lr" for a in "xyz"]
    return names + ["phase"]


def features(observation, n_objects: int, step: int, ref_length: float) -> np.ndarray:
    tcp = np.asarray(observation.tcp_pose, dtype=np.float64)
    parts = [np.asarray(observation.qpos, dtype=np.float64)]
    for k in (0, 1):
        parts += [tcp[7 * k:7 * k + 3], rot6d(tcp[7 * k + 3:7 * k + 7])]
    for j in range(n_objects):
        pose = np.asarray(observation.object_poses[j], dtype=np.float64)
        parts += [pose[:3], rot6d(pose[3:]), pose[:3] - tcp[0:3], pose[:3] - tcp[7:10]]
    parts.append([step / ref_length])
    return np.concatenate(parts).astype(np.float32)


def action_target(observation, action: np.ndarray) -> np.ndarray:
    """The regression target of an action: the 12 arm targets relative to the arm joints, then both grippers."""
    a = np.asarray(action, dtype=np.float64)
    q = np.asarray(observation.qpos, dtype=np.float64)[:12]
    return np.concatenate([a[list(ARM_ACTION)] - q, a[list(GRIP_ACTION)]]).astype(np.float32)


def checkpoint_path(task: str, stage: str, directory: Path | str | None = None) -> Path:
    return Path(directory or CHECKPOINT_DIR) / f"{task}_{stage}.pt"


class AlohaPolicySource(BCPolicySource):
    """One behaviour-cloned checkpoint (task × stage), run closed-loop in a state-only ALOHA platform; actions
    are the 14-D joint targets: qpos + the network's deltas (each at most `MAX_DELTA`), clipped to the joint
    limits, and both grippers snapped to open/closed."""

    PLATFORM = "aloha"
    TASKS = T3_TASKS
    checkpoint_path = staticmethod(checkpoint_path)

    def __init__(self, task: str, stage: str, checkpoint_dir: Path | str | None = None,
                 simulator: AlohaPlatform | None = None):
        super().__init__(task, stage, checkpoint_dir, simulator)
        self.spec = aloha_task(task)

    def feature_names(self) -> list[str]:
        return feature_names(self.task)

    def open_platform(self) -> AlohaPlatform:
        return AlohaPlatform(self.task, render=False, objects=self.spec.objects)

    def act(self, observation, step: int) -> np.ndarray:
        """The deterministic (14,) float32 joint-target action for an observation at `step` of an episode."""
        y = self.network(features(observation, len(self.spec.objects), step, self.ref_length))
        lim = self.platform.qlimits[:12]
        q = np.asarray(observation.qpos, dtype=np.float64)[:12]
        arm = np.clip(q + np.clip(y[:12], -MAX_DELTA, MAX_DELTA), lim[:, 0], lim[:, 1])
        a = np.zeros(14)
        a[list(ARM_ACTION)] = arm
        a[list(GRIP_ACTION)] = (y[12:14] >= 0.5).astype(np.float64)
        return a.astype(np.float32)
