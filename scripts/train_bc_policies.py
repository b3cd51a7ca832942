"""Rebuild a platform's T3 policy checkpoints from scratch: behaviour cloning of the scripted experts, CPU only.

    .venv/bin/python scripts/train_bc_policies.py --platform {maniskill,libero,aloha} [--tasks …] [--demos N]
        [--noisy-rollouts N] [--noise-std X] [--steps N] [--early-steps N] [--eval-seeds N] [--out DIR] …

Every option defaults to the platform's recipe (`RECIPES`, the values the shipped checkpoints were trained
with). Per task:
1. script `--demos` verified expert episodes on training seeds 0, 1, 2, … (the platform's expert source; a seed
   whose script fails is skipped and recorded) and replay each, recording its states;
2. re-execute each demonstration `--noisy-rollouts` times with Gaussian noise on the executed arm actions and
   label every visited state with the expert's clean action (DART-style recovery data). ManiSkill replays the
   demonstration's stream with temporally correlated noise (σ `--noise-std` rad, AR(1) coefficient
   `--noise-rho`) on the 7 arm targets; LIBERO re-runs the closed-loop script with i.i.d. noise (σ OSC units)
   on the 6 arm dimensions (plain cloning of 30 demonstrations solved 0/10 held-out scenes on the can task);
   ALOHA re-runs it with i.i.d. noise (σ rad) on the 12 arm joint targets;
3. train the MLP of `wsp_data.platforms.bc_model` (`fit`: AdamW, cosine decay, one thread, fixed seeds) on the
   platform's state features (`wsp_data.platforms.<platform>.t3`), keeping the weights after `--early-steps`
   (early) and after `--steps` (late);
4. measure closed-loop success of both on `--eval-seeds` held-out training seeds (910,000 + k; stored in the
   checkpoint and its provenance) and, where `--test-seeds` is set (ALOHA's recipe: 20), on test-range scene
   seeds (3,000,000 + 800k: the first candidate seed of T3's group k; recorded in `training_config.json` only,
   never used to choose anything); write `<task>_<stage>.pt` (LIBERO: the task's "/" as "__") and
   `training_config.json` into `--out`.
Everything is seeded and runs on one CPU thread: the same arguments give the same weights (bit for bit).
ManiSkill's demonstrations are cached under `--cache` (default /tmp/wsp-policy-demos) keyed by task and seeds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from wsp_data.platforms.bc_model import FitConfig, MLPPolicy, fit, save_checkpoint  # noqa: E402
from wsp_data.platforms.bc_policy import (  # noqa: E402
    MAX_STEPS_FACTOR, SETTLE_STEPS, STAGES, TRAINING_CONFIG, BCPolicySource, closed_loop_success, sha256)

# Held-out evaluation seeds: training range (< 1,000,000), disjoint from demonstration seeds and from ManiSkill's
# seeds 900,000–900,009 on which its recipe (noise injection, step counts) was chosen.
EVAL_SEED_BASE = 910_000
T3_GROUP_SIZE = 8  # T3's group k proposes scene_seed("t3", 8k, 0) first (`wsp_data.builders.t3`)
DEFAULT_CACHE = Path("/tmp/wsp-policy-demos")


@dataclass(frozen=True)
class BCRecipe:
    """How one platform's checkpoints are trained: demonstrations, recovery data, model fit and evaluation."""

    demos: int  # verified expert demonstrations per task
    noisy_rollouts: int  # noise-injected re-executions per demonstration
    noise_std: float  # σ of that noise (ManiSkill, ALOHA: rad; LIBERO: OSC units)
    noise_rho: float | None  # AR(1) coefficient of that noise (ManiSkill), None: i.i.d. noise
    eval_seeds: int  # held-out training-range seeds of the success measurement
    test_seeds: int | None  # test-range seeds of a second success measurement, None: none
    fit: FitConfig


RECIPES: dict[str, BCRecipe] = {
    "maniskill": BCRecipe(
        demos=100, noisy_rollouts=2, noise_std=0.02, noise_rho=0.8, eval_seeds=30, test_seeds=None,
        fit=FitConfig(seed=0, steps=20000, early_steps=2000, batch=256, lr=1e-3, weight_decay=1e-4,
                      hidden=(256, 256), std_floor=1e-3)),
    "libero": BCRecipe(
        demos=30, noisy_rollouts=2, noise_std=0.1, noise_rho=None, eval_seeds=10, test_seeds=None,
        fit=FitConfig(seed=0, steps=20000, early_steps=2000, batch=256, lr=1e-3, weight_decay=1e-4,
                      hidden=(256, 256), std_floor=1e-3)),
    "aloha": BCRecipe(
        demos=50, noisy_rollouts=2, noise_std=0.04, noise_rho=None, eval_seeds=20, test_seeds=20,
        fit=FitConfig(seed=0, steps=20000, early_steps=200, batch=256, lr=1e-3, weight_decay=1e-4,
                      hidden=(256, 256), std_floor=1e-3)),
}
FIT_FIELDS = ("seed", "steps", "early_steps", "batch", "lr", "weight_decay", "hidden")  # recorded per task


def fit_record(cfg: FitConfig) -> dict:
    """The fit's recorded settings (`FIT_FIELDS`; the hidden widths as a list)."""
    return {k: list(cfg.hidden) if k == "hidden" else getattr(cfg, k) for k in FIT_FIELDS}


def log(msg: str) -> None:
    """A progress line, on stderr."""
    print(msg, file=sys.stderr, flush=True)


def start_training(out: Path) -> tuple[dict, Path]:
    """Set torch up for a reproducible CPU run (one thread, deterministic algorithms), create `out`, and return
    its training record so far (`{"tasks": {…}}`) and the record's path."""
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    out.mkdir(parents=True, exist_ok=True)
    path = out / TRAINING_CONFIG
    config = json.loads(path.read_text()) if path.is_file() else {}
    config.setdefault("tasks", {})
    return config, path


@dataclass(frozen=True)
class TaskData:
    """One task's training set: features X, targets Y, the expert's mean length and what the collection
    records (seeds, sample counts, seconds)."""

    X: np.ndarray
    Y: np.ndarray
    ref: float
    info: dict


class Trainer(ABC):
    """One platform's side of the training: its tasks, data collection, training record and policy source."""

    platform: ClassVar[str]
    sort_record: ClassVar[bool]  # training_config.json with sorted keys
    caches_demonstrations: ClassVar[bool] = False  # whether `cache` is used

    def __init__(self, recipe: BCRecipe, out: Path, cache: Path | None):
        self.recipe, self.out, self.cache = recipe, out, cache

    @staticmethod
    @abstractmethod
    def tasks() -> tuple[str, ...]:
        """The platform's T3 tasks."""

    @abstractmethod
    def collect(self, task: str) -> TaskData:
        """Demonstrations and recovery data of `task`, as features and targets."""

    @abstractmethod
    def record(self, task: str, data: TaskData, losses: list[float], train_seconds: float) -> tuple[dict, dict]:
        """The task's training record (training_config.json) and the checkpoints' metadata without stage."""

    @abstractmethod
    def source(self, task: str, stage: str) -> BCPolicySource:
        """The policy source of a checkpoint just written to `out`."""

    @abstractmethod
    def checkpoint_path(self, task: str, stage: str) -> Path:
        """Where the checkpoint of (task, stage) goes in `out`."""

    def evaluate(self, task: str, stage: str, seeds: list[int]) -> dict:
        """Closed-loop success of one checkpoint on `seeds` (each rollout from its own reset(seed))."""
        return closed_loop_success(self.source(task, stage), seeds)[0]

    def checkpoint_facts(self, path: Path) -> dict:
        """What the training record keeps of one checkpoint file, per stage ({record key: value})."""
        return {"checkpoint_sha256": sha256(path)}

    def finish_task(self, tc: dict, data: TaskData, task_seconds: float) -> None:
        """Complete a task's record once its checkpoints are written (default: nothing to add)."""

    def finish_config(self, config: dict, eval_seeds: list[int], argv: Sequence[str]) -> None:
        """Complete the training record before it is written (default: nothing to add)."""


# -- ManiSkill ---------------------------------------------------------------------------------------------
DEMO_KEYS = ("qpos", "tcp", "objects", "goal", "step", "action", "episode")
# Left out of ManiSkill's checkpoints (wall times vary between runs; the loss log is long): the same arguments then
# give byte-identical checkpoint files. training_config.json keeps them.
UNSTABLE = ("loss_every_500_steps", "collect_seconds", "train_seconds")


def _record_sample(rows: dict, ob, goal, step: int, action: np.ndarray, episode: int) -> None:
    """Append one (state, labelled action) sample to the dataset columns."""
    rows["qpos"].append(ob.qpos)
    rows["tcp"].append(ob.tcp_pose)
    rows["objects"].append(ob.object_poses)
    rows["goal"].append(np.zeros(3, np.float32) if goal is None else goal)
    rows["step"].append(step)
    rows["action"].append(action)
    rows["episode"].append(episode)


def jerk(actions: np.ndarray) -> float:
    """Mean absolute second difference of the 7 arm targets (rad per step²): how jerky a stream is."""
    return float(np.abs(np.diff(actions[:, :7], 2, axis=0)).mean()) if len(actions) > 2 else 0.0


class ManiSkillTrainer(Trainer):
    """ManiSkill: demonstrations replayed under `pd_joint_pos`, recovery data from noisy replays of their streams
    (both cached), the Panda's joint limits in the checkpoints, the record in its own key order."""

    platform = "maniskill"
    sort_record = False
    caches_demonstrations = True

    def __init__(self, recipe: BCRecipe, out: Path, cache: Path | None):
        super().__init__(recipe, out, cache)
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform

        with ManiSkillPlatform("PickCube", render=False) as p:  # the Panda's joint limits (same robot in every task)
            self.arm_limits = p.robot.get_qlimits()[0, :7].detach().cpu().numpy().astype(float).tolist()

    @staticmethod
    def tasks() -> tuple[str, ...]:
        from wsp_data.platforms.maniskill.t3 import T3_TASKS

        return T3_TASKS

    def demonstrations(self, task: str) -> dict:
        """`demos` verified expert episodes with their states: per step qpos, tcp, object poses, goal, action."""
        demos, cache = self.recipe.demos, self.cache
        path = cache / f"{task}_demos{demos}.npz" if cache else None
        if path is not None and path.is_file():
            d = dict(np.load(path, allow_pickle=False))
            log(f"{task}: {demos} demos from cache {path}")
            return d
        from wsp_data.platforms.maniskill.experts import ExpertSource
        from wsp_data.platforms.maniskill.t3 import read_goal

        expert = ExpertSource(task)
        p = expert.replayer
        rows = {k: [] for k in DEMO_KEYS}
        seeds, skipped, lengths = [], [], []
        seed = 0
        t0 = time.perf_counter()
        try:
            while len(seeds) < demos:
                actions = expert.trajectory(seed)
                if actions is None:
                    skipped.append(seed)
                    seed += 1
                    continue
                ob = p.reset(seed)
                goal = read_goal(p, task)
                for t, a in enumerate(actions):
                    _record_sample(rows, ob, goal, t, a, len(seeds))
                    ob = p.step(a)
                if not ob.success:  # cannot happen: trajectory() verified this very replay
                    raise RuntimeError(f"{task} seed {seed}: expert replay did not succeed")
                seeds.append(seed)
                lengths.append(len(actions))
                seed += 1
                if len(seeds) % 20 == 0:
                    log(f"{task}: {len(seeds)}/{demos} demos ({time.perf_counter() - t0:.0f} s)")
        finally:
            expert.close()
        d = {k: np.asarray(v) for k, v in rows.items()}
        d.update(seeds=np.asarray(seeds), skipped=np.asarray(skipped, dtype=np.int64), lengths=np.asarray(lengths),
                 seconds=np.asarray(time.perf_counter() - t0))
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(path, **d)
        return d

    def recovery(self, task: str, d: dict) -> dict:
        """DART-style recovery data: each demonstration re-executed `noisy_rollouts` times with temporally
        correlated Gaussian noise (std `noise_std` rad, AR(1) coefficient `noise_rho`) added to the 7 arm targets;
        every visited state is labelled with the demonstration's nominal action of that step (the way back onto
        the expert's path)."""
        r, cache = self.recipe, self.cache
        rollouts, sigma, rho = r.noisy_rollouts, r.noise_std, r.noise_rho
        n = len(d["seeds"])
        path = cache / f"{task}_demos{n}_noisy{rollouts}_s{sigma:g}_r{rho:g}.npz" if cache else None
        if path is not None and path.is_file():
            log(f"{task}: noisy rollouts from cache {path}")
            return dict(np.load(path, allow_pickle=False))
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform
        from wsp_data.platforms.maniskill.experts import task_spec
        from wsp_data.platforms.maniskill.t3 import read_goal

        rows = {k: [] for k in DEMO_KEYS}
        t0 = time.perf_counter()
        with ManiSkillPlatform(task, render=False, objects=task_spec(task).objects) as p:
            for i, seed in enumerate(d["seeds"]):
                nominal = d["action"][d["episode"] == i]
                for k in range(rollouts):
                    rng = np.random.default_rng([int(seed), k, 7])
                    eps = np.zeros(7)
                    ob = p.reset(int(seed))
                    goal = read_goal(p, task)
                    for t, a in enumerate(nominal):
                        _record_sample(rows, ob, goal, t, a, n + i * rollouts + k)
                        eps = rho * eps + np.sqrt(1 - rho ** 2) * sigma * rng.standard_normal(7)
                        ob = p.step(np.concatenate([a[:7] + eps, a[7:]]).astype(np.float32))
                if (i + 1) % 20 == 0:
                    log(f"{task}: noisy rollouts of {i + 1}/{n} demos ({time.perf_counter() - t0:.0f} s)")
        out = {k: np.asarray(v) for k, v in rows.items()}
        out["seconds"] = np.asarray(time.perf_counter() - t0)
        if path is not None:
            np.savez(path, **out)
        return out

    def collect(self, task: str) -> TaskData:
        from wsp_data.platforms.maniskill.env import Observation
        from wsp_data.platforms.maniskill.t3 import action_target, features

        demos = self.demonstrations(task)
        noisy = self.recovery(task, demos)
        d = {**demos, **{k: np.concatenate([demos[k], noisy[k]]) for k in DEMO_KEYS}}
        ref = float(np.mean(d["lengths"]))
        X, Y = [], []
        for i in range(len(d["step"])):
            ob = Observation(d["qpos"][i], d["tcp"][i], d["objects"][i], np.zeros(0, bool), False)
            X.append(features(task, ob, int(d["step"][i]), d["goal"][i], ref))
            Y.append(action_target(ob, d["action"][i]))
        X, Y = np.stack(X), np.stack(Y)
        log(f"{task}: {len(X)} samples, {X.shape[1]} features, training {self.recipe.fit.steps} steps")
        expert_jerk = float(np.mean([jerk(demos["action"][demos["episode"] == i]) for i in range(len(demos["seeds"]))]))
        info = {"demo_seeds": [int(s) for s in demos["seeds"]], "skipped_seeds": [int(s) for s in demos["skipped"]],
                "demonstration_samples": int(len(demos["step"])), "noisy_samples": int(len(noisy["step"])),
                "expert_max_length": int(np.max(demos["lengths"])),
                "collect_seconds": round(float(demos["seconds"]) + float(noisy["seconds"]), 1),
                "expert_mean_jerk": round(expert_jerk, 6)}
        return TaskData(X, Y, ref, info)

    def record(self, task: str, data: TaskData, losses: list[float], train_seconds: float) -> tuple[dict, dict]:
        from wsp_data.platforms.maniskill.t3 import feature_names

        r, cfg, info = self.recipe, self.recipe.fit, data.info
        tc = {
            "demos": r.demos, "demo_seeds": info["demo_seeds"], "skipped_seeds": info["skipped_seeds"],
            "noisy_rollouts_per_demo": r.noisy_rollouts, "noise_std_rad": r.noise_std, "noise_rho": r.noise_rho,
            "samples": {"demonstration": info["demonstration_samples"], "noisy": info["noisy_samples"],
                        "total": int(len(data.X))},
            "expert_mean_length": data.ref, "expert_max_length": info["expert_max_length"],
            "features": feature_names(task),
            "target": "arm joint targets minus current arm qpos (7, rad) + gripper command (1, +1 open / -1 closed)",
            "architecture": f"MLP {data.X.shape[1]}-" + "-".join(map(str, cfg.hidden)) + "-8, ReLU; inputs and "
                            "targets standardised with training-set statistics stored in the checkpoint",
            "loss": "MSE on standardised targets",
            "optimizer": f"AdamW lr {cfg.lr} with cosine decay to 0 over {cfg.steps} steps, weight decay "
                         f"{cfg.weight_decay}, batch {cfg.batch} drawn uniformly with replacement",
            **fit_record(cfg),
            "stage_steps": {"early": cfg.early_steps, "late": cfg.steps},
            "loss_every_500_steps": losses,
            "inference": "deterministic; arm = qpos + output clipped to the joint limits; gripper = +1 if its "
                         f"output >= 0 else -1; a rollout stops once success has held {SETTLE_STEPS} steps or at "
                         f"ceil({MAX_STEPS_FACTOR} x expert mean length) steps",
            "collect_seconds": info["collect_seconds"],
            "train_seconds": round(train_seconds, 1),
        }
        meta = dict(task=task, in_dim=int(data.X.shape[1]), hidden=list(cfg.hidden), feature_names=feature_names(task),
                    expert_mean_length=data.ref, arm_limits=self.arm_limits, total_training_steps=cfg.steps,
                    training_config={k: v for k, v in tc.items() if k not in UNSTABLE})
        return tc, meta

    def source(self, task: str, stage: str) -> BCPolicySource:
        from wsp_data.platforms.maniskill.t3 import PolicySource

        return PolicySource(task, stage, checkpoint_dir=self.out)

    def checkpoint_path(self, task: str, stage: str) -> Path:
        from wsp_data.platforms.maniskill.t3 import checkpoint_path

        return checkpoint_path(task, stage, self.out)

    def evaluate(self, task: str, stage: str, seeds: list[int]) -> dict:
        """Closed-loop success of one checkpoint on `seeds`, with the streams' jerk and the measurement's time."""
        t0 = time.perf_counter()
        summary, streams = closed_loop_success(self.source(task, stage), seeds)
        return {**summary, "mean_jerk": round(float(np.mean([jerk(a) for a in streams])), 6),
                "seconds": round(time.perf_counter() - t0, 1)}

    def checkpoint_facts(self, path: Path) -> dict:
        return {"checkpoint_sha256": sha256(path), "checkpoint_bytes": path.stat().st_size}

    def finish_task(self, tc: dict, data: TaskData, task_seconds: float) -> None:
        tc["expert_mean_jerk"] = data.info["expert_mean_jerk"]
        tc["total_seconds"] = round(task_seconds, 1)

    def finish_config(self, config: dict, eval_seeds: list[int], argv: Sequence[str]) -> None:
        config["eval_seeds"] = {"first": eval_seeds[0], "count": len(eval_seeds),
                                "note": "held-out training-range seeds: never demonstration seeds, never used "
                                        "while choosing the recipe"}
        config["command"] = "scripts/train_bc_policies.py " + " ".join(argv)


# -- LIBERO and ALOHA: the closed-loop script re-run with noise ----------------------------------------------
class ScriptedTrainer(Trainer):
    """A platform whose recovery data re-run the expert's closed-loop script with i.i.d. noise on the executed arm
    actions (`NoisyScript`), each visited state labelled with the script's clean action."""

    sort_record = True
    target: ClassVar[str]  # the training record's description of the regression target
    noise_std_key: ClassVar[str]  # the training record's name of the noise σ

    @property
    @abstractmethod
    def inference(self) -> str:
        """The training record's description of the run-time action."""

    @abstractmethod
    def expert(self, task: str):
        """The platform's verified expert source of `task`."""

    @abstractmethod
    def noisy_samples(self, src, task: str, seed: int, k: int) -> list[tuple[object, int, np.ndarray]]:
        """The (state, step, clean action) samples of noisy re-run `k` of `task`'s script on `seed` (the script
        class is defined there, so that the trainer imports a platform's simulator only when it trains it)."""

    @abstractmethod
    def features(self, observation, n_objects: int, step: int, ref_length: float) -> np.ndarray:
        """The policy input of one observation."""

    @abstractmethod
    def target_of(self, observation, action: np.ndarray) -> np.ndarray:
        """The regression target of one clean action."""

    @abstractmethod
    def feature_names(self, task: str) -> list[str]:
        """The policy's input feature names of `task`."""

    def collect(self, task: str) -> TaskData:
        demos, noisy, std = self.recipe.demos, self.recipe.noisy_rollouts, self.recipe.noise_std
        t0 = time.perf_counter()
        src = self.expert(task)
        episodes, seeds, skipped, seed = [], [], [], 0
        extra: list[tuple[object, int, np.ndarray]] = []
        try:
            while len(episodes) < demos:
                actions = src.trajectory(seed)
                if actions is None:
                    skipped.append(seed)
                else:
                    ro = src.replayer.replay(seed, actions)
                    episodes.append((ro.observations[:-1], actions))
                    seeds.append(seed)
                    for k in range(noisy):
                        extra += self.noisy_samples(src, task, seed, k)
                seed += 1
        finally:
            src.close()
        ref = float(np.mean([len(a) for _, a in episodes]))
        n = len(src.spec.objects)
        X = np.stack([self.features(ob, n, t, ref) for obs, _ in episodes for t, ob in enumerate(obs)]
                     + [self.features(ob, n, t, ref) for ob, t, _ in extra])
        Y = np.stack([self.target_of(ob, a) for obs, acts in episodes for ob, a in zip(obs, acts)]
                     + [self.target_of(ob, a) for ob, _, a in extra]).astype(np.float32)
        log(f"{task}: {len(episodes)} demonstrations ({len(skipped)} seeds skipped) + {len(extra)} noisy samples, "
            f"{len(X)} samples")
        info = {"demo_seeds": seeds, "skipped_seeds": skipped,
                "expert_max_length": int(max(len(a) for _, a in episodes)), "noisy_rollouts_per_demo": noisy,
                self.noise_std_key: std, "noisy_samples": len(extra),
                "collect_seconds": round(time.perf_counter() - t0, 1)}
        return TaskData(X, Y, ref, info)

    def record(self, task: str, data: TaskData, losses: list[float], train_seconds: float) -> tuple[dict, dict]:
        cfg, X, Y = self.recipe.fit, data.X, data.Y
        tc = {"demos": self.recipe.demos, **data.info, "samples": int(len(X)), "expert_mean_length": data.ref,
              "features": self.feature_names(task), "target": self.target,
              "architecture": f"MLP {X.shape[1]}-" + "-".join(map(str, cfg.hidden)) + f"-{Y.shape[1]}, ReLU, "
                              "standardised inputs and targets",
              **fit_record(cfg),
              "stage_steps": {"early": cfg.early_steps, "late": cfg.steps},
              "inference": self.inference}
        stable = {k: v for k, v in tc.items() if k != "collect_seconds"}
        meta = dict(task=task, in_dim=int(X.shape[1]), out_dim=int(Y.shape[1]), hidden=list(cfg.hidden),
                    feature_names=self.feature_names(task), expert_mean_length=data.ref,
                    total_training_steps=cfg.steps, training_config=stable)
        tc["train_seconds"], tc["loss_every_500_steps"] = round(train_seconds, 1), losses
        return tc, meta


class LiberoTrainer(ScriptedTrainer):
    """LIBERO: the pick-and-place script re-run with noise on the 6 OSC arm dimensions; the target is the action."""

    platform = "libero"
    noise_std_key = "noise_std"
    target = "the expert's OSC action (6 arm dims + gripper)"

    @property
    def inference(self) -> str:
        return (f"deterministic; arm clipped to +-0.9, gripper +1 if its output >= 0 else -1; stops once success "
                f"held {SETTLE_STEPS} steps or at ceil({MAX_STEPS_FACTOR} x expert mean length)")

    @staticmethod
    def tasks() -> tuple[str, ...]:
        from wsp_data.platforms.libero.t3 import T3_TASKS

        return T3_TASKS

    def expert(self, task: str):
        from wsp_data.platforms.libero.experts import LiberoExpertSource

        return LiberoExpertSource(task)

    def noisy_samples(self, src, task: str, seed: int, k: int) -> list[tuple[object, int, np.ndarray]]:
        from wsp_data.platforms.libero.experts import PickPlaceScript

        class NoisyScript(PickPlaceScript):
            """The expert's script executing noisy arm actions, recording (state, step, clean action)."""

            def __init__(self, p, spec, seed: int, std: float, k: int):
                super().__init__(p, spec, seed)
                self.rng, self.std = np.random.default_rng([seed, 11, k]), std
                self.samples: list[tuple[object, int, np.ndarray]] = []

            def act(self, a: np.ndarray) -> None:
                clean = np.asarray(a, dtype=np.float64).copy()
                clean[:6] = np.clip(clean[:6], -0.9, 0.9)
                self.samples.append((self.observation, len(self.actions), clean.astype(np.float32)))
                noisy = clean.copy()
                noisy[:6] += self.rng.normal(0.0, self.std, 6)
                super().act(noisy)

        script = NoisyScript(src.replayer, src.spec, seed, self.recipe.noise_std, k)
        script.run()  # success or not: every visited state is labelled with the clean action
        return script.samples

    def features(self, observation, n_objects: int, step: int, ref_length: float) -> np.ndarray:
        from wsp_data.platforms.libero.t3 import features

        return features(observation, n_objects, step, ref_length)

    def target_of(self, observation, action: np.ndarray) -> np.ndarray:
        return action

    def feature_names(self, task: str) -> list[str]:
        from wsp_data.platforms.libero.t3 import feature_names

        return feature_names(task)

    def source(self, task: str, stage: str) -> BCPolicySource:
        from wsp_data.platforms.libero.t3 import LiberoPolicySource

        return LiberoPolicySource(task, stage, checkpoint_dir=self.out)

    def checkpoint_path(self, task: str, stage: str) -> Path:
        from wsp_data.platforms.libero.t3 import checkpoint_path

        return checkpoint_path(task, stage, self.out)


class AlohaTrainer(ScriptedTrainer):
    """ALOHA: the task's script re-run with noise on the 12 arm joint targets; the target is relative to the joints."""

    platform = "aloha"
    noise_std_key = "noise_std_rad"
    target = "the expert's 12 arm joint targets relative to the arm joints (rad), then both gripper commands"

    @property
    def inference(self) -> str:
        from wsp_data.platforms.aloha.t3 import MAX_DELTA

        return (f"deterministic; arm targets = joints + output bounded to +-{MAX_DELTA} rad, clipped to the joint "
                f"limits; grippers 1 (open) if the output >= 0.5 else 0; stops once success held {SETTLE_STEPS} "
                f"steps or at ceil({MAX_STEPS_FACTOR} x expert mean length)")

    @staticmethod
    def tasks() -> tuple[str, ...]:
        from wsp_data.platforms.aloha.t3 import T3_TASKS

        return T3_TASKS

    def expert(self, task: str):
        from wsp_data.platforms.aloha.experts import AlohaExpertSource

        return AlohaExpertSource(task)

    def noisy_samples(self, src, task: str, seed: int, k: int) -> list[tuple[object, int, np.ndarray]]:
        from wsp_data.platforms.aloha.experts import SCRIPTS, OutOfTime, Script
        from wsp_data.platforms.aloha.t3 import ARM_ACTION

        class NoisyScript(Script):
            """The expert's script executing noisy arm targets, recording (state, step, clean action)."""

            def __init__(self, p, seed: int, std: float, k: int):
                super().__init__(p, seed)
                self.rng, self.std = np.random.default_rng([seed, 11, k]), std
                self.samples: list[tuple[object, int, np.ndarray]] = []

            def act(self) -> None:
                if len(self.actions) >= self.max_steps:
                    raise OutOfTime
                clean = self.command(self.hand)
                self.samples.append((self.observation, len(self.actions), clean))
                noisy = clean.copy()
                noisy[list(ARM_ACTION)] += self.rng.normal(0.0, self.std, 12).astype(np.float32)
                noisy[list(ARM_ACTION)] = np.clip(noisy[list(ARM_ACTION)], *self.p.qlimits[:12].T)
                self.actions.append(noisy)
                self.observation = self.p.step(noisy)

        script = NoisyScript(src.replayer, seed, self.recipe.noise_std, k)
        try:  # success or not: every visited state is labelled with the clean action
            SCRIPTS[task](script)
        except OutOfTime:
            pass
        return script.samples

    def features(self, observation, n_objects: int, step: int, ref_length: float) -> np.ndarray:
        from wsp_data.platforms.aloha.t3 import features

        return features(observation, n_objects, step, ref_length)

    def target_of(self, observation, action: np.ndarray) -> np.ndarray:
        from wsp_data.platforms.aloha.t3 import action_target

        return action_target(observation, action)

    def feature_names(self, task: str) -> list[str]:
        from wsp_data.platforms.aloha.t3 import feature_names

        return feature_names(task)

    def source(self, task: str, stage: str) -> BCPolicySource:
        from wsp_data.platforms.aloha.t3 import AlohaPolicySource

        return AlohaPolicySource(task, stage, checkpoint_dir=self.out)

    def checkpoint_path(self, task: str, stage: str) -> Path:
        from wsp_data.platforms.aloha.t3 import checkpoint_path

        return checkpoint_path(task, stage, self.out)


TRAINERS: dict[str, type[Trainer]] = {t.platform: t for t in (ManiSkillTrainer, LiberoTrainer, AlohaTrainer)}


# -- the run -----------------------------------------------------------------------------------------------
def train_task(trainer: Trainer, task: str, eval_seeds: list[int], test_seeds: list[int] | None) -> dict:
    """Collect, fit, write both checkpoints of `task`, measure them and write them again with their success;
    returns the task's training record."""
    t_task = time.perf_counter()
    data = trainer.collect(task)
    t0 = time.perf_counter()
    early, late, losses = fit(data.X, data.Y, trainer.recipe.fit, log)
    tc, meta = trainer.record(task, data, losses, time.perf_counter() - t0)
    models: dict[str, MLPPolicy] = dict(zip(STAGES, (early, late)))
    for stage, model in models.items():
        save_checkpoint(trainer.checkpoint_path(task, stage), model,
                        dict(meta, stage=stage, training_steps=tc["stage_steps"][stage]))
    tc["success"] = {}
    if test_seeds is not None:
        tc["test_range_success"] = {}
    for stage, model in models.items():
        res = trainer.evaluate(task, stage, eval_seeds)
        log(f"{task} {stage}: success {res['successes']}/{res['seeds']}, mean {res['mean_steps']:.0f} steps")
        tc["success"][stage] = res
        path = trainer.checkpoint_path(task, stage)
        save_checkpoint(path, model, dict(meta, stage=stage, training_steps=tc["stage_steps"][stage],
                                          success={k: v for k, v in res.items() if k != "seconds"}))
        for key, value in trainer.checkpoint_facts(path).items():
            tc.setdefault(key, {})[stage] = value
        if test_seeds:
            res = trainer.evaluate(task, stage, test_seeds)
            log(f"{task} {stage}: test-range success {res['successes']}/{res['seeds']}")
            tc["test_range_success"][stage] = res
    trainer.finish_task(tc, data, time.perf_counter() - t_task)
    return tc


def parse(argv: Sequence[str]) -> tuple[argparse.Namespace, BCRecipe]:
    """The arguments, and the platform's recipe with the options given on the command line."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platform", required=True, choices=sorted(RECIPES))
    ap.add_argument("--tasks", nargs="+", help="default: the platform's T3 tasks")
    recipe_options: dict[str, tuple[str, Callable]] = {
        "demos": ("expert demonstrations per task", int),
        "noisy_rollouts": ("noise-injected re-executions per demonstration", int),
        "noise_std": ("σ of that noise (ManiSkill, ALOHA: rad on the arm targets; LIBERO: OSC units)", float),
        "noise_rho": ("AR(1) coefficient of that noise (ManiSkill)", float),
        "eval_seeds": ("held-out training-range seeds of the success measurement", int),
        "test_seeds": ("test-range seeds of a second success measurement (ALOHA)", int),
    }
    fit_options: dict[str, tuple[str, Callable]] = {
        "steps": ("training steps of the late checkpoint", int),
        "early_steps": ("training steps of the early checkpoint", int),
        "batch": ("samples per training step", int),
        "lr": ("peak learning rate", float),
        "seed": ("training seed", int),
    }
    for name, (text, kind) in {**recipe_options, **fit_options}.items():
        ap.add_argument("--" + name.replace("_", "-"), type=kind, help=f"{text} (default: the platform's recipe)")
    ap.add_argument("--out", type=Path, help="checkpoint folder (default: the platform's checkpoints/)")
    ap.add_argument("--cache", type=Path, help=f"ManiSkill's demonstration cache folder (default {DEFAULT_CACHE}; "
                                               "'' for none)")
    args = ap.parse_args(argv)
    recipe, trainer = RECIPES[args.platform], TRAINERS[args.platform]
    if args.noise_rho is not None and recipe.noise_rho is None:
        ap.error(f"--noise-rho: {args.platform}'s recovery noise is i.i.d.")
    if args.cache is not None and not trainer.caches_demonstrations:
        ap.error(f"--cache: {args.platform}'s demonstrations are not cached")
    if unknown := [t for t in args.tasks or () if t not in trainer.tasks()]:
        ap.error(f"unknown {args.platform} T3 task(s) {', '.join(unknown)}; T3 tasks: {', '.join(trainer.tasks())}")
    fit_cfg = replace(recipe.fit, **{k: getattr(args, k) for k in fit_options if getattr(args, k) is not None})
    recipe = replace(recipe, fit=fit_cfg, **{k: getattr(args, k) for k in recipe_options
                                             if getattr(args, k) is not None})
    if not 0 < recipe.fit.early_steps < recipe.fit.steps:
        ap.error("need 0 < --early-steps < --steps")
    return args, recipe


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args, recipe = parse(argv)
    out = args.out or ROOT / "wsp_data" / "platforms" / args.platform / "checkpoints"
    cls = TRAINERS[args.platform]
    cache = None
    if cls.caches_demonstrations:
        cache = DEFAULT_CACHE if args.cache is None else None if str(args.cache) in ("", ".") else args.cache
    config, config_path = start_training(out)
    trainer = cls(recipe, out, cache)
    eval_seeds = [EVAL_SEED_BASE + k for k in range(recipe.eval_seeds)]
    test_seeds = None
    if recipe.test_seeds is not None:
        from wsp_data.schema import scene_seed

        test_seeds = [scene_seed("t3", T3_GROUP_SIZE * k, 0) for k in range(recipe.test_seeds)]
    for task in args.tasks or trainer.tasks():
        config["tasks"][task] = train_task(trainer, task, eval_seeds, test_seeds)
        trainer.finish_config(config, eval_seeds, argv)
        config_path.write_text(json.dumps(config, indent=1, sort_keys=trainer.sort_record) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
