"""Train the reference world model on a `train_<platform>` split: deterministic (fixed seed, fixed thread count,
torch's deterministic algorithms), resumable (a training state every `SAVE_EVERY` steps), with a loss history,
and optional snapshots: the weights at chosen steps of the same run (the known-ordering check of
`scripts/known_ordering.py`), which do not change the run.

Each step draws `batch` (episode, frame t ≥ 1) pairs uniformly from the training episodes and regresses frame t
from frame 0 and the action features of t (`network.condition`) with an L1 loss weighted `1 + CHANGED_WEIGHT`
on pixels that differ from frame 0 (the robot and what it moves: a few percent of the image, all of the task).
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from wsp_eval.console import terminal
from wsp_models.reference.data import Episodes, load_split
from wsp_models.reference.network import NetConfig, ReferenceNet

CHANGED_WEIGHT = 10.0  # extra loss weight of pixels that differ from frame 0 by more than CHANGED_LEVEL
CHANGED_LEVEL = 10 / 255
SAVE_EVERY = 250  # steps between training states (resume loses at most this many)
LOG_EVERY = 25  # steps per logged training loss (their mean)
VAL_EVERY = 250  # steps between validation losses
VAL_SAMPLES = 96  # fixed (episode, frame) pairs of the held-out episodes
FORMAT = 1  # checkpoint format


@dataclass(frozen=True)
class Recipe:
    steps: int = 5000
    batch: int = 16
    lr: float = 2e-3
    weight_decay: float = 1e-4
    seed: int = 0
    threads: int = 2
    size: int = 128


def _sample(episodes: Episodes, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    idx = rng.integers(0, len(episodes), size=n)
    ts = [int(rng.integers(1, len(episodes.frames[i]))) for i in idx]
    frame0 = np.stack([episodes.frames[i][0] for i in idx])
    target = np.stack([episodes.frames[i][t] for i, t in zip(idx, ts)])
    feats = np.stack([episodes.features[i][t] for i, t in zip(idx, ts)])
    return frame0, target, feats


def _tensors(frame0, target, feats, mean, std):
    def img(a):
        return torch.from_numpy(a).permute(0, 3, 1, 2).float().div_(255)
    return img(frame0), img(target), torch.from_numpy((feats - mean) / std).float()


def weighted_l1(pred: torch.Tensor, target: torch.Tensor, frame0: torch.Tensor) -> torch.Tensor:
    changed = ((target - frame0).abs().amax(dim=1, keepdim=True) > CHANGED_LEVEL).float()
    return ((pred - target).abs() * (1 + CHANGED_WEIGHT * changed)).mean()


def train(release: Path, config: str, out: Path, recipe: Recipe = Recipe(), progress: bool = True,
          snapshots: Sequence[int] = ()) -> Path:
    """Train on `release/config`; write `out/<platform>.pt` (weights and everything needed to run them) and
    `out/<platform>.history.json`, and the same two files in `out/step<N>/` at every step N of `snapshots`
    below `recipe.steps`; resume from `out/.train_state.pt` when it holds a run of the same recipe.
    Returns the checkpoint's path."""
    if bad := [n for n in snapshots if not 0 < n < recipe.steps or n % VAL_EVERY]:
        raise ValueError(f"snapshot step {bad[0]}: must be a multiple of {VAL_EVERY} (a validation loss) below the "
                         f"run's {recipe.steps} steps")
    torch.manual_seed(recipe.seed)
    torch.set_num_threads(recipe.threads)
    torch.use_deterministic_algorithms(True)
    train_eps, val_eps, facts = load_split(release, config, recipe.size, progress)
    all_feats = np.concatenate(train_eps.features)
    mean, std = all_feats.mean(0), all_feats.std(0) + 1e-3
    cfg = NetConfig(features=all_feats.shape[1], size=recipe.size)
    net = ReferenceNet(cfg)
    opt = torch.optim.AdamW(net.parameters(), lr=recipe.lr, weight_decay=recipe.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=recipe.lr, total_steps=recipe.steps, pct_start=0.05)
    rng = np.random.default_rng(recipe.seed)
    val = _tensors(*_sample(val_eps, VAL_SAMPLES, np.random.default_rng(recipe.seed + 1)), mean, std)
    history = {"train": [], "val": []}
    step, seconds = 0, 0.0
    out.mkdir(parents=True, exist_ok=True)
    state_path = out / ".train_state.pt"
    key = {"recipe": recipe.__dict__, "data": facts["sha256"]}
    if state_path.is_file():
        state = torch.load(state_path, weights_only=False)
        if state["key"] == key:
            net.load_state_dict(state["net"])
            opt.load_state_dict(state["opt"])
            sched.load_state_dict(state["sched"])
            rng.bit_generator.state = state["rng"]
            torch.set_rng_state(state["torch_rng"])
            history, step, seconds = state["history"], state["step"], state["seconds"]
    running: list[float] = []
    with tqdm(total=recipe.steps, initial=step, desc=f"train {config}", unit="step", disable=not progress,
              file=terminal()) as bar:
        while step < recipe.steps:
            start = time.perf_counter()
            frame0, target, feats = _tensors(*_sample(train_eps, recipe.batch, rng), mean, std)
            loss = weighted_l1(net(frame0, feats), target, frame0)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
            opt.step()
            sched.step()
            step += 1
            seconds += time.perf_counter() - start
            running.append(loss.item())
            if step % LOG_EVERY == 0:
                history["train"].append([step, float(np.mean(running))])
                bar.set_postfix(loss=f"{np.mean(running):.4f}")
                running = []
            if step % VAL_EVERY == 0 or step == recipe.steps:
                history["val"].append([step, _val_loss(net, val)])
            if step in snapshots:
                _write_checkpoint(out / f"step{step}", config, net, mean, std, facts, recipe, history, seconds, step)
            if step % SAVE_EVERY == 0 and step < recipe.steps:
                tmp = state_path.with_suffix(".partial")
                torch.save({"key": key, "net": net.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                            "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(), "history": history,
                            "step": step, "seconds": seconds}, tmp)
                os.replace(tmp, state_path)
            bar.update()
    ckpt = _write_checkpoint(out, config, net, mean, std, facts, recipe, history, seconds, step)
    state_path.unlink(missing_ok=True)
    return ckpt


def _write_checkpoint(folder: Path, config: str, net: ReferenceNet, mean: np.ndarray, std: np.ndarray, facts: dict,
                      recipe: Recipe, history: dict, seconds: float, step: int) -> Path:
    """`folder/<platform>.pt` and its `.history.json` of the weights after `step` steps (a snapshot's record says
    its `step`; the history is the run's so far)."""
    platform_name = config.removeprefix("train_")
    record = {"format": FORMAT, "platform": platform_name, "data": facts, "recipe": recipe.__dict__,
              "net": net.cfg.as_dict(), "parameters": sum(p.numel() for p in net.parameters()),
              "train_seconds": round(seconds, 1), "torch": torch.__version__,
              "hardware": f"{platform.processor() or platform.machine()}, {recipe.threads} threads",
              "final_val_loss": history["val"][-1][1]}
    if step != recipe.steps:
        record["step"] = step
    folder.mkdir(parents=True, exist_ok=True)
    ckpt = folder / f"{platform_name}.pt"
    torch.save({"record": record, "state_dict": net.state_dict(), "feature_mean": mean, "feature_std": std}, ckpt)
    (folder / f"{platform_name}.history.json").write_text(json.dumps({"record": record, **history}, indent=1))
    return ckpt


@torch.no_grad()
def _val_loss(net: ReferenceNet, val) -> float:
    net.eval()
    frame0, target, feats = val
    losses = [weighted_l1(net(frame0[i:i + 32], feats[i:i + 32]), target[i:i + 32], frame0[i:i + 32]).item()
              for i in range(0, len(frame0), 32)]
    net.train()
    return float(np.mean(losses))
