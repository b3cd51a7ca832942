"""RMFA reference machinery (wsp_eval.flow) on hand-built videos and flows with worked-out answers.

Tolerances: flows come from OpenCV DIS (MEDIUM), whose endpoint error inside a moving textured region is
≤ 0.33 px for shifts up to 8 px (docs: TOOLCHAIN_NOTES). The translation tests compare the *median* flow
over the square's interior (eroded so no pixel sees the square's border or the uncovered background) with
the exact shift, to 0.3 px. Score tests use exact synthetic flows, so their answers are exact (1e-9).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wsp_eval.flow import (
    C, FLOW_SIZE, TAU, active_flows, active_pixels_per_window, clip_duration, reference_flows, rmfa_score,
    rmfa_window_score, sample_times, video_flows, windowed_reference, windows,
)

H, W = FLOW_SIZE[1], FLOW_SIZE[0]


def _texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Blocky random texture (4-px blocks, lightly blurred): DIS needs gradients at every scale it uses."""
    t = np.kron(rng.integers(0, 256, (h // 4 + 1, w // 4 + 1)), np.ones((4, 4)))[:h, :w].astype(np.uint8)
    return cv2.GaussianBlur(t, (3, 3), 0)


def _moving_square(frames: int, dx: int, dy: int, size: int = 128, side: int = 36):
    """A textured square moving (dx, dy) px per frame over a static textured background; labels 1 on it."""
    rng = np.random.default_rng(0)
    bg = _texture(rng, size, size) // 2  # darker background, distinct from the square
    patch = _texture(rng, side, side) // 2 + 128
    video = np.zeros((frames, size, size, 3), dtype=np.uint8)
    labels = np.zeros((frames, size, size), dtype=np.uint8)
    for t in range(frames):
        x, y = 30 + dx * t, 30 + dy * t
        img = bg.copy()
        img[y:y + side, x:x + side] = patch
        video[t] = img[..., None]
        labels[t, y:y + side, x:x + side] = 1
    return video, labels


def test_sample_times_and_duration():
    assert clip_duration(61, 20) == pytest.approx(3.0)
    assert np.allclose(sample_times(1.0), [0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert np.allclose(sample_times(0.19), [0.0])
    assert len(sample_times(clip_duration(61, 20))) == 16  # 15 flows


def test_windows_cover_every_flow_with_full_windows():
    assert windows(0) == []
    assert windows(1) == [(0, 1)]
    assert windows(7) == [(0, 7)]  # a clip shorter than 2 s: one window holding all its flows
    assert windows(10) == [(0, 10)]
    assert windows(12) == [(0, 10), (2, 12)]  # final partial window → one full window ending at the last flow
    assert windows(15) == [(0, 10), (5, 15)]
    assert windows(17) == [(0, 10), (5, 15), (7, 17)]
    assert windows(20) == [(0, 10), (5, 15), (10, 20)]


@pytest.mark.parametrize("dx, dy, expect", [
    (1, 0, (4 * 160 / 128, 0.0)),  # 1 px/frame at 20 fps = 4 px per 0.2 s sample; ×160/128 horizontally → 5 px
    (0, 1, (0.0, 4 * 120 / 128)),  # vertically ×120/128 → 3.75 px
])
def test_translating_square_gives_its_shift(dx, dy, expect):
    video, labels = _moving_square(21, dx, dy)  # 1 s at 20 fps → 6 samples, 5 flows
    ref = reference_flows(video, labels, fps=20)
    assert ref.flows.shape == (5, H, W, 2) and ref.masks.shape == (5, H, W)
    for k in range(5):
        # interior: on the square at both ends, eroded by 4 grid px
        inside = cv2.erode((labels[4 * k] & labels[4 * k + 4]).astype(np.uint8), np.ones((3, 3)))
        inside = cv2.erode(cv2.resize(inside, FLOW_SIZE, interpolation=cv2.INTER_NEAREST), np.ones((9, 9))) > 0
        med = np.median(ref.flows[k][inside], axis=0)
        assert med == pytest.approx(expect, abs=0.3)
        still = cv2.resize((labels[4 * k] | labels[4 * k + 4]), FLOW_SIZE, interpolation=cv2.INTER_NEAREST) == 0
        assert np.median(np.linalg.norm(ref.flows[k][still], axis=-1)) < 0.1  # the background does not move
    assert np.array_equal(ref.flows, video_flows(video, fps=20))  # same flows with or without masks


def test_pair_mask_is_the_union_of_its_endpoints():
    video, labels = _moving_square(21, 1, 0)
    ref = reference_flows(video, labels, fps=20)
    grid = np.stack([cv2.resize(m, FLOW_SIZE, interpolation=cv2.INTER_NEAREST) for m in labels[::4]]) > 0
    assert np.array_equal(ref.masks, grid[:-1] | grid[1:])
    # the square spans 36 px → 45×34 grid px; moved 5 grid px → the union is 50 px wide
    assert ref.masks[0].sum(axis=1).max() == 50


def test_active_pixels_need_robot_motion():
    video, labels = _moving_square(61, 1, 0)  # 3 s → 15 flows → windows (0,10), (5,15)
    ref = reference_flows(video, labels, fps=20)
    assert (active_pixels_per_window(*ref) > 0).all()
    frozen = np.repeat(video[:1], 61, axis=0)  # same mask, no motion
    ref0 = reference_flows(frozen, labels, fps=20)
    assert active_pixels_per_window(*ref0).tolist() == [0, 0]
    unlabelled = reference_flows(video, np.zeros_like(labels), fps=20)  # motion, but not on the robot
    assert active_pixels_per_window(*unlabelled).tolist() == [0, 0]


def test_a_generated_flow_is_computed_only_where_the_reference_robot_moves():
    """RMFA reads a generated flow only on its reference flow's active set, so `video_flows` skips the flows whose
    active set is empty: the others are what a full computation gives, and the score is bit-identical."""
    moving, labels = _moving_square(61, 1, 0)
    still_half = np.concatenate([moving[:31], np.repeat(moving[30:31], 30, axis=0)])  # the robot stops at 1.5 s
    halted = np.concatenate([labels[:31], np.repeat(labels[30:31], 30, axis=0)])
    ref = reference_flows(still_half, halted, fps=20)
    needed = active_flows(ref.flows, ref.masks)
    assert needed[:7].all() and not needed[8:].any()  # flows 0–6 end by 1.4 s; from 1.6 s on the robot is still
    np.testing.assert_array_equal(windowed_reference(ref.flows, ref.masks).needed, needed)  # what T2/T3 use
    generated = _moving_square(61, 1, 1)[0]
    full = video_flows(generated, 20)
    skipped = video_flows(generated, 20, needed=needed)
    np.testing.assert_array_equal(skipped[needed], full[needed])
    assert not skipped[~needed].any() and full[~needed].any()
    assert rmfa_score(skipped, ref.flows, ref.masks) == rmfa_score(full, ref.flows, ref.masks)
    with pytest.raises(ValueError, match="needed flags"):
        video_flows(generated, 20, needed=needed[:-1])


def test_duration_limits_the_samples():
    video, labels = _moving_square(61, 1, 0)
    assert len(reference_flows(video, labels, 20, duration=1.0).flows) == 5
    with pytest.raises(ValueError, match="exceeds"):
        video_flows(video, 20, duration=4.0)
    with pytest.raises(ValueError, match="uint8"):
        video_flows(video.astype(np.float32), 20)


# -- scores on exact synthetic flows ------------------------------------------------------------------------
def _field(k: int, v=(0.0, 0.0)) -> np.ndarray:
    f = np.zeros((k, H, W, 2))
    f[...] = v
    return f


def _mask(k: int) -> np.ndarray:
    m = np.zeros((k, H, W), dtype=bool)
    m[:, 40:80, 50:110] = True
    return m


def test_identical_flows_score_100():
    rng = np.random.default_rng(1)
    f = rng.normal(0, 3, (10, H, W, 2))
    assert rmfa_window_score(f, f, _mask(10)) == pytest.approx(100.0)
    assert rmfa_score(f, f, _mask(10)) == pytest.approx(100.0)


@pytest.mark.parametrize("v, expected", [
    ((2.0, 0.0), 100 * (1 - 2 / 3.16)),  # R = 2 < c: 36.71
    ((0.0, 3.16), 0.0),  # R = c
    ((6.0, 8.0), 0.0),  # R = 10: E = R → 0
])
def test_zero_generated_flow(v, expected):
    """F̂ = 0 gives E = R, so S = 100·max(0, 1 − R / max(R, c))."""
    f_star = _field(10, v)
    assert rmfa_window_score(_field(10), f_star, _mask(10)) == pytest.approx(expected, abs=1e-9)


def test_error_is_rms_over_the_active_set_and_normalised_by_max_r_c():
    f_star = _field(10, (0.0, 4.0))  # R = 4 > c
    assert rmfa_window_score(f_star + [1.0, 0.0], f_star, _mask(10)) == pytest.approx(75.0)  # E = 1
    small = _field(10, (0.0, 2.0))  # R = 2 < c: normalised by c
    assert rmfa_window_score(small + [1.0, 0.0], small, _mask(10)) == pytest.approx(100 * (1 - 1 / C))
    f_hat = f_star.copy()
    f_hat[0] += [1.0, 0.0]
    f_hat[1] += [3.0, 0.0]
    m = _mask(10)
    m[2:] = False  # M = flows 0 and 1, equal pixel counts: E = sqrt((1² + 3²) / 2) = √5, not the mean 2
    assert rmfa_window_score(f_hat, f_star, m) == pytest.approx(100 * (1 - np.sqrt(5) / 4))


def test_only_active_robot_pixels_count():
    f_star = _field(10, (0.0, 4.0))
    f_star[:, 40:60] = [0.0, TAU * 0.8]  # robot pixels below τ: not in M
    f_hat = f_star + [1.0, 0.0]
    f_hat[:, 40:60] = [50.0, 50.0]  # any error there is ignored
    f_hat[:, :40] = [-30.0, 9.0]  # and outside the robot mask
    assert rmfa_window_score(f_hat, f_star, _mask(10)) == pytest.approx(75.0)


def test_empty_windows_are_skipped_and_windows_averaged():
    f_star = _field(20)  # windows (0,10), (5,15), (10,20)
    f_star[0:5] = [0.0, 4.0]
    f_hat = f_star + [1.0, 0.0]  # window (0,10) scores 75; the two later windows have no motion
    assert rmfa_score(f_hat, f_star, _mask(20)) == pytest.approx(75.0)
    f_star[15:20] = [0.0, 4.0]  # now window (10,20) is scorable too; F̂ there = (1, 0) vs (0, 4): E = √17
    assert rmfa_score(f_hat, f_star, _mask(20)) == pytest.approx((75.0 + 100 * max(0, 1 - np.sqrt(17) / 4)) / 2)
    assert rmfa_score(_field(20), _field(20), _mask(20)) is None


def test_mismatched_flow_counts_are_refused():
    with pytest.raises(ValueError, match="common duration"):
        rmfa_score(_field(11), _field(10), _mask(10))
