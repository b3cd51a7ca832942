"""Backends, found by name (spec §4.6): one registry per role, each with an offline CPU default. A registry
entry is a factory `(BackendSpec) -> backend`; other distributions add some through the entry-point groups
`worldsimprobe.flow`, `worldsimprobe.tracker` and `worldsimprobe.judge` (`wsp_eval.registry`).

    flow      dis (default, OpenCV DIS)        dpflow (ptlflow, local checkpoint)
    tracker   lk (default, colour region +     tapnext (tapnet, local checkpoint)
              OpenCV LK + FB)
    judge     net (default, learned, ONNX on    rules (deterministic hand rules, the former default)
              OpenCV dnn; weights packaged)   openai (any OpenAI-compatible VLM endpoint, e.g. Qwen3-VL)

`BackendSpec` names a choice (and its checkpoint or endpoint) and is what worker processes receive;
`make` builds the backends from it, raising `BackendUnavailable` with a clear message when a package, a
checkpoint or an endpoint is missing. Nothing downloads.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from wsp_eval.backends.errors import BackendUnavailable
from wsp_eval.registry import Registry

Factory = Callable[["BackendSpec"], Any]
FLOW: Registry[Factory] = Registry("flow backend", "worldsimprobe.flow")
TRACKER: Registry[Factory] = Registry("tracker backend", "worldsimprobe.tracker")
JUDGE: Registry[Factory] = Registry("judge backend", "worldsimprobe.judge")
REGISTRIES = {"flow": FLOW, "tracker": TRACKER, "judge": JUDGE}


@JUDGE.register("net")
def _net_judge(spec: BackendSpec):
    from wsp_eval.backends.judge_net import NetJudge

    return NetJudge(spec.judge_checkpoint)


@JUDGE.register("rules")
def _rules_judge(spec: BackendSpec):
    from wsp_eval.backends.judge_rules import RulesJudge

    return RulesJudge()


@JUDGE.register("openai")
def _openai_judge(spec: BackendSpec):
    from wsp_eval.backends.judge_openai import OpenAIJudge

    if not spec.judge_url or not spec.judge_model:
        raise BackendUnavailable("judge backend 'openai' needs --judge-url (e.g. http://127.0.0.1:8000/v1) and "
                                 "--judge-model (e.g. Qwen/Qwen3-VL-8B-Instruct)")
    judge = OpenAIJudge(spec.judge_url, spec.judge_model)
    judge.ping()
    return judge


@FLOW.register("dis")
def _dis(spec: BackendSpec):
    from wsp_eval.backends.flow import DISFlow

    return DISFlow()


@FLOW.register("dpflow")
def _dpflow(spec: BackendSpec):
    from wsp_eval.backends.flow import DPFlow

    return DPFlow(spec.flow_checkpoint)


@TRACKER.register("lk")
def _lk(spec: BackendSpec):
    from wsp_eval.backends.tracker import LKTracker

    return LKTracker()


@TRACKER.register("tapnext")
def _tapnext(spec: BackendSpec):
    from wsp_eval.backends.tracker import TAPNextTracker

    return TAPNextTracker(spec.tracker_checkpoint)


@dataclass(frozen=True)
class BackendSpec:
    """Which backend plays each role, with the checkpoint or endpoint it needs."""

    flow: str = "dis"
    tracker: str = "lk"
    judge: str = "net"
    flow_checkpoint: str | None = None
    tracker_checkpoint: str | None = None
    judge_url: str | None = None
    judge_model: str | None = None
    judge_checkpoint: str | None = None  # judge `net`: other weights than the packaged ones

    def __post_init__(self):
        for role, registry in REGISTRIES.items():
            if getattr(self, role) not in registry:
                raise BackendUnavailable(f"unknown {registry.kind} {getattr(self, role)!r}; known: {', '.join(registry)}")

    def to_json(self) -> dict:
        return asdict(self)


@dataclass
class Backends:
    """The constructed backends (built once per worker process)."""

    flow: Any
    tracker: Any
    judge: Any

    def describe(self) -> dict:
        """Name and version of every constructed backend (roles a scoring did not need are left out)."""
        return {role: {"name": b.name, "version": b.version} for role, b in
                (("flow", self.flow), ("tracker", self.tracker), ("judge", self.judge)) if b is not None}


def make(spec: BackendSpec, roles: tuple[str, ...] = ("flow", "tracker", "judge")) -> Backends:
    """Build the backends of `spec` (roles not listed stay None: a T1-only scoring needs none)."""
    return Backends(*(REGISTRIES[r][getattr(spec, r)](spec) if r in roles else None
                      for r in ("flow", "tracker", "judge")))
