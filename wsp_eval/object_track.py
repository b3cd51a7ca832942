"""Object-response fidelity (spec §4.3): where the generated video shows the evaluated object, frame by frame,
against where the simulator's reference shows it; no simulator, no weights, deterministic.

For one reference and a generated video over their common duration, at every reference frame (the generated video's
frame nearest in time, spec §4.1):
1. The reference's object at frame t: its exact visible pixels (the release's `object_mask` label of the evaluated
   object, less the robot's pixels) and their colours in the reference frame smoothed by `SMOOTH`: a masked
   template. The object's place is its simulator position projected through the release's camera (not the
   visible pixels' centroid, which a hand covering part of a resting object moves). A frame where fewer than
   `MIN_PIXELS` (per 128² px) of the object are visible carries no position and is skipped.
2. The generated video's object at frame t: where that template best matches the generated frame (smoothed alike;
   masked sum of squared differences, sub-pixel by a parabola through the minimum and its neighbours) inside the
   search region, the box of the reference's templates grown by `MARGIN` template sizes; p̂_t is that match's
   place of the projected position (the template's centroid moved by the reference's offset, projected position
   less visible centroid). The reference's p*_t is read the same way: the template's match in the reference's own
   frame drawn at the video's sharpness, moved by that offset, so the reference itself has error 0 exactly (the
   sub-pixel vertex's bias, up to half a pixel on a sliver of an object, falls on both alike).
   A video without the object there matches it somewhere else in the region, or at the place it stayed. The
   templates are drawn at the generated video's own sharpness (`sharpness`: the level of `BLURS` at which the
   blurred reference best matches the video's scene away from the robot and the objects), so that a video drawn
   softer than the simulator matches templates as soft as itself, not sharp ones.
3. Relative errors, against the reference's own motion, over the used frames (p_0: the first used frame):
   - an object whose image travels at least `MIN_TRAVEL` (per 128 px of frame height): x = max(x_d, x_v), with the
     displacement error x_d = RMS_t ‖(p̂_t − p̂_0) − (p*_t − p*_0)‖ / RMS_t ‖p*_t − p*_0‖ (a constant offset of the
     match, as blur gives, cancels) and the velocity error over `LAG` frames
     x_v = RMS ‖(p̂_{t+L} − p̂_t) − (p*_{t+L} − p*_t)‖ / RMS ‖p*_{t+L} − p*_t‖ (a jump where the reference glides);
   - an object that turns in place (less travel, but an in-plane rotation of at least `ROT_VISIBLE`): x_turn, the
     appearance error below over the object's own pixels: at every frame t of the common duration, its pixels at
     frame 0 or at frame t that are in sight at both (no robot at either). It needs no match or angle: a still
     object shows frame 0's image where the reference shows it turned (x_turn = 1), one that vanishes shows the
     table there (above 1), one that turns as the reference's shows what it shows (0);
   - the place it left, wherever the object is: at every frame of the common duration (seen or not), the pixels of
     the object's frame-0 image that the reference shows vacated (neither an object nor the robot: the table it
     revealed), x_vac, the appearance error over those pixels: 0 where the video shows what the reference revealed,
     1 where it still shows the object there. It needs no match, so it holds where the object is hidden or only a
     sliver shows (a lifted object in the hand); it applies where the reference vacates at least `MIN_PIXELS` (per
     128² px) in some frame;
   - when: x_win, the same two appearance errors (the place it left, and the object's own pixels at frame 0 or at
     t, in sight at both; for a travelling object too) taken over windows of `WINDOW` frames instead of the whole
     duration (one window where the clip is shorter), the largest over the windows in which the reference changes
     at least `WINDOW_SHARE` of what it changes in its most-changing window.
     Pooled over a clip, a response that is late, jumps or goes a third as far differs from the reference only
     in the second or so in which the reference moves, and the still frames around it dilute that; a window
     holds it.
   - how: x_step, the object's frame-to-frame changes: over its pixels at frame k − 1 or k with the robot at
     neither, the change the video shows from k − 1 to k against the reference's, Σ ‖ΔG − ΔR‖², less the video's
     noise floor (what its changes differ by where the reference shows no motion), relative to the reference's own
     change Σ ‖ΔR‖², both smoothed by `STEP_SMOOTH`, over the same windows as x_win. A jump changes the object's
     pixels in one frame where the reference changes them over several, which positions a frame or two apart do
     not show; an object that glides as the reference's has x_step 0.
   x is the largest of these. The appearance error over pixels P_t and frames T is
   √(Σ_T Σ_{P_t} ‖G − R‖² / Σ_T Σ_{P_t} ‖S − R‖²), G the generated frame, R the reference's and S its frame 0 with
   frame t's robot on top (what an object that never moved would give), all smoothed by `VACATED_SMOOTH` (the
   reference's at the video's sharpness).
   The arm's drawing: every error above is taken twice, with the reference's arm drawn sharp and drawn as the
   video draws it (`arm_sharpness`: the level of `BLURS` at which the reference best matches the video on the
   arm's band, the robot's pixels grown by `ARM_BAND` less the objects'; the robot's pixels grown by twice that
   blur are blurred by it, in R, in S and in the frames the templates are drawn from), and the drawing with the
   smaller x counts: a model that smears the moving arm over a grasped object is not charged for the smear, nor
   one that smears the arm alone for a smear it did not draw. Both drawings are the reference's; the object must
   respond as it does in either. S is drawn with the same smear of frame t's arm as R, so that the smear's halo
   over the object is not counted as the object's own change.
   fidelity = 100·clip((X_ZERO − x) / (X_ZERO − X_FULL), 0, 1). A static video (the object where it started, as
   it was) has x = 1 and scores 0, as does one whose object vanishes or lags far behind; a video whose object moves
   where the reference's rests has errors where the reference has none.
4. A reference is scorable when its object travels or turns so where it can be seen (`ObjectTrack.scorable`): it
   travels at least `MIN_TRAVEL` between frames that carry a position, and at least `SEEN_MOTION` of its image
   path (the projected position's, over every frame) lies between consecutive frames that both carry one (motion
   made while the object is hidden cannot be told from a jump); or it turns at least `ROT_VISIBLE` about the
   camera's axis and the pixels it covers in sight (at frame 0 and not at t, or the reverse) number at least
   `MIN_PIXELS` (per 128² px) at some frame t (a turn made under the hand cannot be seen). The T5 builder drops the
   others, as RMFA's suites drop a reference without a scorable window.

The constants were chosen on training-range builds (ManiSkill, LIBERO and ALOHA, `--seed-range train`) against the
generated-video negatives of `wsp study t5-negatives`; docs/validity.md reports them on sets built afterwards.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from wsp_eval.composites import blurred_region

MIN_PIXELS = 6  # visible object pixels (per 128² px) for a frame to carry a position
SMOOTH = 3.0  # px per 128 px of frame height: both videos are Gaussian-smoothed by this before matching, so that a
#   slightly blurred rendering matches the reference's sharp template
MARGIN = 2.0  # the search region: the reference templates' box grown by this many template sizes
MIN_TRAVEL = 2.0  # px per 128 px of frame height: the reference object's image must move this far to be scorable
SEEN_MOTION = 0.5  # share of the object's image path that must lie between frames in which it is seen
LAG = 4  # frames (0.2 s at 20 Hz): the velocity error's step
ROT_VISIBLE = 0.2  # rad: an object that turns at least this far about the camera's axis can be scored by its turn
VACATED_SMOOTH = 1.0  # px per 128 px: the smoothing of the appearance comparisons (both videos)
VACATED_CROP = 16.0  # px per 128 px: the appearance comparisons are smoothed on the object's box grown by this
#   much, which holds 3σ of the largest smoothing (√(VACATED_SMOOTH² + 4²) px)
BLURS = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)  # px per 128: the sharpness levels a generated video is matched at
SHARPNESS_MARGIN = 8.0  # px per 128: robot and object pixels grown by this are left out of the sharpness estimate
X_FULL = 0.35  # relative error at and below which the fidelity is 100 (noise and a 1 px blur stay below it)
WINDOW = 20  # frames (1 s at 20 Hz): the windowed appearance error's window
WINDOW_SHARE = 0.5  # a window counts when the reference changes at least this share of the most-changing window's
X_ZERO = 0.65  # relative error at and above which the fidelity is 0 (a response of 30 % of the reference's is above)
ARM_BAND = 3.0  # px per 128: the robot's pixels grown by this, less every object's, are where the arm's sharpness is
#   read (the arm's edges, where a smear shows)
STEP_SMOOTH = 2.0  # px per 128: both videos' frame-to-frame changes are compared after this smoothing, so that a
#   sub-pixel difference in where an edge lies does not count as a change the reference does not make


class Template(NamedTuple):
    """The reference object at one sample: its bounding box origin (x, y), colours (h, w, 3) float32, mask (h, w)
    uint8, and its visible pixels' centroid (x, y) in the frame."""

    origin: tuple[int, int]
    pixels: np.ndarray
    mask: np.ndarray
    centre: np.ndarray


class Level(NamedTuple):
    """The reference drawn at one blur level: a template per frame (None where too little of the object is
    visible), and the reference read as a generated video is read at this level: where each used frame's template
    matches that frame (`read`)."""

    templates: list[Template | None]
    read: np.ndarray  # (N, 2): the used templates' centroids as matched in their own frames


class Area(NamedTuple):
    """Pixels an appearance comparison covers: `where` (T, h, w) bool inside `box` (x0, y0, x1, y1) of the frame."""

    where: np.ndarray
    box: tuple[int, int, int, int]


class ObjectTrack(NamedTuple):
    """The reference side: its templates at each blur level drawn so far (level 0, the reference's own sharpness,
    always), where the object is, and what the sharpness estimate and the appearance comparisons cover."""

    size: tuple[int, int]  # (H, W) of the reference frames
    region: tuple[int, int, int, int]  # (x0, y0, x1, y1): where the generated video's object is looked for
    points: np.ndarray  # (T, 2): the object's projected position in every frame, seen or not
    true_turn: np.ndarray  # (T,): its simulator rotation about the camera's axis since frame 0, seen or not (rad)
    frames: np.ndarray  # (T, H, W, 3) uint8: the reference frames
    scene: np.ndarray  # (T, H, W) bool: the pixels of the sharpness estimate (neither robot nor object, grown)
    levels: dict  # blur level → its Level, filled on first use (`at_blur`)
    vacated: Area | None  # the object's frame-0 pixels the reference shows vacated at each frame; None where it
    #   vacates fewer than MIN_PIXELS (per 128² px) in every frame
    turn_area: Area | None  # the object's pixels at frame 0 or at each frame, in sight in both (x_turn's area, and
    #   x_win's for every object); None where those of one and not the other are fewer than MIN_PIXELS (per 128² px)
    #   in every frame
    steps: Area | None  # the object's pixels at frame k − 1 or k, the robot at neither (x_step's area; empty at 0);
    #   None where the object covers fewer than MIN_PIXELS (per 128² px) in every frame
    robot: np.ndarray  # (T, H, W) bool: the robot's pixels
    band: np.ndarray  # (T, H, W) bool: the pixels of the arm's sharpness estimate (ARM_BAND)
    drawn: dict  # arm level → the reference frames with the arm drawn at that level (`arm_drawn`), made on first use
    stills: dict  # arm level → the still frames S drawn at that level (`still_frames`), made on first use

    @property
    def templates(self) -> list[Template | None]:
        """A template per frame at the reference's sharpness (None where too little of the object is visible)."""
        return self.levels[0.0, 0.0].templates

    @property
    def used(self) -> list[int]:
        return [k for k, t in enumerate(self.templates) if t is not None]

    def travel(self) -> np.ndarray:
        """d_t of every used sample: the projected position's distance from the first used sample's (px)."""
        used = self.used
        if not used:
            return np.zeros(0)
        return np.linalg.norm(self.points[used] - self.points[used[0]], axis=1)

    def seen_motion(self) -> float:
        """The share of the object's image path that lies between consecutive frames both carrying a position."""
        steps = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        if steps.sum() <= 0:
            return 0.0
        seen = np.array([t is not None for t in self.templates])
        return float(steps[seen[1:] & seen[:-1]].sum() / steps.sum())

    @property
    def moving(self) -> bool:
        """Whether the reference object's image visibly travels at least MIN_TRAVEL (and T5 scores its position)."""
        d = self.travel()
        return (len(d) >= 2 and float(d.max()) >= MIN_TRAVEL * self.size[0] / 128
                and self.seen_motion() >= SEEN_MOTION)

    @property
    def turning(self) -> bool:
        """Whether the reference object turns visibly in the image (and T5 scores its appearance): its simulator
        rotation about the camera's axis reaches ROT_VISIBLE, and the pixels it covers in sight change by at least
        MIN_PIXELS (per 128² px) in some frame (a hand covering part of a resting object changes neither)."""
        return (self.turn_area is not None
                and float(np.abs(self.true_turn - self.true_turn[0]).max()) >= ROT_VISIBLE)

    @property
    def scorable(self) -> bool:
        return self.moving or self.turning


def rotation_matrices(quat_wxyz: np.ndarray) -> np.ndarray:
    """(T, 4) unit quaternions (wxyz) → (T, 3, 3) rotation matrices."""
    q = np.asarray(quat_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def image_points(world_xyz: np.ndarray, intrinsic, extrinsic) -> np.ndarray:
    """World points (T, 3) → (T, 2) pixel positions in the camera's own image (pixel centres at integers) through
    OpenCV intrinsics (3×3) and world→camera extrinsics (3×4)."""
    xyz = np.asarray(world_xyz, np.float64).reshape(-1, 3)
    cam = (np.asarray(extrinsic, np.float64).reshape(3, 4) @ np.c_[xyz, np.ones(len(xyz))].T).T
    if (cam[:, 2] <= 0).any():
        raise ValueError("an object position lies behind the camera")
    uv = (np.asarray(intrinsic, np.float64).reshape(3, 3) @ cam.T).T
    return uv[:, :2] / uv[:, 2:]


def image_turn(quat_wxyz: np.ndarray, extrinsic) -> np.ndarray:
    """(T,) the object's rotation about the camera's optical axis since frame 0 (rad, unwrapped): the angle of the
    best 2-D rotation fit to the camera-frame relative rotation's image-plane block."""
    r = rotation_matrices(quat_wxyz)
    cam = np.asarray(extrinsic, np.float64).reshape(3, 4)[:, :3]
    rel = cam @ r @ r[0].T @ cam.T
    return np.unwrap(np.arctan2(rel[:, 1, 0] - rel[:, 0, 1], rel[:, 0, 0] + rel[:, 1, 1]))


class ObjectPose(NamedTuple):
    """The evaluated object's simulator pose in every frame and the camera that drew it."""

    poses: np.ndarray  # (T, 7): world xyz (m) + quaternion wxyz
    intrinsic: np.ndarray  # 3×3
    extrinsic: np.ndarray  # 3×4, world → camera


def object_track(frames: np.ndarray, labels: np.ndarray, label: int, robot: np.ndarray,
                 pose: ObjectPose) -> ObjectTrack:
    """The reference side from its frames (T, H, W, 3) uint8, object labels (T, H, W), the evaluated object's label,
    robot labels (T, H, W) and the evaluated object's simulator pose in every frame."""
    if labels.shape != robot.shape or labels.shape != frames.shape[:3]:
        raise ValueError(f"frames {frames.shape}, object labels {labels.shape} and robot labels {robot.shape} differ")
    poses = np.asarray(pose.poses, np.float64)
    if poses.shape != (len(frames), 7):
        raise ValueError(f"{len(frames)} frames but object poses of shape {poses.shape}")
    points = image_points(poses[:, :3], pose.intrinsic, pose.extrinsic)
    true_turn = image_turn(poses[:, 3:], pose.extrinsic)
    h = frames.shape[1]
    least = MIN_PIXELS * (h / 128) ** 2
    robot = robot > 0
    templates: list[Template | None] = []
    for i in range(len(frames)):
        visible = (labels[i] == label) & ~robot[i]
        if visible.sum() < least:
            templates.append(None)
            continue
        ys, xs = np.nonzero(visible)
        y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
        templates.append(Template((int(x0), int(y0)), smoothed(frames[i])[y0:y1, x0:x1],
                                  visible[y0:y1, x0:x1].astype(np.uint8), np.array([xs.mean(), ys.mean()])))
    grow = int(np.ceil(SHARPNESS_MARGIN * h / 128))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))
    scene = np.stack([cv2.dilate(((labels[i] > 0) | robot[i]).astype(np.uint8), kernel) == 0
                      for i in range(len(frames))])
    region = search_region(templates, frames.shape[1:3])
    reach = int(np.ceil(ARM_BAND * h / 128))
    ring = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    band = np.stack([(cv2.dilate(robot[i].astype(np.uint8), ring) > 0) & (labels[i] == 0)
                     for i in range(len(frames))])
    return ObjectTrack(frames.shape[1:3], region, points, true_turn, frames, scene,
                       {(0.0, 0.0): _level(frames, templates, region, 0.0)}, *_areas(labels, label, robot, least), robot,
                       band, {0.0: frames}, {})


def _areas(labels: np.ndarray, label: int, robot: np.ndarray,
           least: float) -> tuple[Area | None, Area | None, Area | None]:
    """The appearance comparisons' pixels (`ObjectTrack.vacated`, `ObjectTrack.turn_area`, `ObjectTrack.steps`),
    cropped to the box of the object's pixels over every frame grown by VACATED_CROP; each None where it covers too
    little."""
    obj = (labels == label) & ~robot
    if not obj[0].any():
        return None, None, None
    h, w = labels.shape[1:]
    grow = int(np.ceil(VACATED_CROP * h / 128))
    ys, xs = np.nonzero(obj.any(axis=0))
    x0, y0 = max(0, int(xs.min()) - grow), max(0, int(ys.min()) - grow)
    x1, y1 = min(w, int(xs.max()) + 1 + grow), min(h, int(ys.max()) + 1 + grow)
    box = (x0, y0, x1, y1)
    crop = (slice(None), slice(y0, y1), slice(x0, x1))
    obj, free = obj[crop], ~robot[crop]
    start = obj[0]
    vacated = start & (labels[crop] == 0) & free
    in_sight = free & free[:1]
    changed = (start ^ obj) & in_sight

    def area(where: np.ndarray, counted: np.ndarray) -> Area | None:
        return Area(where, box) if counted.reshape(len(counted), -1).sum(axis=1).max() >= least else None

    steps = np.zeros_like(obj)
    steps[1:] = (obj[1:] | obj[:-1]) & free[1:] & free[:-1]
    return area(vacated, vacated), area((start | obj) & in_sight, changed), area(steps, obj)


def appearance_terms(frames: np.ndarray, track: ObjectTrack, area: Area | None, frame_idx: np.ndarray,
                     blur: float, arm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per frame k of the common duration, over an area's pixels: e_k = Σ ‖G − R‖² and o_k = Σ ‖S − R‖² (module
    docstring, step 3), both zero where the area is empty (and everywhere for no area). `frame_idx[k]` is the
    generated frame shown at the time of the reference's frame k; `blur` the video's sharpness level, at which the
    reference is drawn, and `arm` the arm's (`arm_sharpness`)."""
    n = min(len(frame_idx), len(track.frames))
    error, own = np.zeros(n), np.zeros(n)
    if area is None:
        return error, own
    x0, y0, x1, y1 = area.box
    scale = track.size[0] / 128

    def drawn(crop: np.ndarray, level: float) -> np.ndarray:
        sigma = float(np.hypot(VACATED_SMOOTH, level)) * scale
        return cv2.GaussianBlur(crop.astype(np.float32), (0, 0), sigma)

    crops = arm_drawn(track, arm)[:, y0:y1, x0:x1]
    for k in range(n):
        where = area.where[k]
        if not where.any():
            continue
        ref = drawn(crops[k], blur)
        still = still_frames(track, arm)[k, y0:y1, x0:x1]
        error[k] = float(np.sum((drawn(frames[frame_idx[k], y0:y1, x0:x1], 0.0) - ref)[where] ** 2))
        own[k] = float(np.sum((drawn(still, blur) - ref)[where] ** 2))
    return error, own


def step_terms(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray, blur: float,
               arm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per frame k ≥ 1 of the common duration, over `ObjectTrack.steps`' pixels A_k: the change from frame k − 1
    to k in the video against the reference's less the video's noise floor, e_k = Σ_A ‖ΔG − ΔR‖² − ν·|A_k| (below
    zero where the video changes less than its noise there; `windowed` clips the windows' ratios at 0, not single
    frames, so noise does not add up), and the reference's own change o_k = Σ_A ‖ΔR‖² (module docstring, step 3);
    ν is the mean per-pixel ‖ΔG − ΔR‖² over the sharpness estimate's scene pixels (at every LAG-th pair), where
    the reference shows no motion. Both smoothed by STEP_SMOOTH, the reference drawn at the video's sharpness and
    at its arm's."""
    n = min(len(frame_idx), len(track.frames))
    error, own = np.zeros(n), np.zeros(n)
    area = track.steps
    if area is None or n < 2:
        return error, own
    scale = track.size[0] / 128
    reference = arm_drawn(track, arm)

    def smooth(frame: np.ndarray, level: float) -> np.ndarray:
        return cv2.GaussianBlur(frame.astype(np.float32), (0, 0), float(np.hypot(STEP_SMOOTH, level)) * scale)

    floor = []
    for k in range(LAG, n, LAG):
        scene = track.scene[k] & track.scene[k - 1]
        if scene.any():
            shown = smooth(frames[frame_idx[k]], 0.0) - smooth(frames[frame_idx[k - 1]], 0.0)
            drawn = smooth(reference[k], blur) - smooth(reference[k - 1], blur)
            floor.append(float(np.mean(np.sum((shown - drawn)[scene] ** 2, axis=-1))))
    noise = float(np.mean(floor)) if floor else 0.0
    x0, y0, x1, y1 = area.box
    shown = [smooth(frames[frame_idx[k], y0:y1, x0:x1], 0.0) for k in range(n)]
    drawn = [smooth(reference[k, y0:y1, x0:x1], blur) for k in range(n)]
    for k in range(1, n):
        where = area.where[k]
        if not where.any():
            continue
        change = (drawn[k] - drawn[k - 1])[where]
        own[k] = float(np.sum(change ** 2))
        error[k] = float(np.sum(((shown[k] - shown[k - 1])[where] - change) ** 2)) - noise * where.sum()
    return error, own


def pooled(error: np.ndarray, own: np.ndarray) -> float:
    """√(Σ e / Σ o), 0 where the reference changes nothing there."""
    total = float(own.sum())
    return float(np.sqrt(error.sum() / total)) if total > 0 else 0.0


def windowed(error: np.ndarray, own: np.ndarray) -> float:
    """The largest √(Σ_W e / Σ_W o) over the windows of `WINDOW` consecutive frames (the whole duration where it is
    shorter) whose Σ_W o is at least `WINDOW_SHARE` of the largest window's: where in time the video differs (0
    where every such Σ_W e is below 0, as x_step's can be)."""
    if own.sum() <= 0:
        return 0.0
    w = min(WINDOW, len(own))
    e = np.convolve(error, np.ones(w), "valid")
    o = np.convolve(own, np.ones(w), "valid")
    keep = o >= WINDOW_SHARE * o.max()
    return float(np.sqrt(max(0.0, (e[keep] / o[keep]).max())))


def _level(frames: np.ndarray, templates: list[Template | None], region: tuple[int, int, int, int],
           blur: float, redraw: bool = False) -> Level:
    """`templates` (the reference's, at its own sharpness) redrawn from the frames blurred by `blur` (px per 128)
    before the matching's smoothing, and the reference read at that level."""
    sigma = float(np.hypot(SMOOTH, blur))
    drawn = {k: smoothed(frames[k], sigma) for k, t in enumerate(templates) if t is not None}
    if blur > 0 or redraw:
        templates = [None if t is None else
                     t._replace(pixels=drawn[k][t.origin[1]:t.origin[1] + t.mask.shape[0],
                                                t.origin[0]:t.origin[0] + t.mask.shape[1]])
                     for k, t in enumerate(templates)]
    read = np.array([locate(drawn[k], templates[k], region) for k in drawn]).reshape(-1, 2)
    return Level(templates, read)


def at_blur(track: ObjectTrack, blur: float, arm: float = 0.0) -> Level:
    """The track's templates drawn at blur level `blur` (px per 128; one of BLURS) from the reference with its arm
    drawn at `arm` (`arm_drawn`), made on first use."""
    if (blur, arm) not in track.levels:
        track.levels[blur, arm] = _level(arm_drawn(track, arm), track.templates, track.region, blur, arm > 0)
    return track.levels[blur, arm]


def sharpness(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray) -> float:
    """The blur level of BLURS at which the reference's scene (its pixels away from the robot and the objects, at
    every LAG-th frame of the common duration) best matches the generated video: how sharply the video is drawn."""
    return _best_level(frames, track, frame_idx, track.scene, 0.0)


def arm_sharpness(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray, blur: float) -> float:
    """The level of BLURS by which the video draws the arm softer than its scene (drawn at `blur`): where the
    reference drawn at hypot(blur, level) best matches the video over the arm's band (`ObjectTrack.band`, at every
    LAG-th frame of the common duration). Learned models often smear the moving arm while the rest stays sharp."""
    return _best_level(frames, track, frame_idx, track.band, blur)


def _best_level(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray, pixels: np.ndarray,
                base: float) -> float:
    """The level of BLURS at which the reference blurred by hypot(base, level) best matches the video (sum of
    squared differences over `pixels` (T, H, W) bool, at every LAG-th frame of the common duration)."""
    scale = track.size[0] / 128
    costs = np.zeros(len(BLURS))
    for k in range(0, min(len(frame_idx), len(track.frames)), LAG):
        ref, where = track.frames[k].astype(np.float32), pixels[k]
        if not where.any():
            continue
        shown = frames[frame_idx[k]].astype(np.float32)[where]
        for i, level in enumerate(BLURS):
            sigma = float(np.hypot(base, level)) * scale
            drawn = cv2.GaussianBlur(ref, (0, 0), sigma) if sigma > 0 else ref
            costs[i] += float(np.sum((drawn[where] - shown) ** 2))
    return BLURS[int(np.argmin(costs))]


def still_frames(track: ObjectTrack, arm: float) -> np.ndarray:
    """S: per frame k, the reference's frame 0 with frame k's robot on top (an object that never moved), its arm
    drawn at `arm` as the reference's is (`arm_drawn`), so that a smear reaching the object blends it with frame k's
    arm in S as in the reference. Made on first use."""
    if arm not in track.stills:
        still = np.where(track.robot[..., None], track.frames, track.frames[:1])
        track.stills[arm] = blurred_region(still, track.robot, arm * track.size[0] / 128) if arm > 0 else still
    return track.stills[arm]


def arm_drawn(track: ObjectTrack, arm: float) -> np.ndarray:
    """The reference frames with the robot's pixels, grown by twice the blur (where a smear of σ reaches), blurred
    by `arm` px per 128 (the arm's sharpness level): the reference as the video draws its arm. Made on first use."""
    if arm not in track.drawn:
        track.drawn[arm] = blurred_region(track.frames, track.robot, arm * track.size[0] / 128)
    return track.drawn[arm]


def search_region(templates: list[Template | None], size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The box of every template's box, grown by `MARGIN` times the largest template side, within the frame."""
    boxes = [(t.origin[0], t.origin[1], t.origin[0] + t.mask.shape[1], t.origin[1] + t.mask.shape[0])
             for t in templates if t is not None]
    if not boxes:
        return 0, 0, size[1], size[0]
    grow = int(np.ceil(MARGIN * max(max(b[2] - b[0], b[3] - b[1]) for b in boxes)))
    return (max(0, min(b[0] for b in boxes) - grow), max(0, min(b[1] for b in boxes) - grow),
            min(size[1], max(b[2] for b in boxes) + grow), min(size[0], max(b[3] for b in boxes) + grow))


def smoothed(frame: np.ndarray, sigma: float = SMOOTH) -> np.ndarray:
    """A frame (H, W, 3) as float32, Gaussian-smoothed by `sigma` px per 128 px of its height."""
    return cv2.GaussianBlur(frame.astype(np.float32), (0, 0), sigma * frame.shape[0] / 128)


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


class Positions(NamedTuple):
    """The object in a generated video and in the reference at the reference's used frames within the common
    duration: positions p̂, p* (N, 2) px and the frames' indices (none where the object is scored by its turn), and
    the errors that need no position."""

    found: np.ndarray
    reference: np.ndarray
    frames: list[int]
    scale: float  # frame height / 128
    blur: float  # the video's blur level (px per 128) the templates were drawn at
    arm: float  # the level the reference's arm is drawn at in the counted drawing: 0 or `arm_sharpness`'s
    vacated: float  # x_vac: the error at the place the object left
    turned: float  # x_turn: the error on the object's own pixels, where it turns in place (`by_turn`); else 0
    windowed: float  # x_win: the largest windowed error at the place it left and on its own pixels
    stepped: float  # x_step: the windowed error of the object's frame-to-frame changes
    by_turn: bool  # whether the object turns in place (scored by its appearance) rather than travels


def positions(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray) -> Positions:
    """Where a generated video shows the object, and its appearance errors; `frame_idx[k]` is its frame shown at the
    time of the reference's frame k. The templates are drawn at the video's own sharpness (`sharpness`), and the
    reference's arm sharp and as the video draws it (`arm_sharpness`): the drawing with the smaller x counts."""
    used = [k for k in track.used if k < len(frame_idx)]
    if not used:
        raise ValueError("the reference object is never in sight")
    by_turn = not track.moving and track.turning
    blur = sharpness(frames, track, frame_idx)
    scale = track.size[0] / 128
    shown = {} if by_turn else {k: smoothed(frames[frame_idx[k]]) for k in used}
    offset = track.points[used] - np.array([track.templates[k].centre for k in used])  # to the projected position
    drawings = []
    for arm in sorted({0.0, arm_sharpness(frames, track, frame_idx, blur)}):
        errors = appearance_errors(frames, track, frame_idx, blur, arm, by_turn)
        if by_turn:  # scored on its own pixels: no position is read
            none = np.zeros((0, 2))
            drawings.append(Positions(none, none, [], scale, blur, **errors))
            continue
        level = at_blur(track, blur, arm)
        found = np.array([locate(shown[k], level.templates[k], track.region) for k in used])
        drawings.append(Positions(found + offset, level.read[: len(used)] + offset, used, scale, blur, **errors))
    return min(drawings, key=relative_error)


def appearance_errors(frames: np.ndarray, track: ObjectTrack, frame_idx: np.ndarray, blur: float, arm: float,
                      by_turn: bool) -> dict:
    """x_vac, x_turn (where the object turns in place, else 0), x_win and x_step with the reference drawn at the
    video's sharpness `blur` and its arm at `arm` (module docstring, step 3), as `Positions` fields."""
    left = appearance_terms(frames, track, track.vacated, frame_idx, blur, arm)
    own = appearance_terms(frames, track, track.turn_area, frame_idx, blur, arm)
    return dict(arm=arm, vacated=pooled(*left), turned=pooled(*own) if by_turn else 0.0,
                windowed=max(windowed(*left), windowed(*own)),
                stepped=windowed(*step_terms(frames, track, frame_idx, blur, arm)), by_turn=by_turn)


def relative_error(p: Positions) -> float:
    """x (module docstring, step 3): the largest of x_vac, x_win, x_step and, for an object whose image travels,
    max(x_d, x_v), for one that turns in place, x_turn."""
    return max(_motion_error(p), p.vacated, p.windowed, p.stepped)


def _motion_error(p: Positions) -> float:
    if p.by_turn:
        return p.turned
    moved = p.reference - p.reference[0]
    motion = float(np.sqrt(np.mean(np.sum(moved ** 2, axis=1))))
    if motion == 0:
        raise ValueError("the reference object neither moves nor turns: not a scorable reference")
    x = _rms(p.found - p.found[0] - moved) / motion
    at = {k: i for i, k in enumerate(p.frames)}
    pairs = np.array([(at[k], at[k + LAG]) for k in p.frames if k + LAG in at], dtype=int).reshape(-1, 2)
    v_star = p.reference[pairs[:, 1]] - p.reference[pairs[:, 0]]
    if len(pairs) and (speed := _rms(v_star)) > 0:
        x = max(x, _rms(p.found[pairs[:, 1]] - p.found[pairs[:, 0]] - v_star) / speed)
    return x


def _rms(v: np.ndarray) -> float:
    if len(v) == 0:
        return 0.0
    return float(np.sqrt(np.mean(np.sum(v ** 2, axis=1))))


def fidelity(x: float) -> float:
    """The fidelity of a relative error x (module docstring, step 3)."""
    return 100.0 * float(np.clip((X_ZERO - x) / (X_ZERO - X_FULL), 0.0, 1.0))
