"""T5 Interaction dynamics (SPEC §3 T5): a judge backend sees 12 uniformly sampled frames of the generated
clip (plus the stored frame-0 object position) and returns a primitive label and two booleans;
S = 100·1[label = intended]·1[agent ok]·1[object ok]. Averaged within primitive, then across primitives.
The judge also runs once on each simulator reference: its agreement with the intended labels is reported."""

from __future__ import annotations

from wsp_eval.backends.judge import sample_frames, score_verdict

SUITE, TITLE = "t5", "Interaction dynamics"
ROLES = ("reference",)
NEEDS = ("judge",)
GROUP_BY, BALANCED = "primitive", True
REFERENCE_RESULTS = True  # `prepare` keeps its result on the reference in the reference-result cache


def _judge(frames, row: dict, platform: str, judge) -> tuple[float, dict]:
    verdict = judge.judge(sample_frames(frames), tuple(float(x) for x in row["object_pixel_256"]), platform)
    detail = {"label": verdict.label, "agent_ok": verdict.agent_ok, "object_ok": verdict.object_ok}
    return score_verdict(verdict, row["primitive"]), detail


def prepare(ref, backends) -> dict:
    def verdict() -> dict:
        score, detail = _judge(ref.frames("reference"), ref.row, ref.platform, backends.judge)
        return {"score": score, **detail}

    return {"row": ref.row, "platform": ref.platform, "reference": ref.cached(verdict)}


def score_seed(prepared: dict, videos, backends) -> tuple[float, dict]:
    frames, _ = videos["reference"]
    return _judge(frames, prepared["row"], prepared["platform"], backends.judge)


def groups(rows: list[dict]) -> list[str]:
    return [r["primitive"] for r in rows]


def reference_check(prepared: dict) -> dict:
    """The judge's verdict on the simulator reference (for its reported agreement)."""
    return prepared["reference"]
