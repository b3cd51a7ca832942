"""T1 calibration score on hand-built videos whose correct score is worked out here.

Videos are constant-offset clips, so D is exactly the squared offset: D(zeros, c) = c². Tolerances are
float round-off only (1e-9)."""

import numpy as np
import pytest

from wsp_eval.suites.t1 import calibration, instance_score, seed_score


def clip(value: int, n: int = 6) -> np.ndarray:
    return np.full((n, 4, 4, 3), value, np.uint8)


def triplet(small: int, large: int, fps=(20, 20, 20), n=(6, 6, 6)):
    return {"original": (clip(0, n[0]), fps[0]), "small": (clip(small, n[1]), fps[1]),
            "large": (clip(large, n[2]), fps[2])}


def test_exact_calibration_scores_one():
    # D0s = 4, D0l = 16 → r = 0.25 = r*
    assert seed_score(triplet(2, 4), r_star=0.25) == pytest.approx(1.0, abs=1e-9)


def test_under_response_ratio_scores_r_over_r_star():
    # D0s = 1, D0l = 16 → r = 1/16; r* = 0.25 → S = (1/16) / 0.25 = 0.25
    assert seed_score(triplet(1, 4), r_star=0.25) == pytest.approx(0.25, abs=1e-9)


def test_over_response_ratio_uses_the_other_branch():
    # D0s = 9, D0l = 16 → r = 0.5625; r* = 0.25 → S = (1 − 0.5625) / 0.75 = 0.58333…
    assert seed_score(triplet(3, 4), r_star=0.25) == pytest.approx(0.4375 / 0.75, abs=1e-9)


def test_reversed_or_degenerate_scaling_scores_zero():
    assert seed_score(triplet(4, 2), r_star=0.25) == 0.0  # r = 4 > 1 → clipped to 0
    assert seed_score(triplet(2, 0), r_star=0.25) == 0.0  # D(ĝ⁰, ĝˡ) = 0
    assert seed_score(triplet(0, 0), r_star=0.25) == 0.0  # a static model


def test_alignment_uses_the_generated_original_timebase():
    # The small variant is generated at 10 fps with 3 frames; the original (20 fps, 6 frames, 0…0.25 s) is
    # the timebase, truncated to the common duration (≤ 0.2 s): frames at 0, .05, .1, .15, .2 s.
    t = triplet(2, 4, fps=(20, 10, 20), n=(6, 3, 6))
    assert seed_score(t, r_star=0.25) == pytest.approx(1.0, abs=1e-9)


def test_seeds_are_averaged_per_instance():
    assert instance_score([triplet(2, 4), triplet(1, 4)], r_star=0.25) == pytest.approx((1.0 + 0.25) / 2)


def test_calibration_is_clipped():
    assert calibration(0.0, 0.3) == 0.0 and calibration(0.3, 0.3) == 1.0 and calibration(2.0, 0.3) == 0.0


def test_oracle_and_static_on_a_real_release(t1_release):
    """The reference itself (decoded from the release's near-lossless video) reproduces r* to within codec
    noise, so it scores ≥ 0.97 per instance; repeating the first frame scores 0."""
    import pyarrow.parquet as pq

    from wsp_eval.baselines import oracle, static
    from wsp_eval.reference import reference_frames

    cfg = t1_release / "t1_maniskill"
    for row in pq.read_table(cfg / "instances.parquet").to_pylist():
        refs = {role: reference_frames(cfg, i) for role, i in zip(row["roles"], row["episode_indices"])}
        assert seed_score({k: (oracle(v), 20) for k, v in refs.items()}, row["r_star"]) >= 0.97
        assert seed_score({k: (static(v), 20) for k, v in refs.items()}, row["r_star"]) == 0.0
