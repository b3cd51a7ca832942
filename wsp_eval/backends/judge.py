"""The T5 primitive judge contract (spec §4.5): what every judge backend sees and returns.

A judge sees `JUDGE_FRAMES` = 12 frames sampled uniformly over the generated clip (`sample_frames`), the
frame-0 position of the evaluated object in the 256×256 scoring frame (the release stores it; every model
shares frame 0), the eight primitive specifications (`PRIMITIVE_SPECS`) and the platform the clip comes from
(`maniskill`, `libero`, `aloha`: a property of the release's config, as the robot in the frames is; the learned
judge keeps weights per platform). It never sees the action stream, the intended label or the model's name.
It returns a `Verdict`: one primitive label (None when its answer could not be parsed, which scores 0) and two
booleans (agent motion matches the label's specification, object motion matches it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

JUDGE_FRAMES = 12
PRIMITIVES = ("push", "pull", "drag", "rotate", "shake", "tap", "knock-over", "drop")
PRIMITIVE_SPECS = {
    "push": "The gripper, closed, comes into planar side contact with the object and pushes it across the "
            "table, away from the robot; the object slides along the table surface without being lifted.",
    "pull": "The gripper, closed, hooks the far side of the object and draws it across the table toward the "
            "robot base; the object slides without being grasped or lifted.",
    "drag": "The gripper grasps the object from the top and drags it sideways along the table surface, "
            "keeping it low (not lifted more than a few centimetres), then releases it.",
    "rotate": "The gripper grasps the object from the top and turns it in place about the vertical axis; "
              "the object rotates but stays at the same spot on the table.",
    "shake": "The gripper grasps the object, lifts it slightly, and shakes it back and forth sideways three "
             "times (several direction reversals), then sets it down.",
    "tap": "The closed gripper briefly presses against the object and retracts at once; the object (a ball) "
           "moves away by itself after the short contact.",
    "knock-over": "The closed gripper hits a tall object high on its side; the object tips over and ends "
                  "lying on the table.",
    "drop": "The gripper grasps the object, lifts it clearly above the table, and opens; the object falls "
            "back down onto the table.",
}


@dataclass(frozen=True)
class Verdict:
    """A judge's answer for one clip. `label` is None when the answer could not be parsed."""

    label: str | None
    agent_ok: bool
    object_ok: bool
    evidence: dict = field(default_factory=dict)  # judge-specific reasons or the raw answer, for reports

    def __post_init__(self):
        if self.label is not None and self.label not in PRIMITIVES:
            raise ValueError(f"unknown primitive label {self.label!r}; known: {', '.join(PRIMITIVES)}")


class Judge(Protocol):
    """A primitive judge backend."""

    name: str
    version: str

    def judge(self, frames: np.ndarray, object_px: tuple[float, float], platform: str | None = None) -> Verdict:
        """`frames`: (12, H, W, 3) uint8 RGB; `object_px`: the object's frame-0 (x, y) in the 256² frame;
        `platform`: the config's platform (a judge may ignore it)."""


def frame_indices(num_frames: int, k: int = JUDGE_FRAMES) -> np.ndarray:
    """`k` frame indices spread uniformly from the first to the last frame (repeats when the clip is short)."""
    if num_frames < 1:
        raise ValueError("a clip needs at least one frame")
    return np.round(np.linspace(0, num_frames - 1, k)).astype(int)


def sample_frames(video: np.ndarray, k: int = JUDGE_FRAMES) -> np.ndarray:
    """The `k` frames a judge sees."""
    return np.asarray(video)[frame_indices(len(video), k)]


def score_verdict(verdict: Verdict, intended: str) -> float:
    """S = 100·1[label = intended]·1[agent ok]·1[object ok]."""
    return 100.0 * float(verdict.label == intended and verdict.agent_ok and verdict.object_ok)
