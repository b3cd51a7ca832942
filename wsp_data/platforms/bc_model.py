"""The behaviour-cloning model every platform's T3 policies use: an MLP from normalised state features to the
normalised action target, trained with AdamW and a cosine schedule on the CPU (`fit` with a `FitConfig`; fixed
seeds, and the trainer `scripts/train_bc_policies.py` runs it on one thread with deterministic algorithms: a
retraining gives the same checkpoint), saved as float32 weights plus JSON metadata."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from wsp_data.schema import ACTION_DIM


@dataclass(frozen=True)
class FitConfig:
    """How `fit` trains: seeds, steps, batch and optimiser, network width, and the floor of the
    standardisation's standard deviations."""

    seed: int  # torch's global seed and the batch sampler's generator
    steps: int  # training steps of the late (final) model
    early_steps: int  # the step after which the early model is kept
    batch: int  # samples per step, drawn uniformly with replacement
    lr: float  # AdamW's peak learning rate (cosine decay to 0 over `steps`)
    weight_decay: float
    hidden: tuple[int, ...]  # hidden layer widths
    std_floor: float  # lower bound of every feature's and target's standard deviation


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


def fit(X: np.ndarray, Y: np.ndarray, cfg: FitConfig, log: Callable[[str], None]
        ) -> tuple[MLPPolicy, MLPPolicy, list[float]]:
    """AdamW + cosine decay on MSE of normalised targets; returns (early, late) models and a loss log."""
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    x, y = torch.from_numpy(X), torch.from_numpy(Y)
    model = MLPPolicy(X.shape[1], tuple(cfg.hidden), Y.shape[1])
    model.x_mean.copy_(x.mean(0))
    model.x_std.copy_(x.std(0).clamp_min(cfg.std_floor))
    model.y_mean.copy_(y.mean(0))
    model.y_std.copy_(y.std(0).clamp_min(cfg.std_floor))
    yn = (y - model.y_mean) / model.y_std
    opt = torch.optim.AdamW(model.net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.5 * (1 + np.cos(np.pi * min(s, cfg.steps) / cfg.steps)))
    early, losses, running = None, [], 0.0
    for step in range(1, cfg.steps + 1):
        idx = torch.randint(len(x), (cfg.batch,), generator=gen)
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
        if step == cfg.early_steps:
            early = MLPPolicy(X.shape[1], tuple(cfg.hidden), Y.shape[1])
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

