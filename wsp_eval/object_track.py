"""Object-response fidelity (spec §4.3): where the generated video shows the evaluated object, frame by frame,
against where the simulator's reference shows it; no simulator, no weights, deterministic.

For one reference and a generated video over their common duration, at every reference frame (the generated video's
frame nearest in time, spec §4.1):
1. The reference's object at frame t: its exact visible pixels (the release's `object_mask` label of the evaluated
   object, less the robot's pixels) and their colours in the reference frame smoothed by `SMOOTH`: a masked
   template, whose centroid p*_t is where the reference shows the object. A frame where fewer than `MIN_PIXELS`
   (per 128² px) of the object are visible carries no position and is skipped.
2. The generated video's object at frame t: the position p̂_t where that template best matches the generated frame
   (smoothed alike; masked sum of squared differences, sub-pixel by a parabola through the minimum and its
   neighbours) inside the search region: the box of the reference's templates grown by `MARGIN` template sizes.
   A video without the object there matches it somewhere else in the region, or at the place it stayed.
3. Two relative errors over the used frames, each against the reference's own motion:
   - displacement: x_d = RMS_t ‖(p̂_t − p̂_0) − (p*_t − p*_0)‖ / RMS_t ‖p*_t − p*_0‖ (p_0: the first used frame; a
     constant offset of the match, as blur gives, cancels);
   - velocity over `LAG` frames: x_v = RMS ‖(p̂_{t+L} − p̂_t) − (p*_{t+L} − p*_t)‖ / RMS ‖p*_{t+L} − p*_t‖, over
     the used frames t whose t + L is used too (a jump where the reference glides fails here);
   x = max(x_d, x_v); fidelity = 100·clip((X_ZERO − x) / (X_ZERO − X_FULL), 0, 1).
   A static video (the object where it started) has x_d = 1 and scores 0, as does one whose object vanishes or lags
   far behind; a video whose object moves where the reference's rests has errors where the reference has none.
4. A reference is scorable when max_t ‖p*_t − p*_0‖ ≥ `MIN_TRAVEL` (per 128 px of frame height) over at least two
   used frames: the T5 builder drops the others, as RMFA's suites drop a reference without a scorable window.

The constants were chosen on training-range builds (ManiSkill and LIBERO, `--seed-range train`) against the
generated-video negatives of `wsp study t5-negatives`; docs/validity.md reports them on sets built afterwards.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

MIN_PIXELS = 6  # visible object pixels (per 128² px) for a frame to carry a position
SMOOTH = 3.0  # px per 128 px of frame height: both videos are Gaussian-smoothed by this before matching, so that a
#   slightly blurred rendering matches the reference's sharp template
MARGIN = 2.0  # the search region: the reference templates' box grown by this many template sizes
MIN_TRAVEL = 2.0  # px per 128 px of frame height: the reference object's image must move this far to be scorable
LAG = 4  # frames (0.2 s at 20 Hz): the velocity error's step
X_FULL = 0.35  # relative error at and below which the fidelity is 100 (noise and a 1 px blur stay below it)
X_ZERO = 0.65  # relative error at and above which the fidelity is 0 (a response of 30 % of the reference's is above)


class Template(NamedTuple):
    """The reference object at one sample: its bounding box origin (x, y), colours (h, w, 3) float32, mask (h, w)
    uint8, and its centroid p* (x, y) in the frame."""

    origin: tuple[int, int]
    pixels: np.ndarray
    mask: np.ndarray
    centre: np.ndarray


class ObjectTrack(NamedTuple):
    """The reference side: a template per used sample (None where too little of the object is visible)."""

    templates: list[Template | None]
    size: tuple[int, int]  # (H, W) of the reference frames
    region: tuple[int, int, int, int]  # (x0, y0, x1, y1): where the generated video's object is looked for

    @property
    def used(self) -> list[int]:
        return [k for k, t in enumerate(self.templates) if t is not None]

    def travel(self) -> np.ndarray:
        """d_t of every used sample (px)."""
        used = self.used
        if not used:
            return np.zeros(0)
        start = self.templates[used[0]].centre
        return np.array([np.linalg.norm(self.templates[k].centre - start) for k in used])

    @property
    def scorable(self) -> bool:
        d = self.travel()
        return len(d) >= 2 and float(d.max()) >= MIN_TRAVEL * self.size[0] / 128


def object_track(frames: np.ndarray, labels: np.ndarray, label: int, robot: np.ndarray) -> ObjectTrack:
    """The reference side from its frames (T, H, W, 3) uint8, object labels (T, H, W), the evaluated object's label
    and robot labels (T, H, W)."""
    if labels.shape != robot.shape or labels.shape != frames.shape[:3]:
        raise ValueError(f"frames {frames.shape}, object labels {labels.shape} and robot labels {robot.shape} differ")
    h = frames.shape[1]
    least = MIN_PIXELS * (h / 128) ** 2
    out: list[Template | None] = []
    for i in range(len(frames)):
        frame = smoothed(frames[i])
        visible = (labels[i] == label) & (robot[i] == 0)
        if visible.sum() < least:
            out.append(None)
            continue
        ys, xs = np.nonzero(visible)
        y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
        out.append(Template((int(x0), int(y0)), frame[y0:y1, x0:x1],
                            visible[y0:y1, x0:x1].astype(np.uint8), np.array([xs.mean(), ys.mean()])))
    return ObjectTrack(out, frames.shape[1:3], search_region(out, frames.shape[1:3]))


def search_region(templates: list[Template | None], size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The box of every template's box, grown by `MARGIN` times the largest template side, within the frame."""
    boxes = [(t.origin[0], t.origin[1], t.origin[0] + t.mask.shape[1], t.origin[1] + t.mask.shape[0])
             for t in templates if t is not None]
    if not boxes:
        return 0, 0, size[1], size[0]
    grow = int(np.ceil(MARGIN * max(max(b[2] - b[0], b[3] - b[1]) for b in boxes)))
    return (max(0, min(b[0] for b in boxes) - grow), max(0, min(b[1] for b in boxes) - grow),
            min(size[1], max(b[2] for b in boxes) + grow), min(size[0], max(b[3] for b in boxes) + grow))


def smoothed(frame: np.ndarray) -> np.ndarray:
    """A frame (H, W, 3) as float32, Gaussian-smoothed by `SMOOTH` (scaled to its height)."""
    return cv2.GaussianBlur(frame.astype(np.float32), (0, 0), SMOOTH * frame.shape[0] / 128)


def _subpixel(values: np.ndarray, i: int) -> float:
    """Offset of a parabola's vertex through values[i − 1 … i + 1] (0 at an edge or a flat top)."""
    if i <= 0 or i >= len(values) - 1:
        return 0.0
    a, b, c = values[i - 1], values[i], values[i + 1]
    den = a - 2 * b + c
    return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) if den > 0 else 0.0


def locate(frame: np.ndarray, t: Template, region: tuple[int, int, int, int]) -> np.ndarray:
    """Where template `t`'s centroid lies in a smoothed frame (H, W, 3) float32 at its best masked-SSD match inside
    `region` (x, y, sub-pixel)."""
    x0, y0, x1, y1 = region
    image = frame[y0:y1, x0:x1]
    h, w = t.mask.shape
    if h > image.shape[0] or w > image.shape[1]:
        raise ValueError(f"a {w}×{h} template does not fit the {image.shape[1]}×{image.shape[0]} search region")
    ssd = cv2.matchTemplate(image, t.pixels, cv2.TM_SQDIFF, mask=t.mask)
    y, x = np.unravel_index(int(np.argmin(ssd)), ssd.shape)
    dx, dy = _subpixel(ssd[y, :], x), _subpixel(ssd[:, x], y)
    return np.array([x0 + x + dx, y0 + y + dy]) + (t.centre - np.array(t.origin))


def positions(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """(p̂, p*, used): the object's position in a generated video and in the reference, (N, 2) px each, at the
    reference's used frames within the common duration (`used`); `frame_idx[k]` is the generated frame shown at the
    time of the reference's frame k."""
    used = [k for k in track.used if k < len(frame_idx)]
    if not used:
        raise ValueError("the reference object is never in sight")
    found = np.array([locate(smoothed(frames[frame_idx[k]]), track.templates[k], track.region) for k in used])
    return found, np.array([track.templates[k].centre for k in used]), used


def relative_error(found: np.ndarray, reference: np.ndarray, frames: list[int]) -> float:
    """x = max(x_d, x_v) of positions p̂ and p* (N, 2) at the reference frames `frames` (module docstring, step 3)."""
    moved = reference - reference[0]
    motion = float(np.sqrt(np.mean(np.sum(moved ** 2, axis=1))))
    if motion == 0:
        raise ValueError("the reference object does not move: not a scorable reference")
    x_d = _rms(found - found[0] - moved) / motion
    at = {k: i for i, k in enumerate(frames)}
    pairs = np.array([(at[k], at[k + LAG]) for k in frames if k + LAG in at], dtype=int).reshape(-1, 2)
    if len(pairs) == 0:
        return x_d
    v_star = reference[pairs[:, 1]] - reference[pairs[:, 0]]
    v_hat = found[pairs[:, 1]] - found[pairs[:, 0]]
    speed = _rms(v_star)
    return max(x_d, _rms(v_hat - v_star) / speed) if speed > 0 else x_d


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(v ** 2, axis=1))))


def fidelity(x: float) -> float:
    """The fidelity of a relative position error x (module docstring, step 3)."""
    return 100.0 * float(np.clip((X_ZERO - x) / (X_ZERO - X_FULL), 0.0, 1.0))
