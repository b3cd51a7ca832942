"""The one protocol of T3's action sources, on every platform: `T3Source.stream(seed) -> SourceStream`.

T3 (spec §3.3) replays, per task and scene seed, one action stream of each source group: the scripted expert,
the scripted operator models H1–H5 and the early and late behaviour-cloned policy checkpoints. Every source
answers the same call, `stream(seed)`, with the stream it produced on that scene and the provenance the release
stores beside it (`source_provenance`); the T3 builder calls nothing else, whichever group it asks.

- The expert: `ExpertStream` around the platform's expert source (`PlatformKit.make_expert`); its stream is the
  verified trajectory (None: no verified success on that seed).
- Operators: subclasses of `ScriptedOperatorSource` (each platform's `t3.py`), whose `attempt(seed)` runs the
  operator's script and returns an `OperatorAttempt`; the stream is the attempt's, kept whether it succeeds or
  fails (None: the script itself failed).
- Policies: `wsp_data.platforms.bc_policy.BCPolicySource`, whose stream is the closed-loop rollout.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

S = TypeVar("S")


@dataclass(frozen=True)
class SourceStream:
    """What a T3 source produced on one scene seed: its native action stream ((T, D) float32, or None when
    it produced none) and its provenance (a JSON-able dict; "kind" is `scripted_expert`, `scripted_operator`
    or `bc_policy`)."""

    actions: np.ndarray | None
    provenance: dict


class T3Source(Protocol):
    """A T3 action source of one task (`PlatformKit.t3_source`, or `ExpertStream`)."""

    def stream(self, seed: int) -> SourceStream:
        """The source's action stream from `reset(seed)` and its provenance."""

    def close(self) -> None:
        """Release the simulators the source opened."""


@dataclass(frozen=True)
class OperatorAttempt:
    """One scripted operator run: its recorded stream (None if the script itself failed), whether the run ended
    in task success, and the script's error where it failed."""

    actions: np.ndarray | None
    success: bool
    error: str | None = None


class VerifiedExpert(Protocol):
    """A platform's expert source (`PlatformKit.make_expert`), as far as T3 uses it."""

    def trajectory(self, seed: int) -> np.ndarray | None:
        """The verified (T, D) float32 stream of scene `seed`, or None: no verified success on that seed."""


class ExpertStream:
    """The scripted expert as a T3 source. The expert source belongs to the caller (a build rig), which closes
    it: `close` leaves it open."""

    def __init__(self, expert: VerifiedExpert, script: str):
        self.expert, self.script = expert, script

    def stream(self, seed: int) -> SourceStream:
        return SourceStream(self.expert.trajectory(seed), {"kind": "scripted_expert", "script": self.script})

    def close(self) -> None:
        """Nothing to release: the expert is the caller's."""


class ScriptedOperatorSource(ABC):
    """A scripted operator model (H1–H5) on one task; a platform implements `attempt`, `provenance`, `close`."""

    @abstractmethod
    def attempt(self, seed: int) -> OperatorAttempt:
        """Run the operator's script from scene `seed` and report its stream and whether it succeeded."""

    @property
    @abstractmethod
    def provenance(self) -> dict:
        """The operator's parameters (stored as the T3 row's `source_provenance`; "kind": scripted_operator)."""

    @abstractmethod
    def close(self) -> None:
        """Release the operator's simulators."""

    def stream(self, seed: int) -> SourceStream:
        """The attempt's stream, success or not (T3 keeps failures: the builder replays it and records success)."""
        return SourceStream(self.attempt(seed).actions, self.provenance)


def operator_style(operators: Mapping[str, S], operator: str) -> S:
    """`operators[operator]`, or KeyError naming the known operators."""
    if operator not in operators:
        raise KeyError(f"unknown operator {operator!r}; operators: {', '.join(operators)}")
    return operators[operator]
