"""The reference world model's network: frame 0 and the action features of frame t → frame t.

A U-Net over frame 0 whose decoder is conditioned on the action features of the frame it draws: the features
are mapped to an 8×8 "pose map" joined to the bottleneck (so the network can place the robot in the image) and
to a per-channel scale and shift of every decoder stage (FiLM). The head draws RGB and a blend mask; the frame is
`mask · drawn + (1 − mask) · frame 0`, so what does not move is copied from frame 0 and sharp.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

# Action features of frame t (`condition`): the actions of frames t−1, t−2, t−4, t−8 (clamped at 0), the
# action integral over [0, t) in action·seconds, the first action, and t in seconds.
LAGS = (1, 2, 4, 8)


def condition(actions: np.ndarray, fps: float) -> np.ndarray:
    """Per-frame action features (T, 6·D + 1) float32 of an action stream (T, D): row t describes the actions
    that led to frame t (frame t follows the actions of frames 0 … t−1), so row 0 holds no action but the first."""
    a = np.asarray(actions, dtype=np.float64)
    t = np.arange(len(a))
    lagged = [a[np.maximum(t - k, 0)] for k in LAGS]
    integral = np.concatenate([np.zeros((1, a.shape[1])), np.cumsum(a, axis=0)[:-1]]) / fps
    first = np.repeat(a[:1], len(a), axis=0)
    return np.concatenate([*lagged, integral, first, (t / fps)[:, None]], axis=1).astype(np.float32)


@dataclass(frozen=True)
class NetConfig:
    features: int  # width of `condition`'s rows
    size: int = 128  # frames are size × size
    widths: tuple[int, ...] = (32, 64, 96, 128)  # encoder channels at size/2, /4, /8, /16
    pose: int = 32  # channels of the 8×8 pose map made from the action features
    head: int = 16  # channels at full resolution

    def as_dict(self) -> dict:
        return asdict(self)


class Block(nn.Module):
    """3×3 convolution, group norm, SiLU; optional FiLM (scale, shift per channel)."""

    def __init__(self, cin: int, cout: int, stride: int = 1):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, 3, stride, 1)
        self.norm = nn.GroupNorm(min(8, cout // 4), cout)

    def forward(self, x: torch.Tensor, film: torch.Tensor | None = None) -> torch.Tensor:
        x = self.norm(self.conv(x))
        if film is not None:
            scale, shift = film.chunk(2, dim=1)
            x = x * (1 + scale[:, :, None, None]) + shift[:, :, None, None]
        return F.silu(x)


class ReferenceNet(nn.Module):
    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg
        w = cfg.widths
        self.down = nn.ModuleList()
        cin = 3
        for c in w:
            self.down.append(nn.ModuleList([Block(cin, c, 2), Block(c, c)]))
            cin = c
        self.bottom = cfg.size // 2 ** len(w)
        self.embed = nn.Sequential(nn.Linear(cfg.features, 256), nn.SiLU(), nn.Linear(256, 256), nn.SiLU())
        self.pose = nn.Linear(256, cfg.pose * self.bottom ** 2)
        self.mid = Block(w[-1] + cfg.pose, w[-1])
        ups, films = nn.ModuleList(), nn.ModuleList()
        cin = w[-1]
        for skip, c in zip((*w[-2::-1], 3), (*w[-2::-1], cfg.head)):
            ups.append(Block(cin + skip, c))
            films.append(nn.Linear(256, 2 * c))
            cin = c
        self.ups, self.films = ups, films
        self.out = nn.Conv2d(cfg.head, 4, 3, 1, 1)

    def forward(self, frame0: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        """`frame0` (B, 3, S, S) in [0, 1], `features` (B, F) normalised → frames (B, 3, S, S) in [0, 1]."""
        skips, x = [frame0], frame0 * 2 - 1
        for conv_down, conv in self.down:
            x = conv(conv_down(x))
            skips.append(x)
        e = self.embed(features)
        pose = self.pose(e).view(-1, self.cfg.pose, self.bottom, self.bottom)
        x = self.mid(torch.cat([skips.pop(), pose], dim=1))
        for up, film in zip(self.ups, self.films):
            skip = skips.pop()
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = up(torch.cat([x, skip * 2 - 1 if skip.shape[1] == 3 else skip], dim=1), film(e))
        rgb, mask = self.out(x).split((3, 1), dim=1)
        mask = torch.sigmoid(mask)
        return mask * torch.sigmoid(rgb) + (1 - mask) * frame0
