"""Converting between the size and frame rate a served model generates at (its handshake) and the release's, once
per video, by the documented rules (docs/guides/model-server.md#resolution-and-frame-rate):

- **size**: the first frame is resized to the model's size and every returned frame back to the reference's, with
  `cv2.resize`, `INTER_AREA` when shrinking and `INTER_LINEAR` when enlarging (as the T4 tracker resizes);
- **frame rate**: the model is asked for the frames that cover the episode's duration at its rate, its action row
  k being the release's row nearest to time k / model fps, and frame j of the video is the model's frame nearest to
  time j / release fps (nearest by timestamp, ties to the earlier: the alignment rule of spec §4.1).

`Resampling.describe()` is what submission.json records (key "resampling") and what the report shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from wsp_eval.video import nearest_indices, timestamps
from wsp_serve.callables import Request

SIZE_METHOD = "cv2.resize, INTER_AREA when shrinking, INTER_LINEAR when enlarging (first frame to the model's size, " \
              "every frame back to the reference's)"
RATE_METHOD = "nearest by timestamp (spec §4.1): the model's action rows sampled at its rate, the video's frames " \
              "taken from the model's nearest frame"


@dataclass
class Resampling:
    """The model's declared size (width, height) and fps, None where it generates at the release's; `resized` and
    `retimed` collect the reference sizes and release rates actually converted."""
    size: tuple[int, int] | None = None
    fps: float | None = None
    resized: set[tuple[int, int]] = field(default_factory=set)
    retimed: set[float] = field(default_factory=set)

    def request(self, request: Request) -> Request:
        """The release's request as the model is asked: its first frame at the model's size, its actions at the
        model's rate (and that rate as fps)."""
        frame, actions, fps = request.first_frame, request.actions, request.fps
        if self.size is not None and frame.shape[1::-1] != self.size:
            self.resized.add(frame.shape[1::-1])
            frame = resize(frame, self.size)
        if self.fps is not None and self.fps != fps:
            self.retimed.add(fps)
            n = model_frames(len(actions), fps, self.fps)
            actions = np.ascontiguousarray(actions[_nearest(len(actions), fps, n, self.fps)])
            fps = self.fps
        return Request(frame, actions, fps, request.seed)

    def frames(self, frames: np.ndarray, num_frames: int, fps: float, size: tuple[int, int]) -> np.ndarray:
        """The model's (N, H', W', 3) uint8 `frames` as the release's `num_frames` frames at `fps`, (H, W) = `size`."""
        if self.fps is not None and self.fps != fps:
            frames = frames[_nearest(len(frames), self.fps, num_frames, fps)]
        if frames.shape[1:3] != tuple(size):
            frames = np.stack([resize(f, (size[1], size[0])) for f in frames])
        return frames

    def describe(self) -> dict | None:
        """What submission.json and the report say about the conversions made; None when there were none."""
        out = {}
        if self.resized:
            out["size"] = {"model": list(self.size), "reference": sorted(map(list, self.resized)),
                           "method": SIZE_METHOD}
        if self.retimed:
            out["fps"] = {"model": self.fps, "release": sorted(self.retimed), "method": RATE_METHOD}
        return out or None


def resize(frame: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """`frame` resized to `size` = (width, height): area averaging when shrinking, bilinear when enlarging."""
    shrink = size[0] * size[1] < frame.shape[0] * frame.shape[1]
    return cv2.resize(frame, size, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def model_frames(num_frames: int, fps: float, model_fps: float) -> int:
    """Frames at `model_fps` that cover the duration of `num_frames` frames at `fps` (frame 0 at t = 0)."""
    return math.ceil((num_frames - 1) * model_fps / fps - 1e-9) + 1


def _nearest(source_count: int, source_fps: float, target_count: int, target_fps: float) -> np.ndarray:
    if source_count == 1:
        return np.zeros(target_count, dtype=int)
    return nearest_indices(timestamps(source_count, source_fps), timestamps(target_count, target_fps))
