"""Suite scorers, found by name. One module per suite; this is the one place that registers them. Suites are
part of the benchmark's definition (seed ranges, release format), so `SCORERS` takes no entry points.

Every suite module provides:
    SUITE, TITLE     its key ("t1") and title
    ROLES            the generated rollouts one seed of an instance needs (roles of the instance row)
    NEEDS            the backend roles it uses ("flow", "tracker", "judge")
    GROUP_BY         what its report breakdown is cut by
    BALANCED         True when the suite score averages within groups first, then across them (T5)
    REFERENCE_RESULTS  True when `prepare` keeps a result on the reference (`InstanceReference.cached`) in
                     the reference-result cache (`wsp_eval.reference_cache`)
    prepare(ref, backends)                  reference-side work, once per instance (`InstanceReference`)
    score_seed(prepared, videos, backends)  (score 0–100, detail) for one seed; videos: role → (frames, fps)
    groups(rows)                            the breakdown group of every instance row
"""

from __future__ import annotations

from types import ModuleType

from wsp_eval.registry import Registry
from wsp_eval.suites import t1, t2, t3, t4, t5

SCORERS: Registry[ModuleType] = Registry("suite scorer")
SCORERS.register(t1.SUITE, t1)
SCORERS.register(t2.SUITE, t2)
SCORERS.register(t3.SUITE, t3)
SCORERS.register(t4.SUITE, t4)
SCORERS.register(t5.SUITE, t5)
