"""A T5 judge against the simulator: agreement per primitive with its confusion matrix, and the rejections it
owes (spec §4.5; docs/validity.md, Primitive recognition), on a release built on test seeds the judge never saw.

    .venv/bin/python benchmarks/judge_validity.py RELEASE [RELEASE ...] [--judge net rules] [--out FILE.json]

Per platform (each `t5_<platform>` config; `t4_<platform>` configs add the still-object references):
- agreement: label = intended primitive; full: the reference scores 100 (label, agent_ok and object_ok); the
  (task, primitive) pairs where a reference does not (a weak pair shows here before it moves a primitive's rate);
- static: frame 0 repeated must score 0 against its intended primitive;
- approach (the reference before first contact) and T4 references (distractor, false contact, spatial
  proximity): the object never moves, so never accepted (label, agent_ok and object_ok) as push, pull, drag, tap, knock-over or drop;
- no_robot (the object moves, the robot held at its frame-0 pose): agent_ok must be False;
- frozen (the robot performs the primitive, the object held at its frame-0 pose, as a world model that ignores
  contact draws it): where it visibly differs from the reference (`judge_data.visibly_different`) it must score
  0 and never be accepted as a moving primitive; the rest (a rotate in place, mostly) are reported apart;
- erased (the frozen clip, but from first contact the object fades out where it stood, as world models often
  draw it: `judge_data.erased_object`): likewise;
- degraded references (JPEG q 40, Gaussian blur σ 1, 64×64 and back): full agreement, as for the originals;
- expert rollouts that are one primitive (`judge_data.EXPERT_PRIMITIVE`: ManiSkill's PushCube and PullCube source
  rollouts, a push and a pull done the expert's way, not T5's): how far the verdicts carry beyond T5's scripts.
Prints Markdown tables; `--out` keeps every verdict.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter, defaultdict
from pathlib import Path

import cv2
import numpy as np

from wsp_eval.backends import BackendSpec, make
from wsp_eval.backends.judge import PRIMITIVES
from wsp_eval.judge_data import T5_KINDS, t4_clips, t5_clips
from wsp_eval.release_format import ReleaseError, load_release, split_config

MOVING = ("push", "pull", "drag", "tap", "knock-over", "drop")
DEGRADE = {
    "jpeg q40": lambda f: cv2.imdecode(cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, 40])[1], cv2.IMREAD_UNCHANGED),
    "blur σ1": lambda f: cv2.GaussianBlur(f, (0, 0), 1.0),
    "64² and back": lambda f: cv2.resize(cv2.resize(f, (64, 64), interpolation=cv2.INTER_AREA), f.shape[1::-1]),
}


def judge_release(release: Path, judge) -> dict[str, list[dict]]:
    """platform → one record per judged clip."""
    meta = load_release(release)
    out: dict[str, list[dict]] = defaultdict(list)
    for config in sorted(meta["configs"]):
        suite, platform = split_config(config)
        clips = (t5_clips(release, config, (*T5_KINDS, "expert", "erased")) if suite == "t5"
                 else t4_clips(release, config) if suite == "t4" else [])
        for c in clips:
            frames = c.judge_frames()
            variants = {c.kind: frames}
            if c.kind == "reference":
                variants.update({f"reference, {k}": np.stack([f_(np.ascontiguousarray(f)) for f in frames])
                                 for k, f_ in DEGRADE.items()})
            for kind, fr in variants.items():
                t = time.perf_counter()
                v = judge.judge(fr, c.object_px, platform)
                out[platform].append({"kind": kind, "instance_id": c.instance_id, "task": c.task, "seed": c.seed,
                                      "intended": c.primitive, "expected": c.label, "expected_object": c.object,
                                      "clear": c.clear, "label": v.label,
                                      "agent_ok": v.agent_ok, "object_ok": v.object_ok,
                                      "evidence": {k: round(float(x), 4) for k, x in v.evidence.items()
                                                   if isinstance(x, (int, float))},
                                      "seconds": time.perf_counter() - t})
    return out


def _full(r: dict) -> bool:
    """The clip scores 100 against its intended primitive."""
    return bool(r["label"] == r["intended"] and r["agent_ok"] and r["object_ok"])


def _verdict(r: dict) -> str:
    """A reference's verdict in a few words: its label, and which boolean failed where the label is right."""
    if r["label"] != r["intended"]:
        return str(r["label"])
    return f"{r['label']} ({', '.join(k for k in ('agent_ok', 'object_ok') if not r[k])} false)"


def summarize(records: list[dict]) -> dict:
    refs = [r for r in records if r["kind"] == "reference"]
    s: dict = {"per_primitive": {}, "confusion": {}}
    for p in PRIMITIVES:
        mine = [r for r in refs if r["intended"] == p]
        if mine:
            s["per_primitive"][p] = {"n": len(mine), "agree": sum(r["label"] == p for r in mine),
                                     "full": sum(map(_full, mine))}
            s["confusion"][p] = dict(Counter(str(r["label"]) for r in mine))
    pairs: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in refs:
        pairs[(r["task"], r["intended"])].append(r)
    s["pairs"] = len(pairs)
    s["pairs_missed"] = {f"{task} · {p}": {"n": len(mine), "full": sum(map(_full, mine)),
                                          "labels": dict(Counter(map(_verdict, (r for r in mine if not _full(r)))))}
                         for (task, p), mine in sorted(pairs.items()) if not all(map(_full, mine))}
    s["agreement"] = sum(v["agree"] for v in s["per_primitive"].values()) / max(len(refs), 1)
    s["full"] = sum(v["full"] for v in s["per_primitive"].values()) / max(len(refs), 1)
    s["t5_score"] = float(np.mean([v["full"] / v["n"] for v in s["per_primitive"].values()])) if refs else None

    def rate(kind: str, bad) -> tuple[int, int]:
        mine = [r for r in records if r["kind"] == kind]
        return sum(bool(bad(r)) for r in mine), len(mine)

    s["static_nonzero"] = rate("static", _full)
    accepted_moving = lambda r: r["label"] in MOVING and r["agent_ok"] and r["object_ok"]  # noqa: E731
    s["approach_accepted_moving"] = rate("approach", accepted_moving)
    s["t4_accepted_moving"] = rate("t4", accepted_moving)
    for kind in sorted({r["intended"] for r in records if r["kind"] == "t4"}):
        mine = [r for r in records if r["kind"] == "t4" and r["intended"] == kind]
        s[f"t4 {kind} accepted_moving"] = (sum(map(accepted_moving, mine)), len(mine))
    s["no_robot_agent_ok"] = rate("no_robot", lambda r: r["agent_ok"])
    for kind in ("frozen", "erased"):
        visible = [r for r in records if r["kind"] == kind and r["expected_object"] is False]
        unseen = [r for r in records if r["kind"] == kind and r["expected_object"] is None]
        s[f"{kind}_scores"] = (sum(map(_full, visible)), len(visible))
        s[f"{kind}_accepted_moving"] = (sum(map(accepted_moving, visible)), len(visible))
        s[f"{kind}_unseen_scores"] = (sum(map(_full, unseen)), len(unseen))
        s[f"{kind}_unseen_primitives"] = dict(Counter(r["intended"] for r in unseen))
    clear = [r for r in records if r["kind"] == "erased" and r["expected_object"] is False and r.get("clear")]
    s["erased_clear_scores"] = (sum(map(_full, clear)), len(clear))
    for k in DEGRADE:
        s[f"full, {k}"] = rate(f"reference, {k}", _full)
    s["expert_full"] = rate("expert", lambda r: r["label"] == r["expected"] and r["agent_ok"] and r["object_ok"])
    s["ms_per_clip"] = 1000 * float(np.median([r["seconds"] for r in records]))
    return s


def markdown(judge_name: str, platform: str, s: dict) -> str:
    lines = [f"### {judge_name} on {platform}", "", "| primitive | n | label agrees | scores 100 |", "|---|---:|---:|---:|"]
    for p, v in s["per_primitive"].items():
        lines.append(f"| {p} | {v['n']} | {v['agree']} | {v['full']} |")
    oracle = "–" if s["t5_score"] is None else f"{s['t5_score'] * 100:.1f}"  # a release of T4 configs only: none
    lines.append(f"| **all** | {sum(v['n'] for v in s['per_primitive'].values())} | {100 * s['agreement']:.1f} % | "
                 f"{100 * s['full']:.1f} % (T5 score of the oracle: {oracle}) |")
    labels = [p for p in PRIMITIVES if p in s["confusion"]]
    cols = labels + sorted({k for row in s["confusion"].values() for k in row} - set(labels))
    lines += ["", "Confusion (rows: intended; columns: the judge's label)", "",
              "| intended | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
    for p in labels:
        lines.append(f"| {p} | " + " | ".join(str(s["confusion"][p].get(c, "")) for c in cols) + " |")
    if s["pairs"]:
        lines += ["", f"(task, primitive) pairs with a reference that does not score 100: {len(s['pairs_missed'])} of "
                  f"{s['pairs']}" + (":" if s["pairs_missed"] else "")]
    if s["pairs_missed"]:
        lines.append("")
        lines += ["| task · primitive | n | scores 100 | the others' verdicts |", "|---|---:|---:|---|"]
        lines += [f"| {k} | {v['n']} | {v['full']} | {', '.join(f'{lab} {c}' for lab, c in v['labels'].items())} |"
                  for k, v in s["pairs_missed"].items()]
    lines += ["", "| check | bad / n | goal |", "|---|---:|---|",
              f"| static (frame 0 repeated) scores > 0 | {'%d / %d' % s['static_nonzero']} | 0 |",
              f"| approach before contact accepted as a moving primitive | {'%d / %d' % s['approach_accepted_moving']} | 0 |",
              f"| T4 still-object reference accepted as a moving primitive | {'%d / %d' % s['t4_accepted_moving']} | 0 |",
              *(f"| … T4 {k.split()[1]} | {'%d / %d' % v} | 0 |" for k, v in s.items() if k.startswith("t4 ")),
              f"| object moves, robot held still: agent_ok | {'%d / %d' % s['no_robot_agent_ok']} | 0 |",
              f"| robot does the primitive, object held still (visibly unlike the reference): scores > 0 | "
              f"{'%d / %d' % s['frozen_scores']} | 0 |",
              f"| … accepted as any moving primitive | {'%d / %d' % s['frozen_accepted_moving']} | 0 |",
              f"| … held still but not visibly unlike the reference ("
              f"{', '.join(f'{k} {v}' for k, v in s['frozen_unseen_primitives'].items()) or 'none'}): scores > 0 | "
              f"{'%d / %d' % s['frozen_unseen_scores']} | (no target) |",
              f"| robot does the primitive, object fades out where it stood (visibly unlike the reference): scores > 0 | "
              f"{'%d / %d' % s['erased_scores']} | 0 |",
              f"| … accepted as any moving primitive | {'%d / %d' % s['erased_accepted_moving']} | 0 |",
              f"| … of them, the reference's object visibly away from where it stood: scores > 0 | "
              f"{'%d / %d' % s['erased_clear_scores']} | 0 |",
              f"| … not visibly unlike the reference ("
              f"{', '.join(f'{k} {v}' for k, v in s['erased_unseen_primitives'].items()) or 'none'}): scores > 0 | "
              f"{'%d / %d' % s['erased_unseen_scores']} | (no target) |"]
    for k in DEGRADE:
        good, n = s[f"full, {k}"]
        lines.append(f"| reference {k}: scores 100 | {good} / {n} (good) | as the originals |")
    if s["expert_full"][1]:
        lines.append(f"| task expert's rollout of one primitive (PushCube push, PullCube pull): scores 100 | "
                     f"{'%d / %d' % s['expert_full']} (good) | all |")
    lines.append(f"\nMedian time per clip: {s['ms_per_clip']:.1f} ms.")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("releases", type=Path, nargs="+")
    ap.add_argument("--judge", nargs="+", default=["net"])
    ap.add_argument("--checkpoint", type=Path, help="the `net` judge's weights (default: the shipped ones)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    for release in args.releases:
        try:
            load_release(release)
        except ReleaseError as e:
            ap.error(str(e))
    cv2.setNumThreads(1)
    result = {}
    for name in args.judge:
        judge = make(BackendSpec(judge=name, judge_checkpoint=str(args.checkpoint) if args.checkpoint else None),
                     ("judge",)).judge
        records: dict[str, list[dict]] = defaultdict(list)
        for release in args.releases:
            for platform, recs in judge_release(release, judge).items():
                records[platform] += recs
        result[name] = {"version": judge.version, "platforms": {}}
        for platform, recs in sorted(records.items()):
            s = summarize(recs)
            result[name]["platforms"][platform] = {"summary": s, "records": recs}
            print(markdown(f"{name} {judge.version}", platform, s) + "\n", flush=True)
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
