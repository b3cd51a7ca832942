"""Suite scorers, found by name. One module per suite; this is the one place that registers them."""

from __future__ import annotations

from wsp_eval.suites import t1

SCORERS = {"t1": t1}
