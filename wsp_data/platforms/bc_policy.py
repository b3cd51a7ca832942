"""Behaviour-cloned policy sources for T3, one base class for every platform: a checkpoint (task × stage) of a
small state → action MLP (`bc_model`), run closed-loop in the platform's own state-only simulator until success
has held `SETTLE_STEPS` consecutive steps or `MAX_STEPS_FACTOR` × the expert's mean length ran out.

A platform subclasses `BCPolicySource` with what differs: its name, tasks and checkpoint paths (class
attributes), its state features (`feature_names`) and, in `act`, how an observation becomes the network's
input and the network's output an action; `open_platform` opens its simulator, `on_reset` reads what an
episode's observation lacks (ManiSkill's goals). `stream(seed)` is the T3 source protocol
(`wsp_data.platforms.t3_sources`). Every platform's checkpoints are trained by `TRAIN_SCRIPT --platform NAME`.
Torch is imported only when a checkpoint is opened.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wsp_data.platforms.t3_sources import SourceStream
from wsp_eval.integrity import sha256

STAGES = ("early", "late")  # the checkpoint kept at 10 % of training, and the final one
TRAINING_CONFIG = "training_config.json"  # the training record beside a platform's checkpoints
SETTLE_STEPS = 5  # a policy rollout stops once success has held this many consecutive steps
MAX_STEPS_FACTOR = 1.5  # a policy's default step budget: this × the expert's mean trajectory length
TRAIN_SCRIPT = "scripts/train_bc_policies.py"  # trains every platform's checkpoints (`--platform NAME`)
DOCS = "docs/guides/policies.md"  # the policies' recipes and measured success


class PolicyCheckpointMissing(FileNotFoundError):
    """A policy checkpoint that is not on disk."""


def rot6d(q) -> np.ndarray:
    """A unit quaternion (wxyz) as the first two columns of its rotation matrix (continuous, sign-free)."""
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y),  # column 0
        2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x),  # column 1
    ], dtype=np.float64)


def open_checkpoint(path: Path, rebuild: str, docs: str):
    """Load a policy checkpoint (model, metadata), or raise PolicyCheckpointMissing naming the path and the
    rebuild command."""
    if not Path(path).is_file():
        raise PolicyCheckpointMissing(f"policy checkpoint {path} is missing; rebuild it with `.venv/bin/python "
                                      f"{rebuild}` (see {docs})")
    from wsp_data.platforms.bc_model import load_checkpoint

    return load_checkpoint(Path(path))


class BCPolicySource(ABC):
    """One behaviour-cloned checkpoint (task × stage), run closed-loop in a state-only simulator of its platform.

    Class attributes: `PLATFORM` (the provenance's platform, and `TRAIN_SCRIPT`'s `--platform`), `TASKS` (tasks
    with checkpoints), `checkpoint_path` ((task, stage, directory) → path)."""

    PLATFORM: str
    TASKS: tuple[str, ...]
    checkpoint_path: Callable[..., Path]

    def __init__(self, task: str, stage: str, checkpoint_dir: Path | str | None = None, simulator=None):
        if task not in self.TASKS:
            raise KeyError(f"no policy for task {task!r}; T3 tasks: {', '.join(self.TASKS)}")
        if stage not in STAGES:
            raise KeyError(f"unknown policy stage {stage!r}; stages: {', '.join(STAGES)}")
        self.task, self.stage = task, stage
        self.path = type(self).checkpoint_path(task, stage, checkpoint_dir)
        self.model, self.meta = open_checkpoint(
            self.path, f"{TRAIN_SCRIPT} --platform {self.PLATFORM} --tasks {task}", DOCS)
        if self.meta["task"] != task or self.meta["stage"] != stage:
            raise ValueError(f"{self.path} holds {self.meta['task']}/{self.meta['stage']}, not {task}/{stage}")
        if self.meta["feature_names"] != self.feature_names():
            raise ValueError(f"{self.path} was trained on other state features than this code computes")
        self.ref_length = float(self.meta["expert_mean_length"])
        self._platform, self._owns = simulator, simulator is None  # a given simulator stays open at `close`
        self.observations: list = []  # the T+1 observations of the last trajectory() (frame 0 = after reset)

    # -- what a platform provides --------------------------------------------------------------------
    @abstractmethod
    def feature_names(self) -> list[str]:
        """The names of the policy's input features for this task (checked against the checkpoint's)."""

    @abstractmethod
    def open_platform(self):
        """A state-only (unrendered) simulator of this task."""

    @abstractmethod
    def act(self, observation, step: int) -> np.ndarray:
        """The deterministic float32 action for an observation at `step` of an episode."""

    def on_reset(self, observation) -> None:
        """Called after each reset of the own simulator, before the first action (default: nothing)."""

    # -- lifecycle -----------------------------------------------------------------------------------
    @property
    def platform(self):
        if self._platform is None:
            self._platform = self.open_platform()
        return self._platform

    def close(self) -> None:
        if self._owns and self._platform is not None:
            self._platform.close()
        self._platform = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- running -------------------------------------------------------------------------------------
    def network(self, x: np.ndarray) -> np.ndarray:
        """The network's raw output (float64) for one feature vector."""
        import torch

        with torch.no_grad():
            return self.model(torch.from_numpy(np.asarray(x, np.float32))[None])[0].double().numpy()

    def default_max_steps(self) -> int:
        return int(math.ceil(MAX_STEPS_FACTOR * self.ref_length))

    def trajectory(self, seed: int, max_steps: int | None = None, settle: int = SETTLE_STEPS
                   ) -> tuple[np.ndarray, bool]:
        """Run the policy closed-loop from `reset(seed)` until success has held `settle` consecutive steps or
        `max_steps` (default `default_max_steps`) ran out. Returns the executed (T, action dim) float32 stream
        and whether the last step ends in success; `observations` keeps the T+1 states it went through."""
        max_steps = self.default_max_steps() if max_steps is None else int(max_steps)
        ob = self.platform.reset(seed)
        self.on_reset(ob)
        self.observations = [ob]
        actions, held = [], 0
        for t in range(max_steps):
            a = self.act(ob, t)
            actions.append(a)
            ob = self.platform.step(a)
            self.observations.append(ob)
            held = held + 1 if ob.success else 0
            if held >= settle:
                break
        return np.stack(actions).astype(np.float32), bool(ob.success)

    def stream(self, seed: int) -> SourceStream:
        """The T3 source protocol: `trajectory(seed)`'s stream (success or not) and the provenance."""
        actions, _ = self.trajectory(seed)
        return SourceStream(actions, self.provenance)

    @property
    def provenance(self) -> dict:
        """What made this source's streams (stored as the T3 row's `source_provenance`)."""
        m = self.meta
        success = m.get("success", {})
        return {"kind": "bc_policy", "platform": self.PLATFORM, "task": self.task, "stage": self.stage,
                "checkpoint": self.path.name, "checkpoint_sha256": sha256(self.path),
                "training_steps": m["training_steps"], "total_training_steps": m["total_training_steps"],
                "success_rate": success.get("rate"), "success_seeds": success.get("seeds"),
                "success_successes": success.get("successes"), "max_steps": self.default_max_steps(),
                "training_config": m["training_config"]}


def closed_loop_success(source: BCPolicySource, seeds: list[int]) -> tuple[dict, list[np.ndarray]]:
    """A policy source's closed-loop success over `seeds` (each rollout from its own `reset(seed)`; the source
    is closed after): the summary the trainer (`TRAIN_SCRIPT`) records, and every rollout's action stream."""
    ok, streams = [], []
    try:
        for s in seeds:
            actions, success = source.trajectory(s)
            ok.append(success)
            streams.append(actions)
    finally:
        source.close()
    return {"rate": round(float(np.mean(ok)), 4), "successes": int(np.sum(ok)), "seeds": len(seeds),
            "seed_range": [seeds[0], seeds[-1]], "mean_steps": round(float(np.mean([len(a) for a in streams])), 1),
            "max_steps": source.default_max_steps()}, streams
