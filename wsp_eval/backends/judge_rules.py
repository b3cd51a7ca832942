"""The deterministic default primitive judge (spec §4.5, §4.6): `RulesJudge`.

It sees only what the paper's VLM sees — the 12 sampled frames (RGB uint8, any size) and the evaluated object's
frame-0 position in the 256×256 scoring frame — never the action stream, robot masks, simulator state or the
intended label. Everything runs on a 128×128 working copy of the frames (the references' native size); all
pixel thresholds below are in that frame.

Features (all measured from the images; `features()` returns them, the verdict carries them as evidence):
1. **Object track.** A colour model of the object is taken at its frame-0 position: the colours of the central
   pixels (r ≤ 3.5 px) that differ from a palette of the surrounding ring (6–12 px; the ring's pixels that look
   like the object's centre are left out, so a large object does not end up in its own background). Greyish
   centre pixels are dropped when the object has chromatic ones (they are the gripper passing in front). In
   every frame a pixel is "object" when its colour is near the object palette and clearly nearer to it than to
   the background palette; the connected component nearest the last position (within `MAX_JUMP`) is the
   object; frame-0 components of the same colour elsewhere (a second blue object) are masked out. Per frame:
   centroid, area, outline shape. Lost or shrunk (< half its frame-0 area) = hidden, mostly by the gripper.
2. **Robot.** A pixel is "robot" when it is unsaturated now but shows a saturated colour (table, object) in
   some frame: the white/grey/black arm covering the coloured scene. Its distance to the object per frame
   says whether the hand reached the object (`rd_min`) and whether it left it (`rd_end`); a thin unsaturated
   rim right around the object is its own blurred edge and does not count. Arm motion:
   the largest fraction of pixels changing by > `DIFF_LEVEL` grey levels between consecutive frames.
3. **Object path** relative to the robot, which stands at the top centre of the view (the direction `u` from
   there to the object is "away from the base", `v` its perpendicular): final displacement along `u` and `v`,
   largest excursion, lateral excursion, rise-and-return in the image (`ret_up`), the last step (an object
   still moving at the end moves by itself), the largest single step (abrupt = a fall), change of area and of
   the outline's normalised second moments (elongation and orientation: a tall object that tips over).
4. **Hand oscillation.** Dense optical flow (OpenCV DIS) between consecutive frames, averaged in a disc around
   the object: direction reversals of its lateral component (a shake, even when the object is hidden).
5. **Appearance change** of the object's window between the first and the last frame (a rotated object looks
   different in place; a static one does not).

Decision (first rule that holds; `classify`):
- moved (displacement ≥ `MOVE_DISP`):
  tap (still moving in the last frame, or travelled ≥ `TAP_DISP`) → knock-over (its outline or area changed,
  and the move was abrupt or the object ends clear of the hand) → drag (mostly sideways) → push (away from the
  robot) / pull;
- in place: shake (lateral excursion or hand oscillation) → drop (rose and came back down, or hidden for most
  of the clip and back in place at the end) → rotate (the fallback, object stays put).
`agent_ok`: the arm visibly moves and the robot reaches the object (for tap: and is clear of the ball at the
end). `object_ok`: the label's own object evidence holds (for rotate, the fallback: the object stays in place,
is visible at the end and changed appearance). A static video therefore fails both; a video that cannot be
read, or whose object cannot be found in frame 0, gets label None.

Known limit: "toward the robot" is read as "toward the top of the image". That holds for ManiSkill's base
cameras in front of the robot, but PullCube's camera sits behind the robot, where push and pull are mirrored
(and a tap rolls away behind the hand): those clips are misjudged.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wsp_eval.backends.judge import Verdict

WORK_SIZE = 128  # px: every video is resized to this square (the references' native size) before measuring
SCORING_SIZE = 256  # px: the frame `object_px` is given in

# -- object colour model and tracking -------------------------------------------------------------------------
L_WEIGHT = 0.5  # weight of Lab lightness in colour distances: the faces of one object differ mostly in shading
CORE_R = 3.5  # px: the object's colour is read within this radius of its frame-0 position (a cube is ~4-6 px)
RING_R = (6.0, 12.0)  # px: the background palette comes from this ring around it
BG_EXCLUDE = 20.0  # ring pixels nearer than this to the object's centre colour belong to the object (a tall box
#   spans the ring), not to the background
OBJ_MIN_SEP = 15.0  # a central pixel joins the object palette only this far from every background colour
CHROMA_MIN = 20.0  # greyish central pixels (chroma below) are dropped when chromatic ones exist: the gripper
BG_PALETTE, OBJ_PALETTE = 24, 12  # colours kept in each palette (evenly over the sorted samples)
OBJ_TOL = 14.0  # a pixel is object when within this of the object palette (a cube's faces are ≤ 12 apart) …
OBJ_RATIO = 0.6  # … and nearer to it than this fraction of its distance to the background palette (wood grain)
MAX_JUMP = 16.0  # px per sampled frame: a tapped ball moves ≤ 13 px between the 12 frames (measured, tune set)
HIDDEN_AREA = 0.5  # a frame where the object's area is below this fraction of frame 0 counts as hidden

# -- robot ----------------------------------------------------------------------------------------------------
ROBOT_SAT_MAX = 40  # HSV saturation (0-255) below which a pixel can be the (white/grey/black) robot: the Panda's
#   links measure ≤ 10, the wooden table ≥ 150 and the objects ≥ 160
COLOURED_SAT_MIN = 80  # … and it must show a saturated colour in some frame (so grey floor and white target
#   rings, which never do, are not robot)
OBJECT_RIM = 2.0  # px around the object (half its size + this) where unsaturated pixels are its blurred rim, not robot
DIFF_LEVEL = 15  # grey levels: a pixel "changes" between consecutive frames above this (codec noise ≤ ~5)
FLOW_DISC = 8.0  # px: optical flow is averaged within this radius of the object (the hand around a grasp)

# -- decision thresholds -------------------------------------------------------------------------------------
# Tuned on instances 0-31 of a 48-instance build (4 per primitive): each threshold sits at about the geometric
# mean of the nearest tune-set values on either side of the two groups it separates (the values are quoted).
MOVE_DISP = 3.5  # px: the object moved. Moving primitives ≥ 4.8 px, in-place ones ≤ 2.8 px (a dropped ball rolls)
TAP_END_STEP = 3.0  # px: still moving between the last two frames. Taps ≥ 8.6 px, every other clip ≤ 0.9 px
TAP_DISP = 18.0  # px: travelled this far. Taps ≥ 23 px, every other clip ≤ 14 px
KNOCK_SHAPE = 0.45  # shape change — max(|Δ normalised second moments|, |log area ratio|), first vs last frame: a
#   tall object that tips shows a new outline. Knock-overs ≥ 0.56; pushes ≤ 0.38 (a hand still covering a pulled
#   or dragged object changes its outline too, hence the second condition:)
ABRUPT = 0.8  # … with one step carrying this fraction of the displacement (a fall): knock-overs ≥ 0.94 (3 of
#   4), every other moving clip ≤ 0.61 …
KNOCK_CLEAR = 11.0  # … or the hand this far (px) from the object at the end: knock-overs ≥ 13, pushes, pulls
#   and drags ≤ 9.7 (the hand follows them; a struck box falls away from it)
LAT_RATIO = 1.0  # sideways when |along v| ≥ this × |along u|. Drags ≥ 2.5, pushes and pulls ≤ 0.46
SHAKE_LAT = 3.5  # px of lateral excursion while ending in place. Shakes ≥ 4.4 px, other in-place ≤ 2.6 px
SHAKE_FLOW_REV, SHAKE_FLOW_MIN = 2, 3.0  # or ≥ 2 lateral flow reversals near the object with a ≥ 3 px/frame
#   lateral flow: shakes 2 (3 of 4), every other tune clip ≤ 1
FLOW_REV_HYST = 3.0  # px: a reversal of the cumulative lateral flow must retreat this far
DROP_RISE = 1.5  # px the object rose in the image and came back. Drops ≥ 2.0 (or hidden), rotates ≤ 1.06
HIDDEN_DROP = 0.65  # or hidden in this fraction of the frames (lifted inside the hand). Drop 0.82, rotates ≤ 0.55
ROT_APP_MIN = 6.0  # Lab units: mean change of the object's window, first vs last frame. Rotates ≥ 11; static
#   regions of the references change by < 0.1 (measured; rendered and encoded identically)
ARM_MOTION_MIN = 0.01  # fraction of the frame changing between consecutive frames: references ≥ 0.04, static 0
APPROACH = 4.0  # px beyond half the object's size: the robot came this near the object. Tune set ≤ 2.6 px
TAP_CLEAR = 2.0  # × the object's size: for a tap the hand is this far from the ball at the end. Taps ≥ 5.7× (the
#   PullCube tap aside, which rolls behind the hand and is misjudged anyway)


@dataclass(frozen=True)
class Track:
    pos: np.ndarray  # (T, 2) centroid x, y (NaN when not found)
    area: np.ndarray  # (T,) pixels (0 when not found)
    shape: np.ndarray  # (T, 2, 2) second moments of the object's pixels over their trace (NaN when < 3 pixels)


def prepare(frames) -> np.ndarray | None:
    """Any (T, H, W[, C]) array → (T, 128, 128, 3) uint8 RGB (non-finite values → 0, clipped to 0-255), or None
    when it cannot be a video."""
    try:
        v = np.asarray(frames)
        if v.ndim == 3:
            v = v[..., None]
        if v.ndim != 4 or v.shape[0] < 1 or v.shape[1] < 2 or v.shape[2] < 2 or v.shape[3] not in (1, 3, 4):
            return None
        if v.dtype != np.uint8:
            v = np.clip(np.nan_to_num(v.astype(np.float64), nan=0.0, posinf=255.0, neginf=0.0), 0, 255)
            v = v.astype(np.uint8)
    except (TypeError, ValueError):
        return None
    v = np.repeat(v, 3, axis=3) if v.shape[3] == 1 else v[..., :3]
    out = np.empty((len(v), WORK_SIZE, WORK_SIZE, 3), np.uint8)
    for t, f in enumerate(v):
        shrink = f.shape[0] > WORK_SIZE or f.shape[1] > WORK_SIZE
        out[t] = cv2.resize(np.ascontiguousarray(f), (WORK_SIZE, WORK_SIZE),
                            interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return out


def colour_dist(lab: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Lab distance with lightness down-weighted by `L_WEIGHT`."""
    d = lab - col
    return np.sqrt((L_WEIGHT * d[..., 0]) ** 2 + d[..., 1] ** 2 + d[..., 2] ** 2)


def _palette_dist(lab: np.ndarray, palette: np.ndarray) -> np.ndarray:
    best = np.full(lab.shape[:-1], np.inf, np.float32)
    for c in palette:
        np.minimum(best, colour_dist(lab, c), out=best)
    return best


def _spread(samples: np.ndarray, k: int) -> np.ndarray:
    """`k` samples evenly over `samples` sorted by (L, a, b): a deterministic small palette."""
    order = np.lexsort((samples[:, 2], samples[:, 1], samples[:, 0]))
    return samples[order][np.linspace(0, len(samples) - 1, min(k, len(samples))).round().astype(int)]


def object_model(lab0: np.ndarray, x0: float, y0: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(object palette, background palette) at frame 0, or None when the object does not stand out."""
    H, W = lab0.shape[:2]
    yy, xx = np.mgrid[:H, :W]
    r = np.hypot(xx - x0, yy - y0)
    core, centre_px = lab0[r <= CORE_R], lab0[r <= 2.0]
    ring = lab0[(r > RING_R[0]) & (r <= RING_R[1])]
    if len(core) == 0 or len(centre_px) == 0 or len(ring) == 0:
        return None
    ring = ring[colour_dist(ring, np.median(centre_px, 0)) > BG_EXCLUDE]
    if len(ring) < 8:
        return None
    bg = _spread(ring, BG_PALETTE)
    cand = core[_palette_dist(core, bg) > OBJ_MIN_SEP]
    if len(cand) == 0:
        return None
    chroma = np.hypot(cand[:, 1] - 128, cand[:, 2] - 128)
    if (chroma >= CHROMA_MIN).any():
        cand = cand[chroma >= CHROMA_MIN]
    return _spread(cand, OBJ_PALETTE), bg


def _object_masks(lab: np.ndarray, obj: np.ndarray, bg: np.ndarray) -> np.ndarray:
    d_obj = _palette_dist(lab, obj)
    out = np.zeros(lab.shape[:-1], np.uint8)
    idx = np.nonzero(d_obj < OBJ_TOL)
    if len(idx[0]):
        out[idx] = d_obj[idx] < OBJ_RATIO * _palette_dist(lab[idx], bg)
    return out


def _shape(comp: np.ndarray) -> np.ndarray:
    """Normalised second moments (covariance / trace) of a pixel set: elongation and orientation, not size."""
    ys, xs = np.nonzero(comp)
    if len(xs) < 3:
        return np.full((2, 2), np.nan)
    c = np.cov(np.stack([xs, ys]).astype(np.float64)) + np.eye(2) / 12.0
    return c / np.trace(c)


def track_object(lab: np.ndarray, x0: float, y0: float) -> Track | None:
    """Colour-component track of the object from its frame-0 position (None when it cannot be found)."""
    T, H, W = lab.shape[:3]
    model = object_model(lab[0], x0, y0)
    if model is None:
        return None
    masks = _object_masks(lab, *model)
    n, comp0, stats, cents = cv2.connectedComponentsWithStats(masks[0], connectivity=8)
    yy, xx = np.mgrid[:H, :W]
    near = comp0[np.hypot(xx - x0, yy - y0) <= CORE_R]
    near = near[near > 0]
    if len(near) == 0:
        return None
    k0 = int(np.argmax(np.bincount(near)))
    obj0 = comp0 == k0
    others = cv2.dilate(((masks[0] > 0) & ~obj0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    pos, area, shape = np.full((T, 2), np.nan), np.zeros(T), np.full((T, 2, 2), np.nan)
    pos[0], area[0], shape[0] = cents[k0], stats[k0, cv2.CC_STAT_AREA], _shape(obj0)
    last = pos[0]
    for t in range(1, T):
        n, comp, stats, cents = cv2.connectedComponentsWithStats((masks[t] & ~others).astype(np.uint8),
                                                                 connectivity=8)
        best, best_score = 0, 0.0
        for i in range(1, n):
            d = float(np.hypot(*(cents[i] - last)))
            score = stats[i, cv2.CC_STAT_AREA] / (1.0 + d / 4.0)  # big and near wins
            if d < MAX_JUMP and score > best_score:
                best, best_score = i, score
        if best:
            pos[t], area[t], shape[t] = cents[best], stats[best, cv2.CC_STAT_AREA], _shape(comp == best)
            last = pos[t]
    return Track(pos, area, shape)


def reversals(seq: np.ndarray, hyst: float) -> int:
    """Direction reversals of a 1-D path: a retreat of at least `hyst` from the running extreme of the current
    direction (jitter smaller than `hyst` never counts). NaNs are skipped."""
    seq = np.asarray(seq, np.float64)
    seq = seq[np.isfinite(seq)]
    if len(seq) < 3:
        return 0
    n, direction, lo, hi, ext = 0, 0, seq[0], seq[0], seq[0]
    for s in seq[1:]:
        if direction == 0:
            lo, hi = min(lo, s), max(hi, s)
            if s >= lo + hyst:
                direction, ext = 1, s
            elif s <= hi - hyst:
                direction, ext = -1, s
        elif direction * (s - ext) > 0:
            ext = s
        elif direction * (ext - s) >= hyst:
            n, direction, ext = n + 1, -direction, s
    return n


def _finite(x: float, default: float = 0.0) -> float:
    return float(x) if np.isfinite(x) else default


def features(frames, object_px) -> dict[str, float]:
    """Every measured feature (plain floats). `tracked` is 0 when the object could not be found in frame 0;
    `video` is 0 when the input is not a readable video."""
    v = prepare(frames)
    if v is None:
        return {"video": 0.0}
    T = len(v)
    x0, y0 = [(float(c) + 0.5) * WORK_SIZE / SCORING_SIZE - 0.5 for c in object_px]
    if not (np.isfinite(x0) and np.isfinite(y0)):
        return {"video": 1.0, "tracked": 0.0}
    grey = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in v]
    changed = [np.mean(np.abs(grey[t + 1].astype(np.int16) - grey[t]) > DIFF_LEVEL) for t in range(T - 1)]
    f = {"video": 1.0, "frames": float(T), "arm_motion": float(max(changed, default=0.0))}
    lab = np.stack([cv2.cvtColor(fr, cv2.COLOR_RGB2LAB) for fr in v]).astype(np.float32)
    tr = track_object(lab, x0, y0) if T >= 2 else None
    f["tracked"] = float(tr is not None)
    if tr is None:
        return f

    pos, area = tr.pos, tr.area
    vis = np.isfinite(pos[:, 0])
    p0, a0 = pos[0], area[0]
    s0 = float(np.sqrt(a0))
    u = p0 - np.array([WORK_SIZE / 2.0, 0.0])  # the robot stands at the top centre of the view
    u = u / max(float(np.linalg.norm(u)), 1e-6)
    vdir = np.array([-u[1], u[0]])
    last = int(np.nonzero(vis)[0][-1])
    rel = pos - p0
    d = rel[last]
    steps = [float(np.linalg.norm(pos[t + 1] - pos[t])) for t in range(T - 1) if vis[t] and vis[t + 1]]
    f.update(
        size=s0, disp=float(np.linalg.norm(d)), disp_u=float(d @ u), disp_v=float(d @ vdir),
        visible_end=float(last == T - 1),
        excursion=float(np.nanmax(np.linalg.norm(rel, axis=1))),
        lat_exc=float(np.nanmax(np.abs(rel @ vdir))),
        ret_up=float(np.nanmax(-rel[:, 1]) - max(0.0, -rel[last, 1])),
        max_step=max(steps, default=0.0),
        end_step=float(np.linalg.norm(pos[-1] - pos[-2])) if vis[-1] and vis[-2] else 0.0,
        area_change=float(np.log(max(area[last], 1.0) / a0)),
        shape_change=_finite(np.linalg.norm(tr.shape[last] - tr.shape[0])),
        hidden=float(np.mean((area[1:] < HIDDEN_AREA * a0) | ~vis[1:])),
    )

    # hand oscillation near the object: lateral DIS flow in a disc around its last known position
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    yy, xx = np.mgrid[:WORK_SIZE, :WORK_SIZE]
    lat, cur = [], p0
    for t in range(T - 1):
        cur = pos[t] if vis[t] else cur
        flow = dis.calc(grey[t], grey[t + 1], None)
        lat.append(float(flow[np.hypot(xx - cur[0], yy - cur[1]) <= FLOW_DISC].mean(0) @ vdir))
    lat = np.array(lat)
    f["flow_rev"] = float(reversals(np.cumsum(lat), FLOW_REV_HYST))
    f["flow_lat"] = float(np.abs(lat).max(initial=0.0))

    # robot: unsaturated now, saturated (table/object colour) in some frame
    sat = np.stack([cv2.cvtColor(fr, cv2.COLOR_RGB2HSV)[..., 1] for fr in v])
    robot = (sat < ROBOT_SAT_MAX) & (sat.max(0) > COLOURED_SAT_MIN)[None]
    rd, cur = [], p0
    for t in range(T):
        cur = pos[t] if vis[t] else cur
        rob = robot[t]
        if vis[t]:  # the blurred rim of the object itself (its colour mixed with the table's) is not robot
            rob = rob & (np.hypot(xx - cur[0], yy - cur[1]) > np.sqrt(area[t]) / 2 + OBJECT_RIM)
        if not rob.any():
            rd.append(float(WORK_SIZE))
            continue
        dist = cv2.distanceTransform((~rob).astype(np.uint8), cv2.DIST_L2, 3)
        ix, iy = (int(np.clip(round(c), 0, WORK_SIZE - 1)) for c in cur)
        rd.append(float(dist[iy, ix]))
    f["rd_min"], f["rd_end"] = float(min(rd)), float(rd[-1])

    # appearance change of the object's window, first frame vs last (each at its own position)
    r = int(max(2, round(s0)))
    wins = []
    for t, p in ((0, p0), (last, pos[last])):
        ix, iy = int(round(p[0])), int(round(p[1]))
        inside = r <= ix < WORK_SIZE - r and r <= iy < WORK_SIZE - r
        wins.append(lab[t, iy - r:iy + r + 1, ix - r:ix + r + 1] if inside else None)
    f["app_change"] = (float(np.mean(np.linalg.norm(wins[0] - wins[1], axis=-1)))
                       if wins[0] is not None and wins[1] is not None else 0.0)
    return f


# -- decision -----------------------------------------------------------------------------------------------
def evidence_for(label: str, f: dict[str, float]) -> bool:
    """Whether the object's measured motion shows `label` (each primitive's rule, independent of the others)."""
    moved = f["disp"] >= MOVE_DISP
    if label == "tap":
        return moved and (f["end_step"] >= TAP_END_STEP or f["disp"] >= TAP_DISP)
    if label == "knock-over":
        shape = max(f["shape_change"], abs(f["area_change"]))
        abrupt = f["max_step"] >= ABRUPT * f["disp"]
        return moved and shape >= KNOCK_SHAPE and (abrupt or f["rd_end"] >= KNOCK_CLEAR)
    if label == "drag":
        return moved and abs(f["disp_v"]) >= LAT_RATIO * abs(f["disp_u"])
    if label == "push":
        return moved and abs(f["disp_v"]) < LAT_RATIO * abs(f["disp_u"]) and f["disp_u"] > 0
    if label == "pull":
        return moved and abs(f["disp_v"]) < LAT_RATIO * abs(f["disp_u"]) and f["disp_u"] < 0
    if label == "shake":
        return not moved and (f["lat_exc"] >= SHAKE_LAT or (
            f["flow_rev"] >= SHAKE_FLOW_REV and f["flow_lat"] >= SHAKE_FLOW_MIN))
    if label == "drop":
        return not moved and (f["ret_up"] >= DROP_RISE or (f["hidden"] >= HIDDEN_DROP and f["visible_end"] > 0))
    if label == "rotate":
        return not moved and f["visible_end"] > 0 and f["app_change"] >= ROT_APP_MIN
    raise ValueError(f"unknown primitive {label!r}")


DECISION_ORDER = ("tap", "knock-over", "drag", "push", "pull", "shake", "drop")  # then rotate (the fallback)


def classify(f: dict[str, float]) -> str | None:
    """The best-matching primitive: the first in `DECISION_ORDER` whose evidence holds, else rotate (the object
    stayed in place). None when the object could not be found."""
    if not f.get("tracked"):
        return None
    return next((p for p in DECISION_ORDER if evidence_for(p, f)), "rotate")


def agent_ok(label: str, f: dict[str, float]) -> bool:
    """The arm visibly moves and reaches the object; for a tap it is also clear of the ball at the end."""
    reached = f["rd_min"] <= APPROACH + f["size"] / 2
    ok = f["arm_motion"] >= ARM_MOTION_MIN and reached
    if label == "tap":
        ok = ok and f["rd_end"] >= TAP_CLEAR * f["size"]
    return bool(ok)


class RulesJudge:
    """Deterministic image-only primitive judge (module docstring): colour tracking, robot pixels, DIS flow."""

    name = "rules"
    version = "1"

    def judge(self, frames: np.ndarray, object_px: tuple[float, float], platform: str | None = None) -> Verdict:
        """One clip's verdict; the rules are the same on every platform (`platform` is not used)."""
        cv2.setNumThreads(1)  # one thread per scoring worker, like the DIS flow backend
        try:
            f = features(frames, object_px)
        except Exception as e:  # a judge never raises on a weird video: it scores 0
            return Verdict(None, False, False, {"error": f"{type(e).__name__}: {e}"})
        label = classify(f)
        if label is None:
            why = ("unreadable video" if not f.get("video") else "fewer than 2 frames" if f.get("frames", 2) < 2
                   else "object not found in frame 0")
            return Verdict(None, False, False, {**f, "reason": why})
        return Verdict(label, agent_ok(label, f), evidence_for(label, f), {**f, "reason": label})
