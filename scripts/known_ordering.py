"""The known-ordering check of the suites: the reference world model saved along one training run must come
out in the order it was trained, worst first (`docs/analyses.md#known-ordering`).

    .venv/bin/python scripts/train_reference_model.py --platform maniskill --work refmodel-ms --no-install \
        --snapshots 250 1000 2500
    .venv/bin/python scripts/known_ordering.py --release refeval-ms --out ordering-ms \
        --checkpoints refmodel-ms/step250 refmodel-ms/step1000 refmodel-ms/step2500 refmodel-ms
    # writes <out>/<name>/ (submissions), <out>/reports/<name>/ (reports), and <out>/ordering.{json,png,md}
    # (`wsp study ordering` on those reports)

Each checkpoint folder holds `<platform>.pt` files (a snapshot folder, a training run's work folder, or
`wsp_models/reference/checkpoints`); a model is named `reference@<steps>` by its record. Resumable: submissions
and scoring resume where they stopped.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from wsp_eval.generate import GenerateError, generate
from wsp_eval.score import score_submission
from wsp_eval.studies import ordering
from wsp_models.reference.model import ReferenceModel


def name_of(model: ReferenceModel, folder: Path) -> str:
    """`reference@<steps>` of `model`, loaded from `folder` (every platform's checkpoint must agree)."""
    steps = {summary["steps"] for summary in model.wsp_info["reference_model"].values()}
    if len(steps) != 1:
        sys.exit(f"{folder}: expected reference-model checkpoints of one step count, found {sorted(steps)}")
    return f"reference@{steps.pop()}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--release", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--checkpoints", type=Path, nargs="+", required=True,
                    help="checkpoint folders in their known order, least trained first")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0],
                    help="generation seeds (default 0: the model is deterministic, the seeds give one video)")
    ap.add_argument("--configs", nargs="+", help="only these configs (default: every scored config)")
    ap.add_argument("--workers", type=int, default=2, help="scoring workers")
    args = ap.parse_args()
    try:
        models = [ReferenceModel(f) for f in args.checkpoints]  # each folder checked before any work
    except GenerateError as e:
        sys.exit(f"known_ordering.py: {e}")
    names = [name_of(m, f) for m, f in zip(models, args.checkpoints)]
    reports = []
    for model, name in zip(models, names):
        print(f"[ordering] {name}: generate and score", flush=True)
        sub = args.out / name
        generate(model, args.release, sub, seeds=args.seeds, configs=args.configs, name=name)
        score_submission(sub, args.release, args.out / "reports" / name, workers=args.workers)
        reports.append(args.out / "reports" / name)
    result = ordering.run(args.release, reports, args.out)
    table = ordering.markdown(result)
    (args.out / "ordering.md").write_text(table)
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
