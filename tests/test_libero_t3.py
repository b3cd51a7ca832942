"""T3's LIBERO sources on real scenes: operator styles differ from the expert as documented, policy checkpoints
load, act deterministically and replay state for state, and a missing checkpoint is a clear error."""

from __future__ import annotations

import numpy as np
import pytest

from wsp_data.platforms.bc_policy import STAGES, PolicyCheckpointMissing
from wsp_data.platforms.libero.experts import LiberoExpertSource
from wsp_data.platforms.libero.t3 import OPERATORS, T3_TASKS, LiberoOperatorSource, LiberoPolicySource, checkpoint_path

TASK = T3_TASKS[0]
SEED = 910_100  # a training-range seed outside the policies' demonstration and evaluation seeds


def jerk(actions: np.ndarray) -> float:
    return float(np.abs(np.diff(actions[:, :3], 2, axis=0)).mean())


@pytest.fixture(scope="module")
def expert():
    src = LiberoExpertSource(TASK)
    yield src.trajectory(SEED)
    src.close()


@pytest.fixture(scope="module")
def operator_runs():
    out = {}
    for op in OPERATORS:
        src = LiberoOperatorSource(TASK, op)
        out[op] = (src.attempt(SEED), src.provenance)
        src.close()
    return out


def test_operator_styles_are_what_the_docs_say(expert, operator_runs):
    n, j = len(expert), jerk(expert)
    runs = {op: r for op, (r, _) in operator_runs.items()}
    assert len(runs["H1"].actions) > 1.5 * n  # slow
    assert len(runs["H2"].actions) < n  # fast
    assert jerk(runs["H3"].actions) > 3 * j  # jerky
    assert len(runs["H4"].actions) > 1.3 * n  # hesitant: stops, idles, backs off, re-approaches
    assert not np.array_equal(runs["H5"].actions[:20], expert[:20])  # another approach path
    for op, (r, prov) in operator_runs.items():
        assert prov["kind"] == "scripted_operator" and prov["operator"] == op and prov["platform"] == "libero"
        assert r.actions.shape[1] == 7 and np.abs(r.actions[:, :6]).max() <= 1.0


@pytest.mark.parametrize("stage", STAGES)
def test_policy_checkpoints_run_deterministically_and_replay(stage):
    assert checkpoint_path(TASK, stage).is_file()
    src = LiberoPolicySource(TASK, stage)
    try:
        a, ok = src.trajectory(SEED)
        b, ok2 = src.trajectory(SEED)
        assert np.array_equal(a, b) and ok == ok2
        assert a.shape[1] == 7 and set(np.unique(a[:, 6])) <= {-1.0, 1.0}
        states = [src.platform.reset(SEED)] + [src.platform.step(x) for x in a]
        replay = src.platform.replay(SEED, a)
        assert np.array_equal(replay.stack("qpos"), np.stack([s.qpos for s in states]))
        prov = src.provenance
        assert prov["kind"] == "bc_policy" and prov["stage"] == stage and prov["checkpoint_sha256"]
        assert prov["training_steps"] == (2000 if stage == "early" else 20000)
    finally:
        src.close()


def test_missing_checkpoint_names_the_rebuild_command(tmp_path):
    with pytest.raises(PolicyCheckpointMissing, match="train_bc_policies.py --platform libero"):
        LiberoPolicySource(TASK, "late", checkpoint_dir=tmp_path)
