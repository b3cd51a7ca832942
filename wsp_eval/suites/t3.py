"""T3 Action-source behaviour preservation (spec §3.3): RMFA as in T2, reported per source group
(`source_group`: expert, H1–H5, early policy, late policy) and overall."""

from __future__ import annotations

from wsp_eval.suites import t2

SUITE, TITLE = "t3", "Action-source behaviour preservation"
ROLES = ("reference",)
NEEDS = ("flow",)
GROUP_BY, BALANCED = "source group", False
REFERENCE_RESULTS = False
prepare, score_seed = t2.prepare, t2.score_seed  # the same RMFA scoring as T2


def groups(rows: list[dict]) -> list[str]:
    return [r["source_group"] for r in rows]
