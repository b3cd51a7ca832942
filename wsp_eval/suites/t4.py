"""T4 Interaction grounding (SPEC §3 T4): track the evaluated object and the distal arm through the generated
video (`wsp_eval.tracking`, tracker backend); S = 100·1[g ≥ 0.5·g_ref]·1[tracked]·1[d ≤ 10 px] (tracked: the
object is visible in at least half as many frames as in the reference); report by kind."""

from __future__ import annotations

import numpy as np

from wsp_eval.tracking import t4_score

SUITE, TITLE = "t4", "Interaction grounding"
ROLES = ("reference",)
NEEDS = ("tracker",)
GROUP_BY, BALANCED = "kind", False


def prepare(ref, backends) -> dict:
    return {"object_px": np.asarray(ref.row["object_pixel_256"], np.float64), "mask0": ref.masks("reference")[0],
            "gate_reference": float(ref.row["gate_reference"]),
            "visible_reference": float(ref.row["object_visible_fraction"])}


def score_seed(prepared: dict, videos, backends) -> tuple[float, dict]:
    frames, _ = videos["reference"]
    s = t4_score(frames, prepared["object_px"], prepared["mask0"], prepared["gate_reference"],
                 prepared["visible_reference"], backends.tracker)
    return s.score, {"displacement": s.displacement, "gate": s.gate, "gate_passed": s.gate_passed,
                     "visible_fraction": s.visible_fraction, "tracked": s.tracked}


def groups(rows: list[dict]) -> list[str]:
    return [r["kind"] for r in rows]
