"""The common validity checks (spec §5) on small state arrays: each failure names its reason."""

import numpy as np

from wsp_data.platforms.validity import check_rollout

LIMITS = np.array([[-2.9, 2.9]] * 7 + [[0.0, 0.04]] * 2)


def _valid(T=10):
    qpos = np.zeros((T + 1, 9))
    tcp = np.tile([0.1, 0, 0.2, 1, 0, 0, 0], (T + 1, 1))
    objs = np.full((T + 1, 4, 7), np.nan)
    objs[:, 0] = [0, 0, 0.02, 1, 0, 0, 0]
    actions = np.zeros((T, 8))
    return qpos, tcp, objs, actions


def test_valid_rollout_passes():
    assert check_rollout(*_valid(), LIMITS) is None


def test_each_failure_has_its_reason():
    q, t, o, a = _valid()
    assert check_rollout(q[:-1], t, o, a, LIMITS) == "incomplete"
    o2 = o.copy(); o2[3, 0, 0] = np.nan
    assert check_rollout(q, t, o2, a, LIMITS) == "nonfinite_state"
    a2 = a.copy(); a2[2, 1] = 3.0
    assert check_rollout(q, t, o, a2, LIMITS) == "joint_limit"
    o3 = o.copy(); o3[5:, 0, 0] = 0.5  # 0.5 m in one 50 ms frame = 10 m/s
    assert check_rollout(q, t, o3, a, LIMITS) == "instability"
    o4 = o.copy(); o4[:, 0, 2] = np.linspace(0.02, -0.08, len(o4))
    assert check_rollout(q, t, o4, a, LIMITS) == "instability"


def test_the_arm_columns_come_from_the_platform():
    """A two-arm state (12 arm joints + 2 fingers): the joint-limit and speed checks read the first `arm`
    columns; with the Panda default (7) the 8th arm joint's violation would go unseen."""
    T = 10
    limits = np.array([[-1.0, 1.0]] * 12 + [[0.02, 0.06]] * 2)
    q = np.zeros((T + 1, 14)); q[:, 12:] = 0.05
    tcp = np.tile([0.1, 0, 0.2, 1, 0, 0, 0] * 2, (T + 1, 1))
    o, a = _valid(T)[2], np.zeros((T, 14))
    assert check_rollout(q, tcp, o, a, limits, arm=12) is None
    a[3, 9] = 1.5  # the right arm's 4th joint target beyond its limit
    assert check_rollout(q, tcp, o, a, limits) is None  # Panda's 7 columns do not include it …
    assert check_rollout(q, tcp, o, a, limits, arm=12) == "joint_limit"  # … the platform's 12 do
    a[3, 9] = 0.0
    q[5:, 10] = 0.9  # 0.9 rad in one 50 ms frame = 18 rad/s
    assert check_rollout(q, tcp, o, a, limits, arm=12) == "instability"


def test_platform_info_describes_frame_size_and_state_layout():
    """`frame_features` takes the camera's height × width and the state / end-effector columns from the
    platform's info; a pose list that is not 7 per arm is refused when the info is made."""
    import pytest

    from wsp_data.schema import PLATFORM_INFO, PlatformInfo, frame_features

    panda = frame_features(PLATFORM_INFO["maniskill"])
    assert panda["observation.images.base_camera"]["shape"] == (128, 128, 3)
    assert panda["observation.state"]["shape"] == (9,) and panda["observation.ee_pose"]["shape"] == (7,)
    two = PlatformInfo("two_arm", 20, 320, 240, "head", "two_arms", "joints", ("a",), "action.ee", "ee", ("b",),
                       "test", state_names=tuple(f"s{i}" for i in range(14)),
                       ee_names=tuple(f"l{i}" for i in range(7)) + tuple(f"r{i}" for i in range(7)))
    f = frame_features(two)
    assert f["observation.images.head"]["shape"] == (240, 320, 3)
    assert f["observation.state"]["shape"] == (14,) and f["observation.ee_pose"]["shape"] == (14,)
    with pytest.raises(ValueError, match="7 each"):
        PlatformInfo("bad", 20, 320, 240, "head", "r", "j", ("a",), "action.ee", "e", ("b",), "t", ee_names=("x",))
