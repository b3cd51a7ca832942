"""T5's score and the label judge on a learned model's videos, against labels given by eye (docs/validity.md, T5).

A generated video has no simulator state, so the judge's verdict on it can only be checked by looking. Two steps,
run from a folder holding the releases and the submissions (paths are kept as given, relative ones relative to it):

    # 1. blind sheets: per T5 instance of the submission, the 12 frames the judge sees (spec §4.5) with the
    #    object's frame-0 position ringed, in a shuffled order under anonymous ids; no primitive, no verdict
    .venv/bin/python benchmarks/judge_on_learned.py sheets --out SHEETS RELEASE:SUBMISSION [RELEASE:SUBMISSION ...]
    # ... label every sheet in SHEETS/labels.csv by eye (columns below), then:
    # 2. T5's score (credited at ≥ 50) and the judge's verdict on each clip (the default backends, as `wsp score`
    #    runs them) against the labels
    .venv/bin/python benchmarks/judge_on_learned.py compare SHEETS [--json OUT]

labels.csv columns: `id`; `moved` (the ringed object: `yes` it visibly moves or changes pose, `no` it stays,
`vanished` it fades or disappears where it stood, `unclear`); `primitive` (the one the video shows, one of the
judge's eight, `none` when the object does not respond, `unclear` when it moves in a way no primitive names for
sure); `robot` (is the robot what moves it: yes / no / - when nothing moves). By eye a clip is *rejected* when the
object stays or vanishes (no primitive happened), *accepted* when it shows the intended primitive done by the
robot, *undecided* when the motion or the primitive is unclear; agreement is counted over decided clips. The key (`key.json`: id → release, config, episode,
seed, intended primitive) is written beside the sheets and is read only by `compare`. The labels of
the reference model's clips are in `benchmarks/judge_on_learned/` with their key.
"""

from __future__ import annotations

import argparse
import csv
import json
import random
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval.backends import BackendSpec, make
from wsp_eval.backends.judge import PRIMITIVES, sample_frames
from wsp_eval.release_format import split_config
from wsp_eval.submission import VIDEO_NAME
from wsp_eval.suites import t5
from wsp_eval.suites.reference import InstanceReference
from wsp_eval.tracking import frame_xy
from wsp_eval.video import read_video

TILE = 160
LABEL_FIELDS = ("id", "moved", "primitive", "robot")
MOVED = ("yes", "no", "vanished", "unclear")
PASS = 50.0  # T5 credits a clip scoring at least this


def _clips(pairs: list[str]) -> list[dict]:
    clips = []
    for pair in pairs:
        release, submission = (Path(p) for p in pair.split(":"))
        seed = json.loads((submission / "submission.json").read_text())["seeds"][0]
        for config in sorted(p.name for p in release.glob("t5_*")):
            for row in pq.read_table(release / config / "instances.parquet").to_pylist():
                clips.append({"release": str(release), "submission": str(submission), "config": config,
                              "episode": row["episode_ids"][0], "seed": seed, "primitive": row["primitive"],
                              "object_px": [float(v) for v in row["object_pixel_256"]]})
    return clips


def _frames(clip: dict) -> np.ndarray:
    video, _ = read_video(Path(clip["submission"], clip["config"], clip["episode"], VIDEO_NAME.format(seed=clip["seed"])))
    return sample_frames(video)


def _sheet(frames: np.ndarray, object_px: list[float]) -> np.ndarray:
    tiles = []
    x, y = frame_xy(tuple(object_px), TILE, TILE)
    for k, f in enumerate(frames):
        tile = np.ascontiguousarray(cv2.resize(f, (TILE, TILE), interpolation=cv2.INTER_LINEAR))
        cv2.circle(tile, (int(round(x)), int(round(y))), 9, (255, 40, 40), 1, cv2.LINE_AA)
        cv2.putText(tile, str(k), (3, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 0), 1, cv2.LINE_AA)
        tiles.append(tile)
    rows = [np.hstack(tiles[i:i + 6]) for i in range(0, len(tiles), 6)]
    return np.vstack(rows)


def sheets(out: Path, pairs: list[str], seed: int) -> None:
    clips = _clips(pairs)
    random.Random(seed).shuffle(clips)
    out.mkdir(parents=True, exist_ok=True)
    key = {}
    for n, clip in enumerate(clips):
        cid = f"c{n:03d}"
        key[cid] = clip
        cv2.imwrite(str(out / f"{cid}.png"), cv2.cvtColor(_sheet(_frames(clip), clip["object_px"]), cv2.COLOR_RGB2BGR))
    (out / "key.json").write_text(json.dumps(key, indent=1))
    labels = out / "labels.csv"
    if not labels.exists():
        with labels.open("w", newline="") as f:
            csv.writer(f).writerows([LABEL_FIELDS] + [[cid, "", "", ""] for cid in key])
    print(f"{len(clips)} sheets in {out}; label them in {labels}")


def _eye(label: dict, intended: str) -> str:
    """accept / reject / undecided, by eye (module doc)."""
    if label["moved"] in ("no", "vanished"):
        return "reject"
    if label["moved"] == "unclear" or label["primitive"] == "unclear":
        return "undecided"
    return "accept" if label["primitive"] == intended and label["robot"] == "yes" else "reject"


def _kind(row: dict) -> str:
    if row["eye_moved"] == "no":
        return "stays"
    if row["eye_moved"] == "vanished":
        return "vanishes"
    if row["eye_moved"] == "unclear":
        return "unclear"
    if row["eye_primitive"] == "unclear":
        return "moves, primitive unclear"
    return "accepted" if row["eye"] == "accept" else "another primitive"


def _t5_score(clip: dict, backends) -> float:
    """T5's score of the clip's whole video against its instance's reference, as `wsp score` computes it."""
    config = Path(clip["release"]) / clip["config"]
    row = next(r for r in pq.read_table(config / "instances.parquet").to_pylist()
               if r["episode_ids"][0] == clip["episode"])
    ref = InstanceReference(config, row)
    video, fps = read_video(Path(clip["submission"], clip["config"], clip["episode"],
                                 VIDEO_NAME.format(seed=clip["seed"])))
    return t5.score_seed(t5.prepare(ref, backends), {"reference": (video, fps)}, backends)[0]


def compare(folder: Path, out: Path | None) -> None:
    key = json.loads((folder / "key.json").read_text())
    labels = {r["id"]: r for r in csv.DictReader((folder / "labels.csv").open())}
    missing = [cid for cid in key if not labels.get(cid, {}).get("primitive")]
    if missing:
        raise SystemExit(f"{folder / 'labels.csv'}: {len(missing)} clips unlabelled (first: {missing[0]})")
    backends = make(BackendSpec(), t5.NEEDS)
    judge = backends.judge
    rows = []
    for cid, clip in key.items():
        lab = labels[cid]
        if lab["primitive"] not in PRIMITIVES + ("none", "unclear") or lab["moved"] not in MOVED:
            raise SystemExit(f"{folder / 'labels.csv'}: {cid}: moved {lab['moved']!r} / primitive "
                             f"{lab['primitive']!r}: moved is one of {', '.join(MOVED)}; primitive one of "
                             f"{', '.join(PRIMITIVES)}, none, unclear")
        v = judge.judge(_frames(clip), tuple(clip["object_px"]), split_config(clip["config"])[1])
        accepted = v.label == clip["primitive"] and v.agent_ok and v.object_ok
        rows.append({"id": cid, "config": clip["config"], "intended": clip["primitive"], "eye_moved": lab["moved"],
                     "eye_primitive": lab["primitive"], "eye_robot": lab["robot"], "eye": _eye(lab, clip["primitive"]),
                     "judged": v.label, "agent_ok": v.agent_ok, "object_ok": v.object_ok, "judge_accepts": accepted,
                     "t5": round(score := _t5_score(clip, backends), 2), "t5_accepts": score >= PASS})
    for config in sorted({r["config"] for r in rows}):
        rs = [r for r in rows if r["config"] == config]
        print(f"\n{config}: {len(rs)} clips; T5 {np.mean([r['t5'] for r in rs]):.1f}; primitive recognised (judge) "
              f"{100 * sum(r['judge_accepts'] for r in rs) / len(rs):.1f}")
        print(f"  | by eye | clips | T5 credits (≥ {PASS:g}) | judge accepts | judged label (object_ok) |")
        print("  |---|---:|---:|---:|---|")
        for kind in ("stays", "vanishes", "moves, primitive unclear", "unclear", "accepted", "another primitive"):
            ks = [r for r in rs if _kind(r) == kind]
            if ks:
                judged = Counter(f"{r['judged']} ({'y' if r['object_ok'] else 'n'})" for r in ks)
                print(f"  | {kind} | {len(ks)} | {sum(r['t5_accepts'] for r in ks)} | {sum(r['judge_accepts'] for r in ks)} | "
                      f"{', '.join(f'{k} {n}' for k, n in judged.most_common())} |")
        decided = [r for r in rs if r["eye"] != "undecided"]
        agree = sum(r["judge_accepts"] == (r["eye"] == "accept") for r in decided)
        t5_agree = sum(r["t5_accepts"] == (r["eye"] == "accept") for r in decided)
        if decided:
            print(f"  decided by eye: {len(decided)}; T5 agrees on {t5_agree} ({100 * t5_agree / len(decided):.1f} %), "
                  f"the judge's verdict on {agree} ({100 * agree / len(decided):.1f} %)")
        wrong = [f"{r['id']} ({r['intended']}, judged {r['judged']}, eye {_kind(r)})" for r in decided
                 if r["judge_accepts"] != (r["eye"] == "accept")]
        print(f"  disagreements: {', '.join(wrong) or 'none'}")
    if out:
        out.write_text(json.dumps({"judge": judge.version, "clips": rows}, indent=1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("sheets")
    s.add_argument("pairs", nargs="+", metavar="RELEASE:SUBMISSION")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--shuffle-seed", type=int, default=0)
    c = sub.add_parser("compare")
    c.add_argument("folder", type=Path)
    c.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    if args.cmd == "sheets":
        sheets(args.out, args.pairs, args.shuffle_seed)
    else:
        compare(args.folder, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
