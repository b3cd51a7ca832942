"""T4 point tracking (SPEC §3 T4), simulator-free: the default tracker backend (OpenCV pyramidal
Lucas–Kanade with a forward–backward check), the object displacement d, the distal-arm motion gate g and
the per-rollout score S = 100·1[g ≥ 0.5·g_ref]·1[d ≤ 10].

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
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

SCORING_SIZE = 256  # px: the square frame every video is scored in
QUERY_RADIUS = 10.0  # px: the 3×3 query grid fits in this radius (corner points exactly on it)
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
#   which the reference's is visible is a tracking failure (S = 0; SPEC §3 T4 counts tracking failures in the
#   mean). Without it an object that vanishes, or is carried away under the fingers, would keep its last
#   centroid and pass: measured, the action-blind baseline (the source rollout: no distractor, target grasped
#   or still at its original place) scored 75 on T4 without the rule.
ARM_GRID_STEP = 4  # px: spacing of the distal-arm seed grid
ARM_ERODE = 2  # px: the distal-arm mask is eroded by this before seeding (no points on its outline)
DISTAL_LABEL = 2  # robot mask label of wrist, hand and fingers

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


def scoring_mask(mask: np.ndarray) -> np.ndarray:
    """(H, W) robot label image (0/1/2) → (256, 256) labels (nearest neighbour)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"expected an (H, W) label image, got shape {mask.shape}")
    return cv2.resize(mask.astype(np.uint8), (SCORING_SIZE, SCORING_SIZE), interpolation=cv2.INTER_NEAREST)


def project(world_xyz: np.ndarray, intrinsic: np.ndarray, extrinsic: np.ndarray, image_size: int) -> np.ndarray:
    """A world point → (x, y) in the scoring frame, through OpenCV intrinsics (3×3) and world→camera
    extrinsics (3×4) of a square `image_size` camera. Raises if the point is behind the camera."""
    cam = np.asarray(extrinsic, np.float64).reshape(3, 4) @ np.append(np.asarray(world_xyz, np.float64)[:3], 1.0)
    if cam[2] <= 0:
        raise ValueError(f"point {world_xyz} is behind the camera (depth {cam[2]:.3f} m)")
    uv = (np.asarray(intrinsic, np.float64).reshape(3, 3) @ cam)[:2] / cam[2]
    return (uv + 0.5) * (SCORING_SIZE / image_size) - 0.5


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
    fb = np.linalg.norm(back - pts, axis=1)
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


@dataclass
class ObjectMotion:
    """The evaluated object's track: d (px), the visible fraction of frames (≥ 1 visible point), and the
    number of textured query points at frame 0."""

    displacement: float
    visible_fraction: float
    textured_points: int


TrackFn = Callable[..., "Tracks"]  # (video, points, *, anchored) -> Tracks: `track` or a backend's


def object_path(grey: np.ndarray, object_px: np.ndarray, track_fn: TrackFn | None = None
                ) -> tuple[Tracks, np.ndarray]:
    """The 3×3 grid around `object_px` tracked (anchored) through a scoring-frame video, and its centroid path
    (T, 2)."""
    tracks = (track_fn or track)(grey, query_grid(object_px), anchored=True)
    return tracks, centroid_path(tracks, anchored=True)


def object_motion(grey: np.ndarray, object_px: np.ndarray, track_fn: TrackFn | None = None) -> ObjectMotion:
    """d = max over frames of ‖centroid_t − centroid_0‖ for the 3×3 grid around `object_px` (anchored)."""
    tracks, c = object_path(grey, object_px, track_fn)
    d = float(np.linalg.norm(c - c[0], axis=1).max())
    return ObjectMotion(d, float(tracks.visible.any(axis=1).mean()), int(tracks.visible[0].sum()))


def gate_frames(num_frames: int) -> tuple[int, int, int]:
    """The three gate frames: first, middle, last."""
    return 0, (num_frames - 1) // 2, num_frames - 1


def motion_gate(grey: np.ndarray, reference_mask0: np.ndarray, track_fn: TrackFn | None = None) -> float:
    """g = max pairwise distance, over the gate frames, of the distal-arm centroid tracked (chained) from a
    grid seeded at frame 0 on the reference mask's label 2. No seed point or no texture: g = 0."""
    seeds = arm_grid(reference_mask0)
    tracks = (track_fn or track)(grey, seeds, anchored=False)
    if not tracks.visible[0].any():
        return 0.0
    c = centroid_path(tracks, anchored=False)[list(gate_frames(len(grey)))]
    return float(max(np.linalg.norm(c[i] - c[j]) for i in range(3) for j in range(i + 1, 3)))


@dataclass
class T4Score:
    """One rollout's T4 score and its parts."""

    score: float
    displacement: float
    gate: float
    gate_passed: bool
    visible_fraction: float
    tracked: bool


def t4_score(frames: np.ndarray, object_px: np.ndarray, reference_mask0: np.ndarray,
             gate_reference: float, visible_reference: float | None = None, tracker=None) -> T4Score:
    """S = 100·1[g ≥ GATE_RATIO·g_ref]·1[tracked]·1[d ≤ MOTION_MAX] for one video (any size; resized to 256²).
    `object_px`: the evaluated object's frame-0 position in the scoring frame; `reference_mask0`: the
    reference robot label mask at frame 0; `gate_reference`: g of the reference (stored per instance);
    `visible_reference`: the fraction of reference frames in which the object is visible (stored per instance;
    None skips the tracking-failure rule, as the builder does on the reference itself); `tracker`: a tracker
    backend (`wsp_eval.backends.tracker`; default this module's Lucas–Kanade)."""
    if not gate_reference > 0:
        raise ValueError(f"gate_reference must be positive, got {gate_reference}")
    video = tracker.prepare(frames) if tracker else scoring_frames(frames)
    fn = tracker.track if tracker else track
    motion = object_motion(video, object_px, fn)
    g = motion_gate(video, reference_mask0, fn)
    passed = g >= GATE_RATIO * gate_reference
    tracked = visible_reference is None or motion.visible_fraction >= TRACKED_RATIO * visible_reference
    ok = passed and tracked and motion.displacement <= MOTION_MAX
    return T4Score(100.0 * ok, motion.displacement, g, bool(passed), motion.visible_fraction, bool(tracked))
