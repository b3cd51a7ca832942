"""T5's object error per reference and stand-in, without the arm gate or the label judge: for every reference of a
T5 config and every variant named (those of `wsp study t5-negatives`), the blur levels T5 reads off the video
(`object_track.sharpness` and `object_track.arm_sharpness`, as scene/arm), the object's relative error x
(`object_track.relative_error`; fidelity 100 at x ≤ 0.35, 0 at x ≥ 0.65) and, of it, the error at the place the
object left (x_vac), the largest windowed appearance error (x_win) and the frame-to-frame error (x_step). The
quick look behind the sharpness rules' design figures (spec §4.3), on training-range builds:

    .venv/bin/python benchmarks/t5_clip_errors.py RELEASE t5_maniskill --variants oracle blur blur_1px noise frozen
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval import object_track as ot
from wsp_eval.release_format import INSTANCES
from wsp_eval.studies import t5_negatives as tn
from wsp_eval.suites.reference import InstanceReference


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("release", type=Path)
    ap.add_argument("config")
    ap.add_argument("--variants", nargs="+", default=["oracle", "blur", "blur_1px", "noise", "frozen"],
                    choices=tn.variant_names(), metavar="VARIANT")
    args = ap.parse_args()
    heads = " | ".join(f"{v} [blur/arm] x (x_vac, x_win, x_step)" for v in args.variants)
    print(f"| reference | primitive | kind | {heads} |")
    print(f"|---|---|---|{'---:|' * len(args.variants)}")
    for row in pq.read_table(args.release / args.config / INSTANCES).to_pylist():
        ref = InstanceReference(args.release / args.config, row)
        clip, k = tn.Clip(ref), int(row["evaluated_index"])
        track = ot.object_track(clip.frames, ref.object_masks("reference"), k + 1, ref.masks("reference"),
                                ref.object_pose("reference", k))
        if not track.scorable:
            print(f"| {row['instance_id']} | {row['primitive']} | not scorable |{' |' * len(args.variants)}")
            continue
        cells = []
        for name in args.variants:
            frames = tn.variant_frames(clip, name)
            found = ot.positions(frames, track, np.arange(len(frames)))
            cells.append(f"[{found.blur:g}/{found.arm:g}] {ot.relative_error(found):.2f} ({found.vacated:.2f}, "
                         f"{found.windowed:.2f}, {found.stepped:.2f})")
        kind = "travels" if track.moving else "turns"
        print(f"| {row['instance_id']} | {row['primitive']} | {kind} | {' | '.join(cells)} |", flush=True)


if __name__ == "__main__":
    main()
