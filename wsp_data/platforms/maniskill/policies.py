"""Learned policy sources for T3: behaviour-cloned MLPs from simulator state to the 8-D joint action.

For each T3 task a small MLP was trained (`scripts/train_policies.py`, CPU, fixed seeds) on replay-verified
scripted expert trajectories of training seeds (`ExpertSource`) plus noise-injected re-executions of them,
and two checkpoints were kept: an *early* one (10% of training) and the *late* (final) one; docs/policies.md
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

import hashlib
import json
import math
import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

from wsp_data.schema import ACTION_DIM

T3_TASKS = ("PickCube", "PushCube", "PullCube", "PlaceSphere", "LiftPegUpright")
STAGES = ("early", "late")
CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"
TRAINING_CONFIG = "training_config.json"
TRAIN_SCRIPT = "scripts/train_policies.py"
SETTLE_STEPS = 5  # a rollout stops once success has held this many consecutive steps
MAX_STEPS_FACTOR = 1.5  # default step budget: this × the expert's mean trajectory length

# The goal the observation does not carry: task → env attribute holding a (static) goal actor.
GOAL_ATTR = {"PickCube": "goal_site", "PushCube": "goal_region", "PullCube": "goal_region"}


class PolicyCheckpointMissing(FileNotFoundError):
    """A policy checkpoint that is not on disk."""


def checkpoint_path(task: str, stage: str, directory: Path | str | None = None) -> Path:
    return Path(directory or CHECKPOINT_DIR) / f"{task}_{stage}.pt"


# -- features ---------------------------------------------------------------------------------------
def rot6d(q) -> np.ndarray:
    """A unit quaternion (wxyz) as the first two columns of its rotation matrix (continuous, sign-free)."""
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y),  # column 0
        2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x),  # column 1
    ], dtype=np.float64)


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


# -- model ------------------------------------------------------------------------------------------
class MLPPolicy(nn.Module):
    """Normalised state → normalised action target; normalisation statistics live in buffers."""

    def __init__(self, in_dim: int, hidden: tuple[int, ...] = (256, 256), out_dim: int = ACTION_DIM):
        super().__init__()
        layers, d = [], in_dim
        for h in hidden:
            layers += [nn.Linear(d, h), nn.ReLU()]
            d = h
        layers.append(nn.Linear(d, out_dim))
        self.net = nn.Sequential(*layers)
        for name, dim in (("x_mean", in_dim), ("x_std", in_dim), ("y_mean", out_dim), ("y_std", out_dim)):
            self.register_buffer(name, torch.zeros(dim) if "mean" in name else torch.ones(dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Raw features → raw action target."""
        return self.net((x - self.x_mean) / self.x_std) * self.y_std + self.y_mean


def fit(X: np.ndarray, Y: np.ndarray, cfg: dict, log) -> tuple[MLPPolicy, MLPPolicy, list[float]]:
    """Adam + cosine decay on MSE of normalised targets; returns (early, late) models and a loss log."""
    torch.manual_seed(cfg["seed"])
    gen = torch.Generator().manual_seed(cfg["seed"])
    x, y = torch.from_numpy(X), torch.from_numpy(Y)
    model = MLPPolicy(X.shape[1], tuple(cfg["hidden"]), Y.shape[1])
    model.x_mean.copy_(x.mean(0))
    model.x_std.copy_(x.std(0).clamp_min(cfg["std_floor"]))
    model.y_mean.copy_(y.mean(0))
    model.y_std.copy_(y.std(0).clamp_min(cfg["std_floor"]))
    yn = (y - model.y_mean) / model.y_std
    opt = torch.optim.AdamW(model.net.parameters(), lr=cfg["lr"], weight_decay=cfg["weight_decay"])
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.5 * (1 + np.cos(np.pi * min(s, cfg["steps"]) / cfg["steps"])))
    early, losses, running = None, [], 0.0
    for step in range(1, cfg["steps"] + 1):
        idx = torch.randint(len(x), (cfg["batch"],), generator=gen)
        pred = model.net((x[idx] - model.x_mean) / model.x_std)
        loss = torch.nn.functional.mse_loss(pred, yn[idx])
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        running += loss.item()
        if step % 500 == 0:
            losses.append(round(running / 500, 6))
            running = 0.0
            log(f"  step {step}: loss {losses[-1]:.4f}")
        if step == cfg["early_steps"]:
            early = MLPPolicy(X.shape[1], tuple(cfg["hidden"]), Y.shape[1])
            early.load_state_dict(model.state_dict())
    return early, model, losses


def save_checkpoint(path: Path, model: MLPPolicy, meta: dict) -> None:
    """A small checkpoint: float32 weights and buffers plus JSON-able metadata."""
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().clone().float().contiguous() for k, v in model.state_dict().items()}
    torch.save({"format": "wsp-bc-mlp/1", "state_dict": state, "meta": json.dumps(meta, sort_keys=True)}, path)


def load_checkpoint(path: Path) -> tuple[MLPPolicy, dict]:
    blob = torch.load(path, map_location="cpu", weights_only=True)
    meta = json.loads(blob["meta"])
    model = MLPPolicy(meta["in_dim"], tuple(meta["hidden"]), meta.get("out_dim", ACTION_DIM))
    model.load_state_dict(blob["state_dict"])
    model.eval()
    return model, meta


def training_log(msg: str) -> None:
    """The training scripts' progress line, on stderr."""
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


def open_checkpoint(path: Path, rebuild: str, docs: str) -> tuple[MLPPolicy, dict]:
    """Load a policy checkpoint, or raise PolicyCheckpointMissing naming the path and the rebuild command."""
    if not Path(path).is_file():
        raise PolicyCheckpointMissing(f"policy checkpoint {path} is missing; rebuild it with `.venv/bin/python "
                                      f"{rebuild}` (see {docs})")
    return load_checkpoint(Path(path))


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# -- the source ------------------------------------------------------------------------------------
class PolicySource:
    """One checkpoint (task × stage) of a behaviour-cloned policy, run closed-loop in a state-only env."""

    def __init__(self, task: str, stage: str, checkpoint_dir: Path | str | None = None):
        if task not in T3_TASKS:
            raise KeyError(f"no policy for task {task!r}; T3 tasks: {', '.join(T3_TASKS)}")
        if stage not in STAGES:
            raise KeyError(f"unknown policy stage {stage!r}; stages: {', '.join(STAGES)}")
        self.task, self.stage = task, stage
        self.path = checkpoint_path(task, stage, checkpoint_dir)
        self.model, self.meta = open_checkpoint(self.path, f"{TRAIN_SCRIPT} --tasks {task}", "docs/policies.md")
        if self.meta["task"] != task or self.meta["stage"] != stage:
            raise ValueError(f"{self.path} holds {self.meta['task']}/{self.meta['stage']}, not {task}/{stage}")
        if self.meta["feature_names"] != feature_names(task):
            raise ValueError(f"{self.path} was trained on other state features than this code computes")
        self.ref_length = float(self.meta["expert_mean_length"])
        self._platform = None
        self._limits = np.asarray(self.meta["arm_limits"], dtype=np.float64)  # (7, 2) rad
        self.goal: np.ndarray | None = None  # the goal of the current episode of the own platform
        self.observations: list = []  # the T+1 observations of the last trajectory() (frame 0 = after reset)

    # -- lifecycle ---------------------------------------------------------------------------------
    @property
    def platform(self):
        if self._platform is None:
            from wsp_data.platforms.maniskill.env import ManiSkillPlatform
            from wsp_data.platforms.maniskill.experts import task_spec

            self._platform = ManiSkillPlatform(self.task, render=False, objects=task_spec(self.task).objects)
        return self._platform

    def close(self) -> None:
        if self._platform is not None:
            self._platform.close()
            self._platform = None

    def __enter__(self) -> PolicySource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- acting ------------------------------------------------------------------------------------
    def act(self, observation, step: int = 0, goal: np.ndarray | None = None) -> np.ndarray:
        """The deterministic (8,) float32 `pd_joint_pos` action for an observation at `step` of an episode.
        `goal` (PickCube, PushCube, PullCube) defaults to the goal of the own platform's current episode."""
        if goal is None and self.task in GOAL_ATTR:
            if self.goal is None:
                raise ValueError(f"{self.task} needs a goal: pass goal= or run trajectory() first")
            goal = self.goal
        x = torch.from_numpy(features(self.task, observation, step, goal, self.ref_length))[None]
        with torch.no_grad():
            y = self.model(x)[0].double().numpy()
        arm = np.asarray(observation.qpos, dtype=np.float64)[:7] + y[:7]
        arm = np.clip(arm, self._limits[:, 0], self._limits[:, 1])
        grip = 1.0 if y[7] >= 0 else -1.0
        return np.array([*arm, grip], dtype=np.float32)

    def default_max_steps(self) -> int:
        return int(math.ceil(MAX_STEPS_FACTOR * self.ref_length))

    def trajectory(self, seed: int, max_steps: int | None = None, settle: int = SETTLE_STEPS
                   ) -> tuple[np.ndarray, bool]:
        """Run the policy closed-loop from `reset(seed)` until success has held `settle` consecutive steps or
        `max_steps` (default 1.5 × the expert's mean length) ran out. Returns the executed (T, 8) float32
        stream and whether the last step ends in success; `observations` keeps the T+1 states it went through."""
        max_steps = self.default_max_steps() if max_steps is None else int(max_steps)
        p = self.platform
        ob = p.reset(seed)
        self.goal = read_goal(p, self.task)
        self.observations = [ob]
        actions, held = [], 0
        for t in range(max_steps):
            a = self.act(ob, t)
            actions.append(a)
            ob = p.step(a)
            self.observations.append(ob)
            held = held + 1 if ob.success else 0
            if held >= settle:
                break
        return np.stack(actions).astype(np.float32), bool(ob.success)

    # -- provenance --------------------------------------------------------------------------------
    @property
    def provenance(self) -> dict:
        m = self.meta
        return {
            "kind": "bc_policy",  # behaviour-cloned policy
            "task": self.task, "stage": self.stage,
            "checkpoint": self.path.name, "checkpoint_sha256": sha256(self.path),
            "training_steps": m["training_steps"], "total_training_steps": m["total_training_steps"],
            "success_rate": m.get("success", {}).get("rate"),
            "success_seeds": m.get("success", {}).get("seeds"),
            "success_successes": m.get("success", {}).get("successes"),
            "max_steps": self.default_max_steps(),
            "training_config": m["training_config"],
        }
