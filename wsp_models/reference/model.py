"""The reference world model as a batched `wsp generate` model (`wsp generate --model reference`).

Loads every checkpoint in `checkpoints/` (one per platform) and answers each request with the checkpoint whose
action width matches the request's (8: ManiSkill joint targets, 7: LIBERO OSC deltas). Frame t is drawn from
frame 0 and the actions before t; frame 0 is the given first frame. The model is deterministic: the generation
seed does not change its output (the three seeds of a submission are three identical videos).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch

from wsp_eval.generate import GenerateError
from wsp_models.reference.network import NetConfig, ReferenceNet, condition
from wsp_serve.callables import Request

CHECKPOINTS = Path(__file__).parent / "checkpoints"
CHUNK = 32  # frames per forward pass
THREADS = 2


class ReferenceModel:
    wsp_batch_size = 4

    def __init__(self, checkpoints: Path = CHECKPOINTS, threads: int = THREADS):
        torch.set_num_threads(threads)
        self.nets: dict[int, tuple[ReferenceNet, np.ndarray, np.ndarray, dict]] = {}
        for path in sorted(Path(checkpoints).glob("*.pt")):
            ckpt = torch.load(path, map_location="cpu", weights_only=False)
            net = ReferenceNet(NetConfig(**ckpt["record"]["net"]))
            net.load_state_dict(ckpt["state_dict"])
            net.eval()
            self.nets[ckpt["record"]["data"]["action_dim"]] = (net, ckpt["feature_mean"], ckpt["feature_std"],
                                                               ckpt["record"])
        if not self.nets:
            raise GenerateError(f"{checkpoints}: no reference-model checkpoint (*.pt); train one with "
                                "scripts/train_reference_model.py")
        self.wsp_info = {"reference_model": {r["platform"]: _summary(r) for *_, r in self.nets.values()},
                         "generation_threads": threads}

    def __call__(self, requests: list[Request]) -> list[np.ndarray]:
        return [self.generate(r) for r in requests]

    @torch.no_grad()
    def generate(self, request: Request) -> np.ndarray:
        first, actions, fps, _seed = request
        width = actions.shape[1]
        if width not in self.nets:
            raise GenerateError(f"reference model: no checkpoint for {width}-wide actions "
                                f"(have: {', '.join(f'{r['platform']} ({d})' for d, (*_, r) in self.nets.items())})")
        net, mean, std, _ = self.nets[width]
        size = net.cfg.size
        h, w = first.shape[:2]
        frame0 = first if (h, w) == (size, size) else cv2.resize(first, (size, size), interpolation=cv2.INTER_AREA)
        feats = torch.from_numpy((condition(actions, fps) - mean) / std).float()
        x0 = torch.tensor(frame0).permute(2, 0, 1).float().div(255)[None]  # a copy: frame 0 may be read-only
        out = []
        for i in range(0, len(feats), CHUNK):
            f = feats[i:i + CHUNK]
            y = net(x0.expand(len(f), -1, -1, -1), f)
            out.append((y.clamp(0, 1) * 255).round().byte().permute(0, 2, 3, 1).numpy())
        frames = np.concatenate(out)
        if (h, w) != (size, size):
            frames = np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_LINEAR) for f in frames])
        frames[0] = first
        return frames


def _summary(record: dict) -> dict:
    """What submission.json says of one checkpoint: its training record's identifying fields."""
    keys = ("format", "parameters", "torch", "train_seconds", "hardware")
    return {**{k: record[k] for k in keys}, "data_sha256": record["data"]["sha256"],
            "steps": record.get("step", record["recipe"]["steps"])}
