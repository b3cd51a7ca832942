"""The T4 tracker (wsp_eval.tracking) on hand-built videos with worked-out answers.

Videos are drawn directly in the 256×256 scoring frame (unless a test checks resizing): a uniform grey
background (no texture, so LK cannot lock onto it) and textured patches (smoothed noise) pasted at integer
offsets, so the true motion of every patch is known exactly. Pyramidal LK localises a rigid textured patch
to a few hundredths of a pixel (docs/TOOLCHAIN: 0.01–0.03 px); the tolerances below (0.5 px on shifts of
6–50 px) leave room for sub-pixel bias at patch borders and are still far tighter than the 10 px decision.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wsp_eval import tracking as tr

S = tr.SCORING_SIZE
BG = 100


def texture(size: int, seed: int) -> np.ndarray:
    noise = np.random.default_rng(seed).integers(0, 256, (size, size)).astype(np.float32)
    return np.clip(cv2.GaussianBlur(noise, (0, 0), 1.2) * 2 - 128, 0, 255).astype(np.uint8)


def canvas() -> np.ndarray:
    return np.full((S, S), BG, np.uint8)


def paste(img: np.ndarray, patch: np.ndarray, center: tuple[int, int]) -> None:
    h = len(patch) // 2
    x, y = center
    img[y - h:y - h + len(patch), x - h:x - h + len(patch)] = patch


def video(n: int, patches: list[tuple[np.ndarray, callable]]) -> np.ndarray:
    """n frames; each patch is drawn (in order) at the integer centre its function gives for frame t."""
    frames = []
    for t in range(n):
        img = canvas()
        for patch, where in patches:
            paste(img, patch, where(t))
        frames.append(img)
    return np.stack(frames)


OBJ = texture(48, 1)  # the evaluated object: 48 px covers the query grid (radius 10) and its LK windows
HAND = texture(40, 2)  # the "hand" that the motion gate follows
OBJ_AT = (150, 170)
HAND_FROM, HAND_TO = (60, 60), (90, 100)  # hand moves (30, 40): 50 px from the first to the last frame


def hand_at(t: int, n: int) -> tuple[int, int]:
    f = t / (n - 1)
    return (round(HAND_FROM[0] + f * (HAND_TO[0] - HAND_FROM[0])), round(HAND_FROM[1] + f * (HAND_TO[1] - HAND_FROM[1])))


def hand_mask() -> np.ndarray:
    """Reference label mask at frame 0: label 2 (wrist/hand/fingers) on the hand patch, 1 on an 'arm' above."""
    m = np.zeros((S, S), np.uint8)
    m[HAND_FROM[1] - 20:HAND_FROM[1] + 20, HAND_FROM[0] - 20:HAND_FROM[0] + 20] = 2
    m[:HAND_FROM[1] - 20, HAND_FROM[0] - 10:HAND_FROM[0] + 10] = 1
    return m


def scene(n: int, obj_at=lambda t: OBJ_AT, hand=True) -> np.ndarray:
    patches = [(OBJ, obj_at)] + ([(HAND, lambda t: hand_at(t, n))] if hand else [])
    return video(n, patches)


# -- geometry -------------------------------------------------------------------------------------
def test_projection_into_the_scoring_frame():
    """Camera at the origin looking down +z, f = 64 px on a 128 px image: (0.5, −0.25, 1) m lands on
    u = 64 + 32 = 96, v = 64 − 16 = 48 at 128²; scaling pixel centres by 2: (2·96 + 0.5, 2·48 + 0.5)."""
    K = np.array([[64, 0, 64], [0, 64, 64], [0, 0, 1]], float)
    E = np.hstack([np.eye(3), np.zeros((3, 1))])
    assert tr.project([0.5, -0.25, 1.0], K, E, 128) == pytest.approx([192.5, 96.5])
    assert tr.project([0, 0, 2.0], K, E, 128) == pytest.approx([128.5, 128.5])
    with pytest.raises(ValueError, match="behind the camera"):
        tr.project([0, 0, -1.0], K, E, 128)


def test_projection_of_a_non_square_camera_matches_the_resize_into_the_scoring_frame():
    """A 320×240 camera (f = 200 px, centre (159.5, 119.5)): each axis scales as `cv2.resize` scales it into the
    256² frame (x by 0.8, y by 16/15), so a white pixel drawn where a point projects lands, after
    `scoring_frames`, where `project` puts it (within the half-pixel blur of area interpolation)."""
    K = np.array([[200, 0, 159.5], [0, 200, 119.5], [0, 0, 1]], float)
    E = np.hstack([np.eye(3), np.zeros((3, 1))])
    point = [0.25, -0.1, 1.0]  # → u = 209.5, v = 99.5 in the 320×240 image
    expected = [(209.5 + 0.5) * 0.8 - 0.5, (99.5 + 0.5) * 16 / 15 - 0.5]
    assert tr.project(point, K, E, (320, 240)) == pytest.approx(expected)
    frame = np.zeros((240, 320), np.uint8)
    frame[97:103, 207:213] = 255  # a 6 px square around (209.5, 99.5)
    assert tr.frame_size(frame) == (320, 240)
    grey = tr.scoring_frames(frame[None])[0].astype(float)
    ys, xs = np.mgrid[:256, :256]
    centre = [(xs * grey).sum() / grey.sum(), (ys * grey).sum() / grey.sum()]
    assert centre == pytest.approx(tr.project(point, K, E, tr.frame_size(frame)), abs=0.5)


def test_query_grid_is_3x3_within_the_radius():
    g = tr.query_grid(np.array([100.0, 50.0]))
    assert g.shape == (9, 2)
    r = np.linalg.norm(g - [100, 50], axis=1)
    assert r.max() == pytest.approx(tr.QUERY_RADIUS, abs=1e-4) and r.min() == 0
    assert len(np.unique(g[:, 0])) == 3 and len(np.unique(g[:, 1])) == 3


def test_arm_grid_seeds_inside_the_eroded_distal_label():
    m = hand_mask()
    pts = tr.arm_grid(m)
    x, y = pts[:, 0].astype(int), pts[:, 1].astype(int)
    assert len(pts) == (40 - 2 * tr.ARM_ERODE) ** 2 // tr.ARM_GRID_STEP ** 2  # 36 / 4 = 9 per side → 81
    assert (m[y, x] == 2).all()
    assert tr.arm_grid(np.zeros((128, 128), np.uint8)).shape == (0, 2)


def test_gate_frames_are_first_middle_last():
    assert tr.gate_frames(5) == (0, 2, 4) and tr.gate_frames(4) == (0, 1, 3) and tr.gate_frames(1) == (0, 0, 0)


# -- object displacement ----------------------------------------------------------------------------
@pytest.mark.parametrize("shift", [(12, -5), (-6, 0), (25, 20)])
def test_moved_patch_displacement_equals_the_shift(shift):
    """The object slides linearly to `shift` px over 11 frames (≤ 2.5 px per frame): d = ‖shift‖."""
    n = 11
    frames = video(n, [(OBJ, lambda t: (OBJ_AT[0] + round(shift[0] * t / (n - 1)),
                                        OBJ_AT[1] + round(shift[1] * t / (n - 1))))])
    m = tr.object_motion(frames, np.array(OBJ_AT, float))
    assert m.displacement == pytest.approx(np.hypot(*shift), abs=0.5)
    assert m.textured_points == 9 and m.visible_fraction == 1.0


def test_static_patch_has_no_displacement():
    m = tr.object_motion(scene(20, hand=False), np.array(OBJ_AT, float))
    assert m.displacement < 0.05 and m.visible_fraction == 1.0


def test_returning_object_counts_its_farthest_excursion():
    """d is the maximum over frames, not the final offset: out by 15 px and back scores d = 15."""
    path = [0, 5, 10, 15, 10, 5, 0]
    frames = video(len(path), [(OBJ, lambda t: (OBJ_AT[0] + path[t], OBJ_AT[1]))])
    assert tr.object_motion(frames, np.array(OBJ_AT, float)).displacement == pytest.approx(15, abs=0.5)


def test_occluder_passing_over_a_static_object_is_not_followed():
    """A differently textured occluder sweeps across the static object (it overlaps the object's patch in
    frames 3–11). Covered points must turn invisible instead of riding along, so d stays ≈ 0 while the
    visible fraction drops."""
    occluder = texture(40, 3)
    n = 14
    frames = video(n, [(OBJ, lambda t: OBJ_AT), (occluder, lambda t: (OBJ_AT[0] - 70 + 10 * t, OBJ_AT[1]))])
    m = tr.object_motion(frames, np.array(OBJ_AT, float))
    assert m.displacement < 0.5
    assert m.visible_fraction < 1.0  # some frames had no visible point: the centroid was carried forward


def test_textureless_object_is_tracked_by_its_edges_or_not_at_all():
    """A uniform 60 px square: its inner query points have no texture in their 15 px windows and are never
    visible; on a fully uniform frame no point is textured, so d = 0 by carrying the centroid forward."""
    square = np.full((60, 60), 220, np.uint8)
    frames = video(5, [(square, lambda t: OBJ_AT)])
    assert tr.textured(frames[0], tr.query_grid(np.array(OBJ_AT, float))).sum() == 0
    small = np.full((16, 16), 220, np.uint8)  # edges fall inside the windows: edge points are textured
    assert tr.textured(video(1, [(small, lambda t: OBJ_AT)])[0], tr.query_grid(np.array(OBJ_AT, float))).sum() >= 4
    m = tr.object_motion(frames, np.array(OBJ_AT, float))
    assert m.textured_points == 0 and m.displacement == 0.0


# -- the colour-region stage (the evaluated object when its colour is distinct) ---------------------------
BLUE, WOOD = (59, 102, 188), (180, 100, 60)  # a ManiSkill cube's blue on an orange, wood-like table
CUBE_AT = (120, 140)


def wood(seed: int = 4) -> np.ndarray:
    """A textured orange table (RGB, scoring frame): the wood colour modulated by ±25 % of smoothed noise."""
    shade = 1.0 + 0.5 * (texture(S, seed).astype(np.float32) / 255.0 - 0.5)
    return np.clip(np.array(WOOD, np.float32)[None, None] * shade[..., None], 0, 255).astype(np.uint8)


def colour_scene(n: int, cube_at, hand_at_=None, hand_size: int = 14, extra: tuple | None = None) -> np.ndarray:
    """n RGB frames: a 7 px blue cube (smaller than the query grid, as in ManiSkill) at cube_at(t) (None: not
    drawn) on the wood, and optionally a grey textured hand (hand_size px) at hand_at_(t) drawn over it;
    `extra` is a second blue cube fixed at that position."""
    hand = cv2.cvtColor(texture(hand_size, 2), cv2.COLOR_GRAY2RGB)
    frames = []
    for t in range(n):
        img = wood().copy()
        for at in ([cube_at(t)] if cube_at(t) is not None else []) + ([extra] if extra else []):
            x, y = at
            img[y - 3:y + 4, x - 3:x + 4] = BLUE
        if hand_at_ is not None:
            x, y = hand_at_(t)
            h = hand_size // 2
            img[y - h:y - h + hand_size, x - h:x - h + hand_size] = hand
        frames.append(img)
    return np.stack(frames)


def far_hand_mask() -> np.ndarray:
    """A robot mask (label 2) away from the cube, on grey pixels: the blue covers none of the robot."""
    m = np.zeros((S, S), np.uint8)
    m[20:50, 20:50] = 2
    return m


def test_colour_region_follows_a_cube_smaller_than_the_query_grid():
    """The 7 px cube slides (20, −8) px over 11 frames: the grid follows its colour region, d = ‖shift‖ (the
    region's centroid is exact for a fully visible square: 0.1 px)."""
    n, shift = 11, (20, -8)
    frames = colour_scene(n, lambda t: (CUBE_AT[0] + round(shift[0] * t / (n - 1)), CUBE_AT[1] + round(shift[1] * t / (n - 1))))
    video = tr.scoring_video(frames)
    assert tr.colour_model(video.rgb[0], np.array(CUBE_AT, float), far_hand_mask()) is not None
    m = tr.object_motion(video, np.array(CUBE_AT, float), far_hand_mask())
    assert m.displacement == pytest.approx(np.hypot(*shift), abs=0.1)
    assert m.visible_fraction == 1.0 and m.textured_points == 9


def test_a_grasped_cube_half_covered_by_the_fingers_is_still_followed():
    """A grey hand covers the cube's left half while carrying it 24 px up: the visible sliver (≥ 5 % of the
    frame-0 area) is followed; its centroid sits 2 px right of the cube's centre, so d = 24 ± 2."""
    n = 13
    path = lambda t: (CUBE_AT[0], CUBE_AT[1] - 2 * t)  # noqa: E731
    frames = colour_scene(n, path, hand_at_=lambda t: (path(t)[0] - 7 if t else 200, path(t)[1]), hand_size=16)
    m = tr.object_motion(tr.scoring_video(frames), np.array(CUBE_AT, float), far_hand_mask())
    assert m.displacement == pytest.approx(24, abs=2) and m.visible_fraction == 1.0


def test_fingers_over_a_still_cube_do_not_move_it():
    """A hand covers the top 4 of the still cube's 7 rows from frame 3 on: the visible bottom rows' centroid
    sits 2 px low, but the occlusion fit places the cube's frame-0 shape where it covers them without lying
    on the (unchanged) wood below: d = 0 exactly (the fit is on the integer grid)."""
    n = 8
    frames = colour_scene(n, lambda t: CUBE_AT,
                          hand_at_=lambda t: (CUBE_AT[0], CUBE_AT[1] - 7) if t >= 3 else (200, 40), hand_size=16)
    m = tr.object_motion(tr.scoring_video(frames), np.array(CUBE_AT, float), far_hand_mask())
    assert m.displacement < 0.1 and m.visible_fraction == 1.0


def test_a_cube_lifted_under_fingers_moves_by_its_true_lift():
    """The fingers close over the cube's top 4 rows and lift it 12 px (1 px per frame): the visible part's
    centroid would read 10 px (2 px low); the fit places the whole cube: d = 12 (ALOHA's drops, lifted 12.5 px,
    read 7–10 px by the visible part's centroid; docs/validity.md, T4 tracker)."""
    n = 14
    path = lambda t: (CUBE_AT[0], CUBE_AT[1] - max(t - 1, 0))  # noqa: E731
    frames = colour_scene(n, path, hand_at_=lambda t: (path(t)[0], path(t)[1] - 7) if t else (200, 40),
                          hand_size=16)
    m = tr.object_motion(tr.scoring_video(frames), np.array(CUBE_AT, float), far_hand_mask())
    assert m.displacement == pytest.approx(12, abs=0.1) and m.visible_fraction == 1.0


def test_no_occlusion_fit_for_a_cube_the_hand_touches_in_frame_0():
    """Frame 0 already shows the fingers over the cube's top: its frame-0 region is only part of the cube, no model
    of its shape, so the object gets no occlusion fit (`shape` None) and is followed by its visible centroid; with
    the hand away in frame 0 the shape is kept."""
    hand = (CUBE_AT[0], CUBE_AT[1] - 7)
    frames = colour_scene(2, lambda t: CUBE_AT, hand_at_=lambda t: hand, hand_size=16)
    mask = np.zeros((S, S), np.uint8)
    mask[hand[1] - 8:hand[1] + 8, hand[0] - 8:hand[0] + 8] = 2
    visible_part = np.array([CUBE_AT[0], CUBE_AT[1] + 2], float)
    touched = tr.colour_model(tr.scoring_video(frames).rgb[0], visible_part, mask)
    assert touched is not None and touched.shape is None
    free = tr.colour_model(tr.scoring_video(colour_scene(1, lambda t: CUBE_AT)).rgb[0], visible_part, far_hand_mask())
    assert free is not None and free.shape.shape == (7, 7)


def test_a_hidden_cube_is_invisible_and_keeps_its_place():
    """A still cube covered entirely by a passing hand in frames 4–8: invisible there (the occlusion rule),
    its last position kept, so d ≈ 0 and the visible fraction is 9/14."""
    n = 14
    frames = colour_scene(n, lambda t: CUBE_AT, hand_at_=lambda t: CUBE_AT if 4 <= t <= 8 else (200, 40), hand_size=16)
    m = tr.object_motion(tr.scoring_video(frames), np.array(CUBE_AT, float), far_hand_mask())
    assert m.displacement < 0.1 and m.visible_fraction == pytest.approx(9 / 14)


def test_the_region_does_not_jump_to_another_cube_of_the_same_colour():
    """The cube vanishes after frame 0 while a second blue cube sits 60 px away (beyond REGION_JUMP_MAX): the
    object is invisible from frame 1 on (a tracking failure for T4), not moved by 60 px."""
    n = 8
    frames = colour_scene(n, lambda t: CUBE_AT if t == 0 else None, extra=(CUBE_AT[0] + 60, CUBE_AT[1]))
    m = tr.object_motion(tr.scoring_video(frames), np.array(CUBE_AT, float), far_hand_mask())
    assert m.displacement == 0.0 and m.visible_fraction == pytest.approx(1 / n)


def test_a_colour_that_is_not_distinct_falls_back_to_lk():
    """No colour model (LK tracks the grid instead) when the object's colour covers the robot (the region
    could follow the gripper), when it leaks into a large same-coloured area, or when the video is grey."""
    frames = colour_scene(3, lambda t: CUBE_AT)
    rgb0 = tr.scoring_video(frames).rgb[0]
    blue_robot = far_hand_mask()
    assert tr.colour_model(rgb0, np.array(CUBE_AT, float), blue_robot) is not None
    rgb_blue_hand = rgb0.copy()
    rgb_blue_hand[20:50, 20:50] = BLUE
    assert tr.colour_model(rgb_blue_hand, np.array(CUBE_AT, float), blue_robot) is None
    blue_table = rgb0.copy()
    blue_table[CUBE_AT[1]:CUBE_AT[1] + 60, CUBE_AT[0] - 30:CUBE_AT[0] + 30] = BLUE
    assert tr.colour_model(blue_table, np.array(CUBE_AT, float), blue_robot) is None
    grey = tr.scoring_video(frames[..., 0])
    assert grey.rgb is None
    assert tr.object_tracks(grey, np.array(CUBE_AT, float), blue_robot).visible.shape == (3, 9)


# -- motion gate -------------------------------------------------------------------------------------
def test_gate_measures_the_hand_displacement():
    """The hand moves (30, 40) px in a straight line: max pairwise distance of first/middle/last = 50."""
    assert tr.motion_gate(scene(21), hand_mask()) == pytest.approx(50.0, abs=0.5)


def test_frozen_and_armless_videos_fail_the_gate():
    n = 21
    moving = scene(n)
    g_ref = tr.motion_gate(moving, hand_mask())
    frozen = np.repeat(moving[:1], n, axis=0)
    armless = scene(n, hand=False)
    for frames in (frozen, armless):
        s = tr.t4_score(frames, np.array(OBJ_AT, float), hand_mask(), g_ref)
        assert s.gate == pytest.approx(0.0, abs=0.05) and not s.gate_passed and s.score == 0.0


def test_two_hands_moving_toward_each_other_pass_a_per_hand_gate():
    """Two 40 px hands start at x = 60 and x = 196 and meet 40 px nearer the middle each (mirror paths): one
    centroid over both barely moves (the hands' motions cancel), so a two-arm robot's gate is per hand
    (`hands`: each hand's frame-0 pixel; seeds go to the nearer hand) and g is the larger hand's, 40 px.
    A frozen video fails every hand."""
    n = 21
    left = lambda t: (60 + round(40 * t / (n - 1)), 60)  # noqa: E731
    right = lambda t: (196 - round(40 * t / (n - 1)), 60)  # noqa: E731
    frames = video(n, [(HAND, left), (texture(40, 3), right)])
    mask = np.zeros((S, S), np.uint8)
    mask[40:80, 40:80] = mask[40:80, 176:216] = 2
    hands = np.array([[60.0, 60.0], [196.0, 60.0]])
    assert tr.motion_gate(frames, mask) < 3.0
    assert tr.motion_gate(frames, mask, hands=hands) == pytest.approx(40.0, abs=0.5)
    frozen = np.repeat(frames[:1], n, axis=0)
    assert tr.motion_gate(frozen, mask, hands=hands) == pytest.approx(0.0, abs=0.05)


# -- the score ---------------------------------------------------------------------------------------
def test_score_passes_a_faithful_video_and_fails_a_moved_object():
    n = 21
    mask = hand_mask()
    g_ref = tr.motion_gate(scene(n), mask)
    faithful = tr.t4_score(scene(n), np.array(OBJ_AT, float), mask, g_ref)
    assert faithful.score == 100.0 and faithful.gate_passed and faithful.displacement < 0.05
    small = scene(n, obj_at=lambda t: (OBJ_AT[0] + round(6 * t / (n - 1)), OBJ_AT[1]))  # 6 px ≤ 10: still fine
    assert tr.t4_score(small, np.array(OBJ_AT, float), mask, g_ref).score == 100.0
    moved = scene(n, obj_at=lambda t: (OBJ_AT[0] + round(16 * t / (n - 1)), OBJ_AT[1] - round(12 * t / (n - 1))))
    s = tr.t4_score(moved, np.array(OBJ_AT, float), mask, g_ref)
    assert s.gate_passed and s.displacement == pytest.approx(20.0, abs=0.5) and s.score == 0.0


def test_an_object_that_vanishes_is_a_tracking_failure():
    """The object is in frame 0 only (a model that dropped it, or carried it off under the fingers): its
    points are visible in 1 of 21 frames, the centroid is carried forward (d = 0), and the gate passes. With
    the reference visible in every frame, 1/21 < TRACKED_RATIO·1.0 → tracking failure → S = 0; without the
    reference fraction (the builder's own check) the rule is off and the carried centroid scores 100."""
    n = 21
    mask = hand_mask()
    g_ref = tr.motion_gate(scene(n), mask)
    gone = scene(n)
    gone[1:] = video(n, [(HAND, lambda t: hand_at(t, n))])[1:]  # the same scene without the object after frame 0
    s = tr.t4_score(gone, np.array(OBJ_AT, float), mask, g_ref, visible_reference=1.0)
    assert s.gate_passed and s.displacement < 0.05
    assert s.visible_fraction == pytest.approx(1 / n) and not s.tracked and s.score == 0.0
    assert tr.t4_score(gone, np.array(OBJ_AT, float), mask, g_ref).score == 100.0
    faithful = tr.t4_score(scene(n), np.array(OBJ_AT, float), mask, g_ref, visible_reference=1.0)
    assert faithful.tracked and faithful.score == 100.0


def test_half_speed_arm_passes_the_gate_and_less_fails():
    """The gate is relative: a hand that covers 60% of the reference path passes, 40% fails."""
    n = 21
    mask = hand_mask()
    g_ref = tr.motion_gate(scene(n), mask)
    for fraction, passes in ((0.6, True), (0.4, False)):
        part = video(n, [(OBJ, lambda t: OBJ_AT), (HAND, lambda t: hand_at(round(fraction * t), n))])
        assert tr.t4_score(part, np.array(OBJ_AT, float), mask, g_ref).gate_passed is passes


def test_low_resolution_rgb_is_resized_to_the_scoring_frame():
    """A 128² RGB video whose object slides 6 px at 128² moves 12 px in the scoring frame (fails d ≤ 10)."""
    n = 11
    small = video(n, [(OBJ, lambda t: (OBJ_AT[0] + round(12 * t / (n - 1)), OBJ_AT[1]))])
    rgb = np.stack([cv2.cvtColor(cv2.resize(f, (128, 128), interpolation=cv2.INTER_AREA), cv2.COLOR_GRAY2RGB)
                    for f in small])
    assert tr.scoring_frames(rgb).shape == (n, S, S)
    assert tr.object_motion(tr.scoring_frames(rgb), np.array(OBJ_AT, float)).displacement == pytest.approx(12, abs=0.6)


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="uint8"):
        tr.scoring_frames(np.zeros((2, 8, 8, 3), np.float32))
    with pytest.raises(ValueError, match="video"):
        tr.scoring_frames(np.zeros((8, 8), np.uint8))
    with pytest.raises(ValueError, match="gate_reference"):
        tr.t4_score(scene(3), np.array(OBJ_AT, float), hand_mask(), 0.0)


def _pudding(n: int, lift: float) -> tuple[np.ndarray, tuple[int, int]]:
    """LIBERO's chocolate pudding in miniature: a 10 px textured object with still textured neighbours 1 px to
    its right and below, lifted `lift` px per frame from frame 3 on."""
    obj, near = texture(10, 3), texture(30, 13)
    c = (150, 170)
    right, below = (c[0] + 5 + 1 + 15, c[1]), (c[0], c[1] + 5 + 1 + 15)
    return video(n, [(near, lambda t: right), (texture(30, 23), lambda t: below),
                     (obj, lambda t: (c[0], c[1] - round(max(0, t - 3) * lift)))]), c


def test_lk_stage_seeds_on_a_small_object_not_on_its_neighbours():
    """The paper's grid (radius 10 px) around a 10 px object lies mostly on its neighbours: lifted 52 px, the
    object's own points are lost while the neighbours' stay visible and still, so its centroid reads < 10 px —
    a carried-away object that T4 would pass. The LK stage's grid (`LK_QUERY_RADIUS`, 5 px) lies on the object:
    its points are lost with it, visible in < 0.5 of the frames (the reference's object: all), a tracking
    failure, so T4 scores 0. Left still, the same grid keeps it visible and still (no false alarm)."""
    lifted, c = _pudding(30, 2.0)
    spec = tr.track(lifted, tr.query_grid(np.array(c, float)), anchored=True)
    path = tr.centroid_path(spec, anchored=True)
    assert np.linalg.norm(path - path[0], axis=1).max() < tr.MOTION_MAX and spec.visible.any(axis=1).mean() == 1
    moved = tr.object_motion(lifted, np.array(c, float))
    assert moved.visible_fraction < tr.TRACKED_RATIO or moved.displacement > tr.MOTION_MAX
    still = tr.object_motion(_pudding(30, 0.0)[0], np.array(c, float))
    assert still.visible_fraction == 1 and still.displacement < 1
