"""T4's presence rule (spec §4.4): the still evaluated object must still be drawn as the reference draws it.

The tracker places the object; it cannot tell an object that stays where it stood from one that fades out or
smears away there (the place keeps its last value). Presence compares the object's *contrast* with its
surroundings in the generated frame against the reference's, at the simulator's exact object mask, frame by frame:

- In reference frame t, the object's pixels are its segmentation mask less the robot's; its surroundings are the
  ring `RING` px (per 128 px of frame height) outside its frame-0 mask, less the robot and every other object.
  Its contrast v*_t is the difference of their mean CIE Lab colours. A frame is *evaluable* when at least
  `VISIBLE_MIN` of the frame-0 object area is in sight and ‖v*_t‖ ≥ `CONTRAST_MIN` ΔE.
- In the generated frame, the same two pixel sets are moved by the tracker's displacement of the object (so an
  object drawn a few pixels off, which T4's d allows, is measured where it is drawn), each within ±`SLACK` px;
  v_t is their colour difference there and p_t = max over those positions of ⟨v_t, v*_t⟩ / ‖v*_t‖²: 1 when the
  object stands out as in the reference, 0 when it is gone (its place looks like its surroundings).
- Presence P is the smallest, over every window of `WINDOW_SECONDS` with at least half of its frames evaluable,
  of the median p_t over those frames; no such window: P = 1 (nothing to hold against the video). The rule
  passes when P ≥ `KEEP`.

Why a window median: a generated arm that passes a little wider than the reference's covers the object for a few
frames; an object that is gone for a second is gone.
"""

from __future__ import annotations

import base64
import zlib
from dataclasses import dataclass

import cv2
import numpy as np

from wsp_eval.tracking import to_lab

RING = (2.0, 6.0)  # px per 128 px of frame height: the surroundings lie this far outside the frame-0 mask
VISIBLE_MIN = 0.5  # share of the frame-0 object area in sight for a reference frame to count
CONTRAST_MIN = 8.0  # CIE76 ΔE: a reference frame whose object stands out less than this does not count
SLACK = 1  # px: the generated sets are also tried this far around the tracked displacement
WINDOW_SECONDS = 1.0
KEEP = 0.4  # presence at which the rule passes: between the largest tracked fading or smearing stand-in (0.38)
#   and the smallest blurred still object (0.45) of the training-range design sets (docs/validity.md, T4 tracker)


@dataclass
class PresenceReference:
    """The reference side, per frame: the object's and its surroundings' pixel coordinates (rows, cols) and the
    reference contrast v*_t (Lab, float32 as `to_lab` gives it); `None` where the frame is not evaluable."""

    frames: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None]
    shape: tuple[int, int]
    window: int

    def to_record(self) -> dict:
        """JSON-ready (the reference-result cache keeps it): per frame null or the two pixel sets as bit-packed,
        compressed masks of the frame with v*_t; `from_record` gives back the same coordinates in the same order."""
        frames = [None if e is None else {"in": _pack(e[0], self.shape), "around": _pack(e[1], self.shape),
                                          "v": [float(x) for x in e[2]]} for e in self.frames]
        return {"frames": frames, "shape": list(self.shape), "window": self.window}

    @classmethod
    def from_record(cls, record: dict) -> PresenceReference:
        shape = (int(record["shape"][0]), int(record["shape"][1]))
        frames = [None if e is None else (_unpack(e["in"], shape), _unpack(e["around"], shape),
                                          np.asarray(e["v"], np.float32)) for e in record["frames"]]
        return cls(frames, shape, int(record["window"]))


def _pack(rows_cols: np.ndarray, shape: tuple[int, int]) -> str:
    mask = np.zeros(shape, bool)
    mask[rows_cols[0], rows_cols[1]] = True
    return base64.b64encode(zlib.compress(np.packbits(mask).tobytes())).decode("ascii")


def _unpack(text: str, shape: tuple[int, int]) -> np.ndarray:
    bits = np.unpackbits(np.frombuffer(zlib.decompress(base64.b64decode(text)), np.uint8), count=shape[0] * shape[1])
    return np.stack(np.nonzero(bits.reshape(shape)))


def _disc(radius: float) -> np.ndarray:
    r = max(1, int(round(radius)))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def presence_reference(frames: np.ndarray, obj: np.ndarray, robot: np.ndarray, others: np.ndarray,
                       fps: float) -> PresenceReference:
    """`frames` (T, H, W, 3) the reference; `obj`, `robot`, `others` (T, H, W) bool: the evaluated object's mask,
    the robot's, every other object's."""
    h = frames.shape[1]
    scale = h / 128.0
    m0 = obj[0].astype(np.uint8)
    ring = (cv2.dilate(m0, _disc(RING[1] * scale)) > 0) & ~(cv2.dilate(m0, _disc(RING[0] * scale)) > 0)
    area0 = max(int((obj[0] & ~robot[0]).sum()), int(obj[0].sum()))
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
    for t, frame in enumerate(frames):
        inside = obj[t] & ~robot[t]
        around = ring & ~robot[t] & ~others[t] & ~obj[t]
        if area0 == 0 or inside.sum() < VISIBLE_MIN * area0 or not around.any():
            out.append(None)
            continue
        image = to_lab(frame)
        pin, pout = np.nonzero(inside), np.nonzero(around)
        v = image[pin].mean(axis=0) - image[pout].mean(axis=0)
        out.append((np.stack(pin), np.stack(pout), v) if np.linalg.norm(v) >= CONTRAST_MIN else None)
    return PresenceReference(out, frames.shape[1:3], max(1, int(round(WINDOW_SECONDS * fps))))


def _contrast(image: np.ndarray, pin: np.ndarray, pout: np.ndarray, dy: int, dx: int) -> np.ndarray | None:
    h, w = image.shape[:2]
    a, b = pin + np.array([[dy], [dx]]), pout + np.array([[dy], [dx]])
    ka = (a[0] >= 0) & (a[0] < h) & (a[1] >= 0) & (a[1] < w)
    kb = (b[0] >= 0) & (b[0] < h) & (b[1] >= 0) & (b[1] < w)
    if not ka.any() or not kb.any():
        return None
    return image[a[0][ka], a[1][ka]].mean(axis=0) - image[b[0][kb], b[1][kb]].mean(axis=0)


def frame_presence(frames: np.ndarray, ref: PresenceReference, shifts: np.ndarray) -> np.ndarray:
    """p_t per frame (NaN where the reference frame is not evaluable); `frames` the generated video, resized to the
    reference's size where it differs; `shifts` (T, 2) the tracked displacement (dx, dy) of the object from frame 0,
    in the reference's px."""
    if len(frames) != len(ref.frames):
        raise ValueError(f"presence: a video of {len(frames)} frames against a reference of {len(ref.frames)}")
    p = np.full(len(frames), np.nan)
    for t, entry in enumerate(ref.frames):
        if entry is None:
            continue
        pin, pout, v = entry
        frame = frames[t]
        if frame.shape[:2] != ref.shape:
            frame = cv2.resize(frame, ref.shape[::-1], interpolation=cv2.INTER_AREA)
        image = to_lab(frame)
        cx, cy = (int(round(s)) for s in shifts[t])
        best = -np.inf
        for dy in range(cy - SLACK, cy + SLACK + 1):
            for dx in range(cx - SLACK, cx + SLACK + 1):
                g = _contrast(image, pin, pout, dy, dx)
                if g is not None:
                    best = max(best, float(g @ v) / float(v @ v))
        p[t] = best if np.isfinite(best) else 0.0
    return p


def presence(p: np.ndarray, window: int) -> float:
    """P: the smallest window median of p over windows at least half evaluable; 1 when there is none."""
    out = 1.0
    for i in range(max(1, len(p) - window + 1)):
        w = p[i: i + window]
        seen = w[~np.isnan(w)]
        if len(seen) and 2 * len(seen) >= len(w):
            out = min(out, float(np.median(seen)))
    return out
