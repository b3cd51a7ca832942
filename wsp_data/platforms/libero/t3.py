"""T3's action sources on LIBERO: scripted operator models H1–H5 and behaviour-cloned policy checkpoints.

Every source answers the T3 source protocol, `stream(seed)` (`wsp_data.platforms.t3_sources`).

Operators (`LiberoOperatorSource`) are the expert's pick-and-place script (`PickPlaceScript`) run with a
documented style, every parameter in the provenance:
- H1 slow: servo gain ×0.35 and arm actions bounded to ±0.35 (the expert: ±0.9), gripper held 1.5× longer.
- H2 fast: gain ×1.8, looser waypoint tolerance (1.6×), gripper held 0.6× as long.
- H3 jerky: i.i.d. Gaussian noise (σ = 0.15 OSC units, seeded by the scene seed) on the arm dimensions.
- H4 hesitant: at every waypoint it stops short (60% of the way), idles 8 steps, backs off 2 cm and re-approaches.
- H5 another approach path: cruises 10 cm higher and comes down onto the grasp from 6 cm beside it.
Failures are kept (the T3 builder records success).

Policies (`LiberoPolicySource`): an MLP (`bc_model.MLPPolicy`) from simulator state to the 7-D OSC action,
trained by behaviour cloning on scripted-expert trajectories of training seeds
(`scripts/train_bc_policies.py --platform libero`); an early (10%) and a late (final) checkpoint per task in
`wsp_data/platforms/libero/checkpoints/`. Features: qpos (9), grip-site position (3) and rotation 6-D (6), per task
object position (3), rotation 6-D (6) and position relative to the grip site (3), phase = step / the expert's
mean length (1). Output: the 6 arm dimensions (bounded to ±0.9) and the gripper (snapped to ±1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_data.platforms.bc_policy import BCPolicySource, rot6d
from wsp_data.platforms.libero.env import GRIPPER_CLOSED, GRIPPER_OPEN, LiberoPlatform
from wsp_data.platforms.libero import experts as lx
from wsp_data.platforms.libero.experts import PickPlaceScript, task_spec
from wsp_data.platforms.t3_sources import OperatorAttempt, ScriptedOperatorSource, operator_style

T3_TASKS = (
    "libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket",
    "libero_object/pick_up_the_butter_and_place_it_in_the_basket",
    "libero_spatial/pick_up_the_black_bowl_from_table_center_and_place_it_on_the_plate",
    "libero_goal/put_the_bowl_on_the_stove",
    "libero_90/KITCHEN_SCENE1_put_the_black_bowl_on_the_plate",
)
OPERATOR_STEP_BUDGET = 2.5  # × the expert's step budget (H1 takes about twice the expert's time)
OPERATOR_SUCCESS_WAIT = 20  # steps an operator waits for the goal after its place move; then it has failed
CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"

OPERATORS: dict[str, dict] = {
    "H1": {"style": "slow", "gain": 0.35, "max_action": 0.35, "grip_steps": 1.5},
    "H2": {"style": "fast", "gain": 1.8, "tol": 1.6, "grip_steps": 0.6},
    "H3": {"style": "jerky", "noise": 0.15},
    "H4": {"style": "hesitant", "stop_short": 0.6, "idle": 8, "back_off": 0.02},
    "H5": {"style": "another approach path", "cruise_extra": 0.10, "side_approach": 0.06},
}


class OperatorScript(PickPlaceScript):
    """The pick-and-place script with an operator's style."""

    def __init__(self, p: LiberoPlatform, spec, seed: int, style: dict):
        super().__init__(p, spec, seed)
        self.style = style
        self.gain = lx.GAIN * style.get("gain", 1.0)
        self.max_steps = int(lx.MAX_STEPS * OPERATOR_STEP_BUDGET)
        self.success_wait = OPERATOR_SUCCESS_WAIT
        self.rng = np.random.default_rng([seed, 7])

    def act(self, a: np.ndarray) -> None:
        a = np.asarray(a, dtype=np.float64).copy()
        if "noise" in self.style:
            a[:6] += self.rng.normal(0.0, self.style["noise"], 6) * (np.abs(a[:6]).max() > 0)
        bound = self.style.get("max_action", lx.MAX_ACTION)
        a[:6] = np.clip(a[:6], -bound, bound)
        super().act(a)

    def move(self, target, yaw=None, tol: float = 0.006, max_steps: int = 60) -> bool:
        s = self.style
        target = np.asarray(target, dtype=np.float64)
        budget = int(max_steps / min(s.get("gain", 1.0), 1.0))
        if "stop_short" in s:  # stop short, idle, back off, re-approach
            start = self.g.ee()
            super().move(start + s["stop_short"] * (target - start), yaw=yaw, tol=tol, max_steps=budget)
            for _ in range(s["idle"]):
                self.act(np.array([0, 0, 0, 0, 0, 0, self.grip]))
            super().move(self.g.ee() + np.r_[0, 0, s["back_off"]], yaw=yaw, tol=tol, max_steps=20)
        return super().move(target, yaw=yaw, tol=tol * s.get("tol", 1.0), max_steps=budget)

    def gripper(self, command: float, steps: int = 10) -> None:
        super().gripper(command, max(1, round(steps * self.style.get("grip_steps", 1.0))))

    def approach(self, grasp: np.ndarray, clear: float) -> list[tuple[np.ndarray, float, int]]:
        if "side_approach" not in self.style:
            return super().approach(grasp, clear)
        beside = grasp + np.r_[0.0, self.style["side_approach"], 0.0]
        return [(beside + [0, 0, clear + self.style["cruise_extra"]], 0.006, 100), (beside + [0, 0, 0.03], 0.004, 60)]


class LiberoOperatorSource(ScriptedOperatorSource):
    """One scripted operator model (H1–H5) on one LIBERO task, on a state-only env: `simulator` (the caller's,
    left open) or its own."""

    def __init__(self, task: str, operator: str, simulator: LiberoPlatform | None = None):
        self.task, self.operator, self.style = task, operator, operator_style(OPERATORS, operator)
        self.spec = task_spec(task)
        self._owns = simulator is None
        self.platform = LiberoPlatform(task, render=False, objects=self.spec.objects) if self._owns else simulator

    def attempt(self, seed: int) -> OperatorAttempt:
        s = OperatorScript(self.platform, self.spec, seed, self.style)
        ok = s.run()
        if not s.actions:
            s.act(np.array([0, 0, 0, 0, 0, 0, GRIPPER_OPEN]))
        return OperatorAttempt(np.stack(s.actions), ok)

    @property
    def provenance(self) -> dict:
        # "model" keeps this module's former path: it is released data (source_provenance), not an import
        return {"kind": "scripted_operator", "operator": self.operator, "platform": "libero",
                "model": "wsp_data.sources.libero_t3.OperatorScript", **self.style}

    def close(self) -> None:
        if self._owns:
            self.platform.close()


# -- policies ---------------------------------------------------------------------------------------
def feature_names(task: str) -> list[str]:
    names = [f"q{i}" for i in range(9)] + ["ee_x", "ee_y", "ee_z"] + [f"ee_r{i}" for i in range(6)]
    for obj in task_spec(task).objects:
        names += [f"{obj}_{k}" for k in ("x", "y", "z", *(f"r{i}" for i in range(6)), "dx", "dy", "dz")]
    return names + ["phase"]


def features(observation, n_objects: int, step: int, ref_length: float) -> np.ndarray:
    ee = np.asarray(observation.tcp_pose, dtype=np.float64)
    parts = [np.asarray(observation.qpos, dtype=np.float64), ee[:3], rot6d(ee[3:])]
    for k in range(n_objects):
        pose = np.asarray(observation.object_poses[k], dtype=np.float64)
        parts += [pose[:3], rot6d(pose[3:]), pose[:3] - ee[:3]]
    parts.append([step / ref_length])
    return np.concatenate(parts).astype(np.float32)


def checkpoint_path(task: str, stage: str, directory: Path | str | None = None) -> Path:
    return Path(directory or CHECKPOINT_DIR) / f"{task.replace('/', '__')}_{stage}.pt"


class LiberoPolicySource(BCPolicySource):
    """One behaviour-cloned checkpoint (task × stage), run closed-loop in a state-only LIBERO env; actions are
    the 7-D OSC action: the 6 arm dimensions bounded to ±`MAX_ACTION`, the gripper snapped to open/closed."""

    PLATFORM = "libero"
    TASKS = T3_TASKS
    checkpoint_path = staticmethod(checkpoint_path)

    def __init__(self, task: str, stage: str, checkpoint_dir: Path | str | None = None,
                 simulator: LiberoPlatform | None = None):
        super().__init__(task, stage, checkpoint_dir, simulator)
        self.spec = task_spec(task)

    def feature_names(self) -> list[str]:
        return feature_names(self.task)

    def open_platform(self) -> LiberoPlatform:
        return LiberoPlatform(self.task, render=False, objects=self.spec.objects)

    def act(self, observation, step: int) -> np.ndarray:
        y = self.network(features(observation, len(self.spec.objects), step, self.ref_length))
        arm = np.clip(y[:6], -lx.MAX_ACTION, lx.MAX_ACTION)
        return np.array([*arm, GRIPPER_CLOSED if y[6] >= 0 else GRIPPER_OPEN], dtype=np.float32)
