"""Backends, found by name (SPEC §4): one registry per role, each with an offline CPU default.

    flow      dis (default, OpenCV DIS)        dpflow (ptlflow, local checkpoint)
    tracker   lk (default, OpenCV LK + FB)     tapnext (tapnet, local checkpoint)
    judge     rules (default, deterministic)   openai (any OpenAI-compatible VLM endpoint, e.g. Qwen3-VL)

`BackendSpec` names a choice (and its checkpoint or endpoint) and is what worker processes receive;
`make` builds the backends from it, raising `BackendUnavailable` with a clear message when a package, a
checkpoint or an endpoint is missing. Nothing downloads.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from wsp_eval.backends.errors import BackendUnavailable


def _rules_judge(spec: BackendSpec):
    from wsp_eval.backends.judge_rules import RulesJudge

    return RulesJudge()


def _openai_judge(spec: BackendSpec):
    from wsp_eval.backends.judge_openai import OpenAIJudge

    if not spec.judge_url or not spec.judge_model:
        raise BackendUnavailable("judge backend 'openai' needs --judge-url (e.g. http://127.0.0.1:8000/v1) and "
                                 "--judge-model (e.g. Qwen/Qwen3-VL-8B-Instruct)")
    judge = OpenAIJudge(spec.judge_url, spec.judge_model)
    judge.ping()
    return judge


def _dis(spec: BackendSpec):
    from wsp_eval.backends.flow import DISFlow

    return DISFlow()


def _dpflow(spec: BackendSpec):
    from wsp_eval.backends.flow import DPFlow

    return DPFlow(spec.flow_checkpoint)


def _lk(spec: BackendSpec):
    from wsp_eval.backends.tracker import LKTracker

    return LKTracker()


def _tapnext(spec: BackendSpec):
    from wsp_eval.backends.tracker import TAPNextTracker

    return TAPNextTracker(spec.tracker_checkpoint)


FLOW = {"dis": _dis, "dpflow": _dpflow}
TRACKER = {"lk": _lk, "tapnext": _tapnext}
JUDGE = {"rules": _rules_judge, "openai": _openai_judge}
REGISTRIES = {"flow": FLOW, "tracker": TRACKER, "judge": JUDGE}


@dataclass(frozen=True)
class BackendSpec:
    """Which backend plays each role, with the checkpoint or endpoint it needs."""

    flow: str = "dis"
    tracker: str = "lk"
    judge: str = "rules"
    flow_checkpoint: str | None = None
    tracker_checkpoint: str | None = None
    judge_url: str | None = None
    judge_model: str | None = None

    def __post_init__(self):
        for role, registry in REGISTRIES.items():
            if getattr(self, role) not in registry:
                raise BackendUnavailable(f"unknown {role} backend {getattr(self, role)!r}; known: {', '.join(registry)}")

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
