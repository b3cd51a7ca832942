"""The T3 source protocol (`wsp_data.platforms.t3_sources`) on stand-in sources, without a simulator: every
source answers `stream(seed)` with its stream and provenance; an operator's failures are kept."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wsp_data.platforms.t3_sources import (
    ExpertStream, OperatorAttempt, ScriptedOperatorSource, SourceStream, operator_style,
)


class Expert:
    def __init__(self):
        self.closed = False

    def trajectory(self, seed: int) -> np.ndarray | None:
        return None if seed < 0 else np.full((3, 2), seed, np.float32)

    def close(self) -> None:
        self.closed = True


class Operator(ScriptedOperatorSource):
    def attempt(self, seed: int) -> OperatorAttempt:
        if seed < 0:
            return OperatorAttempt(None, False, "ValueError: no plan")
        return OperatorAttempt(np.zeros((4, 2), np.float32), success=seed % 2 == 0)

    @property
    def provenance(self) -> dict:
        return {"kind": "scripted_operator", "operator": "H1"}

    def close(self) -> None:
        pass


def test_expert_stream_is_the_verified_trajectory_and_leaves_the_expert_open():
    expert = Expert()
    src = ExpertStream(expert, "experts.PickCube")
    s = src.stream(2)
    assert isinstance(s, SourceStream) and np.array_equal(s.actions, expert.trajectory(2))
    assert s.provenance == {"kind": "scripted_expert", "script": "experts.PickCube"}
    assert src.stream(-1).actions is None
    src.close()
    assert not expert.closed


def test_operator_stream_keeps_failures():
    src = Operator()
    assert src.stream(1).actions.shape == (4, 2)  # a failed replay: the stream is kept
    assert src.stream(-1).actions is None  # the script itself failed
    assert src.stream(0).provenance == src.provenance


def test_streams_and_attempts_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        SourceStream(None, {}).actions = np.zeros(1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        OperatorAttempt(None, False).success = True


def test_operator_style_names_the_known_operators():
    assert operator_style({"H1": 1}, "H1") == 1
    with pytest.raises(KeyError, match="H1, H2"):
        operator_style({"H1": 1, "H2": 2}, "H9")
