"""Nearest-frame alignment and the T1 aligned MSE on hand-built videos with worked-out answers."""

import numpy as np
import pytest

from wsp_eval.video import aligned_mse, nearest_indices, timestamps


def test_timestamps_start_at_zero():
    assert timestamps(3, 20).tolist() == [0.0, 0.05, 0.1]
    with pytest.raises(ValueError):
        timestamps(3, 0)


def test_nearest_indices_ties_go_to_earlier_frame():
    src = timestamps(3, 10)  # 0, .1, .2
    assert nearest_indices(src, np.array([0.0, 0.05, 0.06, 0.2, 0.9])).tolist() == [0, 0, 1, 2, 2]


def test_aligned_mse_same_rate_is_frame_by_frame():
    a = np.zeros((4, 2, 2, 3), np.uint8)
    b = a.copy()
    b[2] = 10  # one frame of four differs by 10 everywhere → mean of squares = 100 / 4
    assert aligned_mse(a, b, 20, 20) == pytest.approx(25.0)


def test_aligned_mse_uses_base_timebase_within_common_duration():
    # base: 5 frames at 10 fps (0 … 0.4 s); other: 3 frames at 5 fps (0, 0.2, 0.4 s), values 0, 20, 40.
    base = np.zeros((5, 1, 1, 1), np.uint8)
    other = np.array([0, 20, 40], np.uint8).reshape(3, 1, 1, 1)
    # nearest other frame for base t = 0, .1, .2, .3, .4 → 0, 0 (tie → earlier), 1, 1 (tie), 2
    expected = (0 + 0 + 400 + 400 + 1600) / 5
    assert aligned_mse(base, other, 10, 5) == pytest.approx(expected)


def test_aligned_mse_truncates_to_shorter_video():
    base = np.zeros((10, 1, 1, 1), np.uint8)  # 0 … 0.45 s at 20 fps
    other = np.full((3, 1, 1, 1), 2, np.uint8)  # 0 … 0.1 s: only base frames at t ≤ 0.1 count
    assert aligned_mse(base, other, 20, 20) == pytest.approx(4.0)
