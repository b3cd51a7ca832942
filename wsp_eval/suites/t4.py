"""T4 Interaction grounding (spec §3.4): track the evaluated object and the distal arm through the generated
video (`wsp_eval.tracking`, tracker backend) and check that the object is still drawn where it stands
(`wsp_eval.object_presence`); S = 100·1[g ≥ 0.5·g_ref]·1[tracked]·1[d ≤ 10 px]·1[P ≥ 0.4] (tracked: the
object is visible in at least half as many frames as the same tracker sees it in the reference; P: its presence);
report by kind."""

from __future__ import annotations

import numpy as np

from wsp_eval.object_presence import KEEP, PresenceReference, frame_presence, presence, presence_reference
from wsp_eval.tracking import SCORING_SIZE, object_motion, scoring_video, t4_score

SUITE, TITLE = "t4", "Interaction grounding"
ROLES = ("reference",)
NEEDS = ("tracker",)
GROUP_BY, BALANCED = "kind", False
REFERENCE_RESULTS = True  # `prepare` keeps its result on the reference in the reference-result cache


def prepare(ref, backends) -> dict:
    """The instance's query point, frame-0 mask and gate; the reference side of the tracking-failure and presence
    rules, measured here on the reference and kept in the reference-result cache: the object's visible fraction
    with the scoring tracker (not read from the release, so that the rule compares like with like whichever
    tracker scores and whichever tracker version built the release) and the presence reference."""
    object_px, mask0 = np.asarray(ref.row["object_pixel_256"], np.float64), ref.first_mask("reference")
    tracker = backends.tracker

    def reference_side() -> dict:
        frames = ref.frames("reference")
        video = tracker.prepare(frames) if tracker else scoring_video(frames)
        objects = ref.object_masks("reference")
        evaluated = objects == int(ref.row["evaluated_object_index"]) + 1
        present = presence_reference(frames, evaluated, ref.masks("reference") > 0, (objects > 0) & ~evaluated,
                                     ref.fps)
        return {"visible_reference": object_motion(video, object_px, mask0, tracker).visible_fraction,
                "presence": present.to_record()}

    side = ref.cached(reference_side, ("visible_reference", "presence"))
    hands = ref.row.get("hand_pixels_256")  # two-arm platforms: the gate is per hand
    return {"object_px": object_px, "mask0": mask0, "gate_reference": float(ref.row["gate_reference"]),
            "visible_reference": side["visible_reference"],
            "hands": None if hands is None else np.asarray(hands, np.float64),
            "presence": PresenceReference.from_record(side["presence"])}


def score_seed(prepared: dict, videos, backends) -> tuple[float, dict]:
    frames, _ = videos["reference"]
    s = t4_score(frames, prepared["object_px"], prepared["mask0"], prepared["gate_reference"],
                 prepared["visible_reference"], backends.tracker, prepared["hands"])
    ref = prepared["presence"]
    h, w = ref.shape
    shifts = s.shifts * np.array([w, h], np.float64) / SCORING_SIZE
    p = presence(frame_presence(frames, ref, shifts), ref.window)
    present = p >= KEEP
    return s.score * present, {"displacement": s.displacement, "gate": s.gate, "gate_passed": s.gate_passed,
                               "visible_fraction": s.visible_fraction, "tracked": s.tracked, "presence": p,
                               "present": bool(present)}


def groups(rows: list[dict]) -> list[str]:
    return [r["kind"] for r in rows]
