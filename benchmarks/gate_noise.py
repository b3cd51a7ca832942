"""How far a grey level of noise moves T4's motion gate (docs/validity.md, T4 tracker): for every T4 reference of
a release, the gate g of its stored video as the scorer reads it, then g of the same video with independent
uniform noise of −1, 0 or +1 grey level per pixel and channel (draws 0..N−1). A faithful video differs from the
reference by at least that much, and the gate passes it only when g ≥ 0.5·g_ref.

    .venv/bin/python benchmarks/gate_noise.py RELEASE [--draws 8] [--out FILE.json]

Prints per config: references, those whose gate fails under some draw, the failing draws, and the range of
g / g_ref over every draw; --out keeps each reference's figures.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval.reference import reference_frames, reference_masks
from wsp_eval.release_format import INSTANCES
from wsp_eval.tracking import GATE_RATIO, motion_gate, scoring_video


def noisy(video: np.ndarray, draw: int) -> np.ndarray:
    """`video` with −1, 0 or +1 grey level added to every value (draw `draw`), clipped to 0..255."""
    levels = np.random.default_rng(draw).integers(-1, 2, video.shape, dtype=np.int16)
    return np.clip(video.astype(np.int16) + levels, 0, 255).astype(np.uint8)


def reference_gates(config_dir: Path, row: dict, draws: int) -> dict:
    episode = row["episode_indices"][0]
    video = reference_frames(config_dir, episode)
    mask0 = reference_masks(config_dir, episode, first_only=True)[0]
    hands = np.array(row["hand_pixels_256"]) if row.get("hand_pixels_256") is not None else None
    stored = motion_gate(scoring_video(video), mask0, hands=hands)
    ratios = [motion_gate(scoring_video(noisy(video, d)), mask0, hands=hands) / row["gate_reference"]
              for d in range(draws)]
    return {"instance_id": row["instance_id"], "task": row["task"], "kind": row["kind"],
            "gate_reference": row["gate_reference"], "gate_stored": stored, "ratios": ratios,
            "failing_draws": sum(r < GATE_RATIO for r in ratios)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("release", type=Path)
    p.add_argument("--draws", type=int, default=8)
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    results = {}
    for config_dir in sorted(d for d in args.release.iterdir() if d.name.startswith("t4_")):
        rows = pq.read_table(config_dir / INSTANCES).to_pylist()
        results[config_dir.name] = [reference_gates(config_dir, r, args.draws) for r in rows]
    for config, refs in results.items():
        ratios = [x for r in refs for x in r["ratios"]]
        print(f"{config}: {len(refs)} references; {sum(r['failing_draws'] > 0 for r in refs)} fail the gate under "
              f"some draw ({sum(r['failing_draws'] for r in refs)} of {len(ratios)} draws); g/g_ref "
              f"{min(ratios):.2f}–{max(ratios):.2f}")
    if args.out:
        args.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
