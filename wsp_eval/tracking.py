"""T4 point tracking (spec §4.4), simulator-free: the default tracker backend (OpenCV pyramidal
Lucas–Kanade with a forward–backward check), the object displacement d, the distal-arm motion gate g and
the tracker's part of the per-rollout score, S = 100·1[g ≥ 0.5·g_ref]·1[tracked]·1[d ≤ 10] (the T4 suite adds
the presence rule of `wsp_eval.object_presence`).

Everything runs in the 256×256 *scoring frame*: every video is resized to it (and turned grey) first, and
pixel positions are given in it. Coordinates are OpenCV's (pixel centres at integers, x right, y down), so a
point at u in a W-wide image sits at (u + 0.5)·256/W − 0.5 in the scoring frame — the mapping `cv2.resize`
applies.

Two tracking modes, same LK machinery and thresholds:
- *anchored* (the evaluated object): every frame is matched against the query frame 0, starting from the
  point's last visible position. A static object accrues no drift, and an occluder (the gripper passing in
  front) does not drag the points along: it fails the check and the point is invisible until it reappears.
- *chained* (the distal arm, whose appearance changes as the hand turns): frame t−1 → t; a point that fails
  the check once is lost for good.
A point is *visible* in a frame when LK converged both ways and its forward–backward error is below `FB_MAX`;
an anchored point's window must also still resemble its frame-0 window (`ERR_MAX`). A point whose frame-0
window lacks texture (minimum eigenvalue of the structure tensor below `MIN_EIG`: a uniform face, plain
background) is never visible: textureless objects are handled by the points around them, which straddle the
object's edges and the table.
A centroid moves by the mean displacement of its visible points (so points dropping in and out do not shift
it); with no visible point it carries its last value forward.

The evaluated object goes first through a *colour-region* stage (`object_tracks`): when its frame-0 colour is
distinct (its region of that colour is compact around the object and covers almost none of the robot), the
whole query grid follows that region — visible in a frame when a region of the object's colour, at least
`REGION_PART_MIN` of its frame-0 area, lies within `REGION_JUMP_MAX` px of its last position. Why: the paper's
grid (radius 10 px) is wider than a ManiSkill cube (6–8 px in the scoring frame), so most query points sit on
the table, and grey LK loses the object's own points as soon as the fingers close on it; the table points stay
visible and still, and a carried-away object goes undetected (grey LK alone detects 68 % of true motions over
10 px on ManiSkill, with 6 % false alarms; `docs/validity.md`, T4 tracker). Colour survives where grey texture does not:
a blue cube on orange wood, a grasped red cube between grey fingers. Where the colour is not distinct (textured or dark LIBERO objects, an
object coloured like the robot) the points are tracked by LK as above, from a grid of half the paper's radius
(`LK_QUERY_RADIUS`): on the object itself rather than on its neighbours, so that an object lost under the fingers
is invisible (a tracking failure) instead of read as still by the neighbours' points. The occlusion rule: an object hidden
(by the hand, or carried out of sight) is invisible, keeps its last position, and counts against the
tracking-failure rule of `t4_score`. An object *partly* hidden (its visible region smaller than
`FIT_PART_MAX` of its frame-0 area: fingers over a cube's top) is placed by an occlusion-aware fit of its
frame-0 shape (`occlusion_fit`; only where frame 0 shows the object whole: no robot pixel within
`HIDDEN_AT_START` of it): the shape's translation that covers the most visible object pixels while
lying on the fewest background pixels, where background is what still looks as it did in frame 0 or like the
object's frame-0 surroundings, and anything else (a finger, its shadow) may be hiding the object. Why: the
visible part's centroid slides away from the occluder — measured on ALOHA, a cube under closing fingers read
4 px off while still and a 12.5 px lift read 7–10 px (`docs/validity.md`, T4 tracker).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

SCORING_SIZE = 256  # px: the square frame every video is scored in
QUERY_RADIUS = 10.0  # px: the 3×3 query grid fits in this radius (corner points exactly on it)
LK_QUERY_RADIUS = 5.0  # px: the LK stage's grid instead (the colour stage keeps the paper's, which moves rigidly
#   with the region): the paper's corners, 10 px out, lie beside an object of 8–12 px (LIBERO's chocolate pudding,
#   ManiSkill's pegs in the scoring frame), on still neighbours that stay visible while the object's own points
#   are lost under the fingers, so a lifted object read as still. Measured on LIBERO's validation references
#   (docs/validity.md, T4 tracker): moving objects detected (d > 10 or lost) 32 / 36 with 10 px, 35 with 3, 36 with 5,
#   35 with 7; no false alarm on still objects with any of them.
LK_WINDOW = 15  # px: LK window side, about an object's size in the scoring frame plus its surroundings
CHAINED_LEVELS = 3  # pyramid levels above full size for chained points: captures ≈ 15·2³/2 = 60 px per frame
ANCHORED_LEVELS = 1  # … for anchored points, which start at their last position: captures ≈ 15 px per frame.
#   Coarser levels would let large moving structures nearby (the arm, 8× the window at level 3) drag a fixed
#   template off a static object: measured on a PickCube reference, 3 levels lost a static, unoccluded distractor
#   from frame 5 on (visible in 30% of frames); 1 level kept it until the hand covered it (73%).
LK_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
MIN_EIG = 1e-3  # LK's normalised minimum eigenvalue: below it a window has no trackable texture
FB_MAX = 1.0  # px: forward–backward error above which a point is not visible
ERR_MAX = 12.0  # grey levels: mean absolute difference to the frame-0 window above which an anchored point is
#   not visible (measured on references: true matches ≤ 6.3 at the 99th percentile, matches onto the passing
#   gripper ≥ 17). Chained points skip it: their template is the previous frame.
MOTION_MAX = 10.0  # px: d above this means the object moved (S = 0)
GATE_RATIO = 0.5  # the generated gate must reach this fraction of the reference gate
GATE_MIN_REFERENCE = 20.0  # px: build time keeps an instance only if the reference gate reaches this
TRACKED_RATIO = 0.5  # a generated rollout whose object is visible in fewer than this fraction of the frames in
#   which the reference's is visible is a tracking failure (S = 0; spec §3.4 counts tracking failures in the
#   mean). Without it an object that vanishes, or is carried away under the fingers, would keep its last
#   centroid and pass: measured, the action-blind baseline (the source rollout: no distractor, target grasped
#   or still at its original place) scored 75 on T4 without the rule.
ARM_GRID_STEP = 4  # px: spacing of the distal-arm seed grid
ARM_ERODE = 2  # px: the distal-arm mask is eroded by this before seeding (no points on its outline)
DISTAL_LABEL = 2  # robot mask label of wrist, hand and fingers
COLOUR_DELTA_E = 22.0  # CIE76 ΔE in Lab within which a pixel has the object's colour (a blue cube against the
#   wood is ≥ 60 away; a generated video's colour drift of a few units stays inside)
COLOUR_PATCH = 2  # px: the object's colour is the median over a (2·2+1)² patch at its frame-0 position
REGION_RADIUS_MAX = 24.0  # px: the frame-0 region of the object's colour must lie within this of its position,
#   else the colour leaks into the surroundings and is not distinct (LK instead)
REGION_AREA_MIN = 4  # px²: a smaller frame-0 region is noise, not an object (LK instead)
ROBOT_COLOUR_MAX = 0.02  # the object's colour may cover at most this fraction of the robot's frame-0 pixels,
#   so that the region cannot follow the gripper (LK instead)
REGION_PART_MIN = 0.05  # a region smaller than this fraction of the frame-0 area (or than 2 px²) is not the
#   object: a grasped cube shows a sliver of colour between the fingers, which is kept
REGION_SEARCH = 48  # px: half-side of the window searched around the last position
REGION_JUMP_MAX = 40.0  # px: the object's region moves at most this far from its last position (measured on
#   353 validation references and rollouts: true motion ≤ 17 px per frame, drops included)
FIT_PART_MAX = 0.8  # a visible region smaller than this fraction of the frame-0 area is partly hidden: the
#   object is placed by `occlusion_fit`; a larger one by its centroid (sub-pixel, and unbiased when whole)
BACKGROUND_DELTA_E = 6.0  # CIE76 ΔE within which a pixel still looks like frame 0 at its place, or like the
#   object's frame-0 surroundings: background, which the object's shape may not cover (codec noise on a
#   lossless-contract submission is ≤ 1; a finger or its shadow is ≥ 10 away)
SURROUND_RING = (2.0, 6.0)  # px: the object's frame-0 surroundings: pixels this far from its region
SURROUND_BATCH = 64  # surrounding colours compared with a window at once (bounds the (batch, h, w) temporary)
HIDDEN_AT_START = 2.0  # px: a robot pixel this close to the frame-0 region may hide part of the object, whose
#   frame-0 shape is then no model of it: no occlusion fit for that object (its centroid, as before the fit)

_LK = dict(winSize=(LK_WINDOW, LK_WINDOW), criteria=LK_CRITERIA)


def scoring_frames(frames: np.ndarray) -> np.ndarray:
    """(T, H, W, 3) RGB or (T, H, W) grey uint8 video → (T, 256, 256) grey uint8 in the scoring frame."""
    frames = np.asarray(frames)
    if frames.ndim not in (3, 4) or len(frames) == 0:
        raise ValueError(f"expected a (T, H, W[, 3]) video with T ≥ 1, got shape {frames.shape}")
    if frames.dtype != np.uint8:
        raise ValueError(f"expected uint8 frames, got {frames.dtype}")
    out = np.empty((len(frames), SCORING_SIZE, SCORING_SIZE), np.uint8)
    for t, f in enumerate(frames):
        grey = cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) if f.ndim == 3 else f
        shrink = grey.shape[0] > SCORING_SIZE or grey.shape[1] > SCORING_SIZE
        out[t] = cv2.resize(grey, (SCORING_SIZE, SCORING_SIZE),
                            interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return out


class ScoringVideo:
    """A video in the scoring frame: `grey` (T, 256, 256) uint8 for LK, and `rgb` (T, 256, 256, 3) uint8 for the
    colour-region stage (None for a grey input), resized from the source frames only when first asked for: an
    object the LK stage tracks never needs it (`first_rgb` resizes frame 0 alone, for the colour test)."""

    def __init__(self, grey: np.ndarray, frames: np.ndarray | None = None):
        self.grey, self._frames = grey, frames
        self._rgb: np.ndarray | None = None

    @property
    def rgb(self) -> np.ndarray | None:
        if self._rgb is None and self._frames is not None:
            out = np.empty((len(self._frames), SCORING_SIZE, SCORING_SIZE, 3), np.uint8)
            for t, f in enumerate(self._frames):
                _resize_rgb(f, out[t])
            self._rgb = out
        return self._rgb

    @property
    def first_rgb(self) -> np.ndarray | None:
        if self._rgb is not None:
            return self._rgb[0]
        if self._frames is None:
            return None
        return _resize_rgb(self._frames[0], np.empty((SCORING_SIZE, SCORING_SIZE, 3), np.uint8))


def _resize_rgb(frame: np.ndarray, dst: np.ndarray) -> np.ndarray:
    interp = cv2.INTER_AREA if max(frame.shape[:2]) > SCORING_SIZE else cv2.INTER_LINEAR
    return cv2.resize(frame, (SCORING_SIZE, SCORING_SIZE), dst=dst, interpolation=interp)


def scoring_video(frames: np.ndarray) -> ScoringVideo:
    """(T, H, W, 3) RGB or (T, H, W) grey uint8 video → `ScoringVideo` (resized as `scoring_frames`)."""
    frames = np.asarray(frames)
    return ScoringVideo(scoring_frames(frames), frames if frames.ndim == 4 else None)


def scoring_mask(mask: np.ndarray) -> np.ndarray:
    """(H, W) robot label image (0/1/2) → (256, 256) labels (nearest neighbour)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"expected an (H, W) label image, got shape {mask.shape}")
    return cv2.resize(mask.astype(np.uint8), (SCORING_SIZE, SCORING_SIZE), interpolation=cv2.INTER_NEAREST)


def project(world_xyz: np.ndarray, intrinsic: np.ndarray, extrinsic: np.ndarray,
            image_size: int | tuple[int, int]) -> np.ndarray:
    """A world point → (x, y) in the scoring frame, through OpenCV intrinsics (3×3) and world→camera
    extrinsics (3×4) of a camera whose images are `image_size` = (width, height) px (an int: square). Each axis
    is scaled as `cv2.resize` scales it into the 256×256 frame. Raises if the point is behind the camera."""
    cam = np.asarray(extrinsic, np.float64).reshape(3, 4) @ np.append(np.asarray(world_xyz, np.float64)[:3], 1.0)
    if cam[2] <= 0:
        raise ValueError(f"point {world_xyz} is behind the camera (depth {cam[2]:.3f} m)")
    uv = (np.asarray(intrinsic, np.float64).reshape(3, 3) @ cam)[:2] / cam[2]
    size = np.broadcast_to(np.asarray(image_size, np.float64), (2,))
    return (uv + 0.5) * (SCORING_SIZE / size) - 0.5


def frame_xy(object_px: tuple[float, float], width: int, height: int) -> tuple[float, float]:
    """A 256² scoring-frame position → the same point in a W×H frame (pixel centres at integers): `project`'s
    scaling undone."""
    x, y = object_px
    return (x + 0.5) * width / SCORING_SIZE - 0.5, (y + 0.5) * height / SCORING_SIZE - 0.5


def frame_size(frame: np.ndarray) -> tuple[int, int]:
    """(width, height) of an (H, W[, C]) image: the `image_size` its camera's points project with."""
    return int(frame.shape[1]), int(frame.shape[0])


def query_grid(center: np.ndarray, radius: float = QUERY_RADIUS) -> np.ndarray:
    """The 3×3 query grid around `center` (x, y), spaced so that its corners lie on `radius`: (9, 2)."""
    s = radius / np.sqrt(2.0)
    off = np.array([(dx, dy) for dy in (-s, 0.0, s) for dx in (-s, 0.0, s)])
    return (np.asarray(center, np.float64)[None] + off).astype(np.float32)


def arm_grid(mask: np.ndarray) -> np.ndarray:
    """Seed points on the distal-arm label (2) of a robot mask: a grid of `ARM_GRID_STEP` px on the label
    eroded by `ARM_ERODE` px, in the scoring frame: (N, 2), possibly N = 0."""
    distal = (scoring_mask(mask) == DISTAL_LABEL).astype(np.uint8)
    distal = cv2.erode(distal, np.ones((2 * ARM_ERODE + 1, 2 * ARM_ERODE + 1), np.uint8))
    ys, xs = np.nonzero(distal)
    on_grid = (xs % ARM_GRID_STEP == ARM_GRID_STEP // 2) & (ys % ARM_GRID_STEP == ARM_GRID_STEP // 2)
    return np.stack([xs[on_grid], ys[on_grid]], axis=1).astype(np.float32)


def textured(grey: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Which points have a window with trackable texture (LK's minimum eigenvalue ≥ `MIN_EIG`)."""
    if len(points) == 0:
        return np.zeros(0, bool)
    _, _, eig = cv2.calcOpticalFlowPyrLK(grey, grey, points, None, flags=cv2.OPTFLOW_LK_GET_MIN_EIGENVALS,
                                         minEigThreshold=0.0, maxLevel=0, **_LK)
    return eig.reshape(-1) >= MIN_EIG


def _lk(a: np.ndarray, b: np.ndarray, pts: np.ndarray, guess: np.ndarray, levels: int, err_max: float
        ) -> tuple[np.ndarray, np.ndarray]:
    """Track `pts` from a to b (starting at `guess`) and back (starting at `pts`, so that an anchored point's
    backward track need not capture its whole displacement since frame 0); positions in b and visibility."""
    fwd, st_f, err = cv2.calcOpticalFlowPyrLK(a, b, pts, guess.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                              maxLevel=levels, **_LK)
    back, st_b, _ = cv2.calcOpticalFlowPyrLK(b, a, fwd, pts.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                             maxLevel=levels, **_LK)
    dx, dy = (back - pts).T  # |back − pts|: np.linalg.norm(axis=1)'s float32 arithmetic, without its overhead
    fb = np.sqrt(dx * dx + dy * dy)
    ok = (st_f.reshape(-1) == 1) & (st_b.reshape(-1) == 1) & (fb < FB_MAX) & (err.reshape(-1) < err_max)
    return fwd, ok & np.isfinite(fwd).all(axis=1)


@dataclass
class Tracks:
    """Point tracks in the scoring frame: positions (T, N, 2) (last visible value where not visible) and
    visibility (T, N); frame 0 holds the query points, visible where textured."""

    positions: np.ndarray
    visible: np.ndarray


def track(grey: np.ndarray, points: np.ndarray, *, anchored: bool) -> Tracks:
    """Track `points` (N, 2) from frame 0 of a scoring-frame video (T, 256, 256) (see the module doc)."""
    if grey.ndim != 3 or grey.shape[1:] != (SCORING_SIZE, SCORING_SIZE) or grey.dtype != np.uint8:
        raise ValueError(f"expected a (T, {SCORING_SIZE}, {SCORING_SIZE}) uint8 video (see scoring_frames), "
                         f"got {grey.dtype} {grey.shape}")
    points = np.asarray(points, np.float32).reshape(-1, 2)
    T, n = len(grey), len(points)
    pos = np.repeat(points[None], T, axis=0)
    vis = np.zeros((T, n), bool)
    vis[0] = textured(grey[0], points)
    alive = vis[0].copy()
    for t in range(1, T):
        if not alive.any():
            pos[t:] = pos[t - 1]
            break
        idx = np.nonzero(alive)[0]
        if anchored:
            p, ok = _lk(grey[0], grey[t], points[idx], pos[t - 1, idx], ANCHORED_LEVELS, ERR_MAX)
        else:
            p, ok = _lk(grey[t - 1], grey[t], pos[t - 1, idx], pos[t - 1, idx], CHAINED_LEVELS, np.inf)
            alive[idx[~ok]] = False  # chained: a lost point never comes back
        pos[t] = pos[t - 1]
        pos[t, idx[ok]] = p[ok]
        vis[t, idx[ok]] = True
    return Tracks(pos, vis)


def centroid_path(tracks: Tracks, *, anchored: bool) -> np.ndarray:
    """(T, 2) centroid: frame 0's centroid of the textured points, moved by the mean displacement of the
    visible points (from frame 0 when anchored, from t−1 when chained); carried forward when none is visible."""
    pos, vis = tracks.positions, tracks.visible
    T = len(pos)
    out = np.zeros((T, 2))
    if not vis[0].any():
        out[:] = pos[0].mean(axis=0) if pos.shape[1] else np.nan
        return out
    out[0] = pos[0, vis[0]].mean(axis=0)
    for t in range(1, T):
        v = vis[t]
        if not v.any():
            out[t] = out[t - 1]
        elif anchored:
            out[t] = out[0] + (pos[t, v] - pos[0, v]).mean(axis=0)
        else:
            out[t] = out[t - 1] + (pos[t, v] - pos[t - 1, v]).mean(axis=0)
    return out


TrackFn = Callable[..., "Tracks"]  # (video, points, *, anchored) -> Tracks: `track` or a backend's


@dataclass
class ColourModel:
    """The evaluated object's colour (Lab, float) and its frame-0 region: area (px²), centroid (x, y), shape
    (a binary crop of the region, uint8; None when the robot touches the region in frame 0, which may then
    show only part of the object) and the centroid's offset in that crop (x, y); plus what is background
    for `occlusion_fit`: the whole frame 0 in Lab (256, 256, 3) and the colours around the region (K, 3)."""

    lab: np.ndarray
    area: int
    centre: np.ndarray
    shape: np.ndarray | None
    shape_centre: np.ndarray
    lab0: np.ndarray
    surround: np.ndarray


def to_lab(rgb: np.ndarray) -> np.ndarray:
    """An RGB image (uint8) in CIE Lab (float32; L 0–100)."""
    return cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB)


def _squared_delta_e(planes: list[np.ndarray], colour: np.ndarray) -> np.ndarray:
    """Squared CIE76 distance of a Lab image, given as its three planes, to `colour` (one Lab colour, or an image
    of them), summed L, a, b in that order: the float32 arithmetic of `np.linalg.norm(lab - colour, axis=-1)`
    before its square root, so thresholds decide exactly as the norm did, at a fraction of its cost."""
    colour = np.asarray(colour, np.float32)
    d = planes[0] - colour[..., 0]
    s = d * d
    for k in (1, 2):
        np.subtract(planes[k], colour[..., k], out=d)
        s += d * d
    return s


def _planes(lab: np.ndarray) -> list[np.ndarray]:
    return list(cv2.split(lab))


def _near(lab: np.ndarray, colour: np.ndarray, delta_e: float) -> np.ndarray:
    """Which pixels of a Lab image lie within CIE76 `delta_e` of `colour` (one Lab colour, or an image of them)."""
    return np.sqrt(_squared_delta_e(_planes(lab), colour)) < delta_e


def _colour_mask(rgb: np.ndarray, lab: np.ndarray) -> np.ndarray:
    return _near(to_lab(rgb), lab, COLOUR_DELTA_E).astype(np.uint8)


def colour_model(rgb0: np.ndarray, object_px: np.ndarray, robot_mask0: np.ndarray) -> ColourModel | None:
    """The object's colour model from frame 0 (RGB, scoring frame), or None when its colour is not distinct:
    the region of that colour around `object_px` is tiny or leaks beyond `REGION_RADIUS_MAX`, or the colour
    covers more than `ROBOT_COLOUR_MAX` of the robot (`robot_mask0`, any size, labels > 0)."""
    x, y = (int(round(v)) for v in object_px)
    k = COLOUR_PATCH
    if not (k <= x < SCORING_SIZE - k and k <= y < SCORING_SIZE - k):
        return None
    lab0 = to_lab(rgb0)
    lab = np.median(lab0[y - k:y + k + 1, x - k:x + k + 1].reshape(-1, 3), axis=0)
    match = _near(lab0, lab, COLOUR_DELTA_E).astype(np.uint8)
    _, labels = cv2.connectedComponents(match, connectivity=8)
    ids = labels[y - k:y + k + 1, x - k:x + k + 1].ravel()
    if not (ids > 0).any():
        return None
    region = labels == np.bincount(ids[ids > 0]).argmax()
    ys, xs = np.nonzero(region)
    if len(xs) < REGION_AREA_MIN or np.hypot(xs - object_px[0], ys - object_px[1]).max() > REGION_RADIUS_MAX:
        return None
    robot = scoring_mask(robot_mask0) > 0
    if robot.any() and match[robot].mean() > ROBOT_COLOUR_MAX:
        return None
    away = cv2.distanceTransform((~region).astype(np.uint8), cv2.DIST_L2, 3)
    ring = (away > SURROUND_RING[0]) & (away <= SURROUND_RING[1])
    surround = np.unique(np.round(lab0[ring] / 2.0), axis=0) * 2.0  # distinct colours, to 2 ΔE
    centre = np.array([xs.mean(), ys.mean()])
    hidden0 = bool((robot & (away <= HIDDEN_AT_START)).any())  # the robot touches it in frame 0
    shape = None if hidden0 else region[ys.min():ys.max() + 1, xs.min():xs.max() + 1].astype(np.uint8)
    return ColourModel(lab, len(xs), centre, shape, centre - (xs.min(), ys.min()), lab0, surround.astype(np.float32))


def occlusion_fit(rgb: np.ndarray, visible: np.ndarray, model: ColourModel, estimate: np.ndarray) -> np.ndarray:
    """Where a partly hidden object is: the translation of its frame-0 shape (`model.shape`), within one shape
    size of `estimate` (the visible part's centroid), that covers the most pixels of `visible` (the object's
    region in this frame, (256, 256) bool) minus the background pixels it lies on (a pixel of neither the
    object's colour nor a possible occluder: within `BACKGROUND_DELTA_E` of frame 0 at its place or of the
    object's surroundings); ties go to the translation nearest `estimate`. Returns the object's centre (x, y),
    on the integer grid of translations; `estimate` where the search window leaves the frame."""
    h, w = model.shape.shape
    r = max(h, w)
    left, top = (int(round(v)) - r for v in np.asarray(estimate) - model.shape_centre)
    x0, y0 = max(left, 0), max(top, 0)
    x1, y1 = min(left + 2 * r + w + 1, SCORING_SIZE), min(top + 2 * r + h + 1, SCORING_SIZE)
    if x1 - x0 < w or y1 - y0 < h:
        return np.asarray(estimate, np.float64)
    planes = _planes(to_lab(rgb[y0:y1, x0:x1]))
    coloured = np.sqrt(_squared_delta_e(planes, model.lab)) < COLOUR_DELTA_E
    unchanged = np.sqrt(_squared_delta_e(planes, model.lab0[y0:y1, x0:x1])) < BACKGROUND_DELTA_E
    nearest = np.full(planes[0].shape, np.inf, np.float32)  # to the nearest surrounding colour (sqrt is monotone)
    for k in range(0, len(model.surround), SURROUND_BATCH):  # colours broadcast over the window, a batch at a time
        batch = model.surround[k:k + SURROUND_BATCH, None, None, :]
        np.minimum(nearest, _squared_delta_e(planes, batch).min(axis=0), out=nearest)
    like_surround = np.sqrt(nearest) < BACKGROUND_DELTA_E
    background = (~coloured & (unchanged | like_surround)).astype(np.float32)
    shape = model.shape.astype(np.float32)
    score = (2 * cv2.matchTemplate(visible[y0:y1, x0:x1].astype(np.float32), shape, cv2.TM_CCORR)
             - cv2.matchTemplate(background, shape, cv2.TM_CCORR))
    ys, xs = np.nonzero(score >= score.max() - 0.5)  # the scores are integers: ties within float error
    centres = np.stack([xs + x0, ys + y0], axis=1) + model.shape_centre
    return centres[np.argmin(np.linalg.norm(centres - estimate, axis=1))]


def region_tracks(rgb: np.ndarray, points: np.ndarray, model: ColourModel) -> Tracks:
    """The query points moved rigidly with the object's colour region through an RGB scoring-frame video: in
    each frame the region of the object's colour nearest its last position (within `REGION_JUMP_MAX`, at least
    `REGION_PART_MIN` of its frame-0 area), placed by its centroid, or by `occlusion_fit` when smaller than
    `FIT_PART_MAX` of its frame-0 area and the frame-0 shape is whole (`model.shape`); none: invisible, last
    position kept."""
    points = np.asarray(points, np.float32).reshape(-1, 2)
    T = len(rgb)
    pos = np.repeat(points[None], T, axis=0)
    vis = np.zeros((T, len(points)), bool)
    vis[0] = True
    last = model.centre.copy()
    min_area = max(2.0, REGION_PART_MIN * model.area)
    for t in range(1, T):
        x0, y0 = (max(int(v) - REGION_SEARCH, 0) for v in last)
        x1, y1 = (min(int(v) + REGION_SEARCH + 1, SCORING_SIZE) for v in last)
        _, labels, stats, centres = cv2.connectedComponentsWithStats(
            _colour_mask(rgb[t, y0:y1, x0:x1], model.lab), connectivity=8)
        found = [k for k in range(1, len(stats)) if stats[k, cv2.CC_STAT_AREA] >= min_area]
        dist = [float(np.linalg.norm(centres[k] + (x0, y0) - last)) for k in found]
        if not dist or min(dist) > REGION_JUMP_MAX:
            pos[t] = pos[t - 1]
            continue
        k = found[int(np.argmin(dist))]
        last = centres[k] + (x0, y0)  # the search follows the visible part
        at = last
        if model.shape is not None and stats[k, cv2.CC_STAT_AREA] < FIT_PART_MAX * model.area:
            visible = np.zeros((SCORING_SIZE, SCORING_SIZE), bool)
            visible[y0:y1, x0:x1] = labels == k
            at = occlusion_fit(rgb[t], visible, model, last)
        pos[t] = points + (at - model.centre).astype(np.float32)
        vis[t] = True
    return Tracks(pos, vis)


def object_tracks(video: ScoringVideo | np.ndarray, object_px: np.ndarray, robot_mask0: np.ndarray | None = None
                  ) -> Tracks:
    """The default tracker on the evaluated object: the 3×3 grid around `object_px` by its colour region when
    the colour is distinct (`colour_model`; needs an RGB video and the reference's frame-0 robot mask), else
    by anchored LK on the grey video, from a grid of radius `LK_QUERY_RADIUS`."""
    if isinstance(video, ScoringVideo):
        rgb0 = video.first_rgb
        if rgb0 is not None and robot_mask0 is not None:
            model = colour_model(rgb0, object_px, robot_mask0)
            if model is not None:
                return region_tracks(video.rgb, query_grid(object_px), model)
        video = video.grey
    return track(video, query_grid(object_px, LK_QUERY_RADIUS), anchored=True)


def object_path(video: ScoringVideo | np.ndarray, object_px: np.ndarray, robot_mask0: np.ndarray | None = None,
                tracker=None) -> tuple[Tracks, np.ndarray]:
    """The evaluated object's tracks (`object_tracks`, or a backend's `track_object`) and its centroid path
    (T, 2)."""
    tracks = (tracker.track_object(video, object_px, robot_mask0) if tracker
              else object_tracks(video, object_px, robot_mask0))
    return tracks, centroid_path(tracks, anchored=True)


@dataclass
class ObjectMotion:
    """The evaluated object's track: d (px), the visible fraction of frames (≥ 1 visible point), the
    number of textured query points at frame 0 (all 9 when the colour region tracks it), and its centroid's
    displacement from frame 0 in every frame (T, 2) in the scoring frame."""

    displacement: float
    visible_fraction: float
    textured_points: int
    path: np.ndarray


def object_motion(video: ScoringVideo | np.ndarray, object_px: np.ndarray, robot_mask0: np.ndarray | None = None,
                  tracker=None) -> ObjectMotion:
    """d = max over frames of ‖centroid_t − centroid_0‖ for the evaluated object (`object_path`)."""
    tracks, c = object_path(video, object_px, robot_mask0, tracker)
    d = float(np.linalg.norm(c - c[0], axis=1).max())
    return ObjectMotion(d, float(tracks.visible.any(axis=1).mean()), int(tracks.visible[0].sum()), c - c[0])


def gate_frames(num_frames: int) -> tuple[int, int, int]:
    """The three gate frames: first, middle, last."""
    return 0, (num_frames - 1) // 2, num_frames - 1


def motion_gate(video: ScoringVideo | np.ndarray, reference_mask0: np.ndarray, track_fn: TrackFn | None = None,
                hands: np.ndarray | None = None) -> float:
    """g = max pairwise distance, over the gate frames, of the distal-arm centroid tracked (chained) from a
    grid seeded at frame 0 on the reference mask's label 2. No seed point or no texture: g = 0.

    `hands` (K, 2): on a K-arm robot, each hand's frame-0 position in the scoring frame; each seed point
    belongs to the nearest hand, each hand has its own centroid, and g is the largest hand's g (one centroid
    over two hands moving toward each other barely moves; a frozen or arm-less video still fails every hand)."""
    seeds = arm_grid(reference_mask0)
    if track_fn is None:
        video = video.grey if isinstance(video, ScoringVideo) else video
    tracks = (track_fn or track)(video, seeds, anchored=False)
    if hands is None:
        return _gate(tracks)
    owner = nearest_hand(seeds, hands)
    return max((_gate(Tracks(tracks.positions[:, owner == k], tracks.visible[:, owner == k]))
                for k in range(len(hands))), default=0.0)


def nearest_hand(points: np.ndarray, hands: np.ndarray) -> np.ndarray:
    """For each of `points` (N, 2), the index of the nearest of `hands` (K, 2), in the same coordinates."""
    return np.linalg.norm(np.asarray(points, np.float64)[:, None] - np.asarray(hands, np.float64)[None],
                          axis=-1).argmin(axis=1)


def _gate(tracks: Tracks) -> float:
    if not tracks.visible[0].any():
        return 0.0
    c = centroid_path(tracks, anchored=False)[list(gate_frames(len(tracks.positions)))]
    return float(max(np.linalg.norm(c[i] - c[j]) for i in range(3) for j in range(i + 1, 3)))


@dataclass
class T4Score:
    """One rollout's T4 score and its parts; `shifts` is the object's tracked displacement from frame 0 in every
    frame (T, 2), in the scoring frame."""

    score: float
    displacement: float
    gate: float
    gate_passed: bool
    visible_fraction: float
    tracked: bool
    shifts: np.ndarray


def t4_score(frames: np.ndarray, object_px: np.ndarray, reference_mask0: np.ndarray,
             gate_reference: float, visible_reference: float | None = None, tracker=None,
             hands: np.ndarray | None = None) -> T4Score:
    """S = 100·1[g ≥ GATE_RATIO·g_ref]·1[tracked]·1[d ≤ MOTION_MAX] for one video (any size; resized to 256²).
    `object_px`: the evaluated object's frame-0 position in the scoring frame; `reference_mask0`: the
    reference robot label mask at frame 0; `gate_reference`: g of the reference (stored per instance);
    `visible_reference`: the fraction of reference frames in which the same tracker sees the object (None
    skips the tracking-failure rule, as the builder does on the reference itself); `tracker`: a tracker
    backend (`wsp_eval.backends.tracker`; default this module's colour region + Lucas–Kanade); `hands`: each
    hand's frame-0 pixel on a robot with more than one arm (`motion_gate`)."""
    if not gate_reference > 0:
        raise ValueError(f"gate_reference must be positive, got {gate_reference}")
    video = tracker.prepare(frames) if tracker else scoring_video(frames)
    motion = object_motion(video, object_px, reference_mask0, tracker)
    g = motion_gate(video, reference_mask0, tracker.track if tracker else None, hands)
    passed = g >= GATE_RATIO * gate_reference
    tracked = visible_reference is None or motion.visible_fraction >= TRACKED_RATIO * visible_reference
    ok = passed and tracked and motion.displacement <= MOTION_MAX
    return T4Score(100.0 * ok, motion.displacement, g, bool(passed), motion.visible_fraction, bool(tracked),
                   motion.path)
