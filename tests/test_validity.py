"""The common validity checks (SPEC §5) on small state arrays: each failure names its reason."""

import numpy as np

from wsp_data.builders.validity import check_rollout

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
