"""The oracle under common video encodings: what `wsp validate` says of each, and what each would score if it
were accepted (`wsp score --accept-lossy`), per config, beside the lossless oracle (docs/submission.md).

    .venv/bin/python benchmarks/encoding_study.py RELEASE --out DIR [--workers 2] [--only TEXT ...]

Writes the oracle baseline (seed 0) once, re-encodes every video of it per encoding in ENCODINGS (PyAV, the
frames decoded from the lossless oracle, scaled with area/bicubic resampling where the encoding changes the
size), validates and scores each, and prints a Markdown table; `DIR/encoding_study.json` keeps the numbers.
Resumable: finished encodings and scores are reused (the score cache).
"""

from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import av
import cv2
import numpy as np
from tqdm import tqdm

from wsp_eval.baselines import write_baseline
from wsp_eval.score import score_submission
from wsp_eval.submission import SUBMISSION_JSON, validate
from wsp_eval.video import read_video


@dataclass(frozen=True)
class Encoding:
    name: str
    codec: str
    pix_fmt: str
    options: dict
    side: int | None = None  # resample to side×side before encoding (None: as produced)


ENCODINGS = (
    Encoding("h264 RGB crf 0 (wsp generate)", "libx264rgb", "rgb24", {"crf": "0"}),
    Encoding("png in mp4", "png", "rgb24", {}),
    Encoding("h264 RGB crf 0, 256×256", "libx264rgb", "rgb24", {"crf": "0"}, 256),
    Encoding("h264 yuv444p qp 0", "libx264", "yuv444p", {"qp": "0"}),
    Encoding("h264 yuv420p qp 0", "libx264", "yuv420p", {"qp": "0"}),
    Encoding("h264 yuv444p crf 18", "libx264", "yuv444p", {"crf": "18"}),
    Encoding("h264 yuv420p crf 18", "libx264", "yuv420p", {"crf": "18"}),
    Encoding("h264 yuv420p crf 23, 256×256", "libx264", "yuv420p", {"crf": "23"}, 256),
    Encoding("h264 yuv420p crf 28, 128×128", "libx264", "yuv420p", {"crf": "28"}, 128),
    Encoding("h264 RGB crf 0, 192×192", "libx264rgb", "rgb24", {"crf": "0"}, 192),
    Encoding("h264 RGB crf 0, 96×96", "libx264rgb", "rgb24", {"crf": "0"}, 96),
)


def encode(frames: np.ndarray, fps: float, path: Path, enc: Encoding) -> None:
    if enc.side is not None and frames.shape[1:3] != (enc.side, enc.side):
        interp = cv2.INTER_AREA if enc.side < frames.shape[1] else cv2.INTER_CUBIC
        frames = np.stack([cv2.resize(f, (enc.side, enc.side), interpolation=interp) for f in frames])
    with av.open(str(path), "w", format="mp4") as container:
        stream = container.add_stream(enc.codec, rate=int(round(fps)))
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], enc.pix_fmt
        stream.options = {**enc.options, "threads": "1"}
        for f in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(f, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def reencode(oracle: Path, out: Path, enc: Encoding) -> None:
    done = out.with_name(out.name + ".complete")  # beside the submission: a submission holds only its files
    if done.is_file():
        return
    shutil.rmtree(out, ignore_errors=True)
    videos = sorted(oracle.rglob("*.mp4"))
    for src in tqdm(videos, desc=enc.name, unit="video", leave=False):
        dst = out / src.relative_to(oracle)
        dst.parent.mkdir(parents=True, exist_ok=True)
        encode(*read_video(src), dst, enc)
    shutil.copy(oracle / SUBMISSION_JSON, out / SUBMISSION_JSON)
    done.touch()


def suite_scores(report: dict) -> dict[str, float]:
    return {f"{s}_{p}": v["score"] for p, plat in report["platforms"].items()
            for s, v in plat["suites"].items() if v.get("score") is not None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("release", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--only", nargs="+", default=(), help="encodings whose name contains one of these (the first "
                    "encoding, the lossless baseline, is always kept)")
    args = ap.parse_args()
    oracle = args.out / "oracle"
    write_baseline("oracle", args.release, oracle, seeds=(0,), progress=True)
    rows = []
    for i, enc in enumerate(ENCODINGS):
        if i and args.only and not any(t in enc.name for t in args.only):
            continue
        sub = args.out / f"enc{i}"
        reencode(oracle, sub, enc)
        problems = validate(sub, args.release)
        report = score_submission(sub, args.release, args.out / f"report{i}", workers=args.workers,
                                  accept_lossy=True, progress=False)
        first = problems[0].message.split(";")[0] if problems else ""
        rows.append({"encoding": enc.name, "refused": len(problems), "reason": first, "scores": suite_scores(report)})
        print(f"{enc.name}: {len(problems)} refused; {rows[-1]['scores']}", flush=True)
    (args.out / "encoding_study.json").write_text(json.dumps(rows, indent=1))
    configs = sorted(rows[0]["scores"])
    base = rows[0]["scores"]
    print("\n| encoding | `wsp validate` | " + " | ".join(configs) + " | largest change |")
    print("|---|---|" + "---:|" * (len(configs) + 1))
    for r in rows:
        verdict = "accepted" if not r["refused"] else f"refused ({r['reason']})"
        worst = max(abs(r["scores"][c] - base[c]) for c in configs)
        print(f"| {r['encoding']} | {verdict} | " + " | ".join(f"{r['scores'][c]:.1f}" for c in configs)
              + f" | {worst:.1f} |")


if __name__ == "__main__":
    main()
