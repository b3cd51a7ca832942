"""T4 Interaction grounding (spec §3.4): track the evaluated object and the distal arm through the generated
video (`wsp_eval.tracking`, tracker backend); S = 100·1[g ≥ 0.5·g_ref]·1[tracked]·1[d ≤ 10 px] (tracked: the
object is visible in at least half as many frames as the same tracker sees it in the reference); report by kind."""

from __future__ import annotations

import numpy as np

from wsp_eval.tracking import object_motion, scoring_video, t4_score

SUITE, TITLE = "t4", "Interaction grounding"
ROLES = ("reference",)
NEEDS = ("tracker",)
GROUP_BY, BALANCED = "kind", False
REFERENCE_RESULTS = True  # `prepare` keeps its result on the reference in the reference-result cache


def prepare(ref, backends) -> dict:
    """The instance's query point, frame-0 mask and gate; the object's visible fraction in the reference is
    measured here with the scoring tracker (not read from the release; kept in the reference-result cache), so
    that the tracking-failure rule compares like with like whichever tracker scores and whichever tracker
    version built the release."""
    object_px, mask0 = np.asarray(ref.row["object_pixel_256"], np.float64), ref.first_mask("reference")
    tracker = backends.tracker

    def visible() -> dict:
        frames = ref.frames("reference")
        video = tracker.prepare(frames) if tracker else scoring_video(frames)
        return {"visible_reference": object_motion(video, object_px, mask0, tracker).visible_fraction}

    hands = ref.row.get("hand_pixels_256")  # two-arm platforms: the gate is per hand
    return {"object_px": object_px, "mask0": mask0, "gate_reference": float(ref.row["gate_reference"]),
            "visible_reference": ref.cached(visible)["visible_reference"],
            "hands": None if hands is None else np.asarray(hands, np.float64)}


def score_seed(prepared: dict, videos, backends) -> tuple[float, dict]:
    frames, _ = videos["reference"]
    s = t4_score(frames, prepared["object_px"], prepared["mask0"], prepared["gate_reference"],
                 prepared["visible_reference"], backends.tracker, prepared["hands"])
    return s.score, {"displacement": s.displacement, "gate": s.gate, "gate_passed": s.gate_passed,
                     "visible_fraction": s.visible_fraction, "tracked": s.tracked}


def groups(rows: list[dict]) -> list[str]:
    return [r["kind"] for r in rows]
