"""Two source trees' scoring hot paths on the same submission videos, outputs asserted identical: `read_video` on
every video; the copy check (`InstanceReference.equals`, every role of every seed, one reference object per
instance as `wsp score` keeps it); for T2/T3 RMFA's windows (`windowed_reference` once per instance,
`score_windows` per seed, on flows computed once); for T4 the evaluated object's tracks (`object_tracks`); for T5
the `net` judge's logits on each video's 12 sampled frames. CPU seconds (least of `--repeat`, the two trees
alternating, one core), and the saving projected to the paper's counts.

    git worktree add /tmp/before e757a28
    .venv/bin/python benchmarks/hot_path_ab.py /tmp/before RELEASE SUBMISSION [RELEASE SUBMISSION ...]

The `before` tree's `wsp_eval/video.py`, `backends/judge_net.py`, `suites/reference.py`, `flow.py` and
`tracking.py` are imported from its files, this checkout's as installed. These paths' savings (a few per cent of
a scoring) are below the noise of `benchmarks/score_speed.py`'s end-to-end timings on a shared machine; a change
elsewhere in scoring is timed there.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).parent))
from score_speed import FULL_COUNTS  # noqa: E402

from wsp_eval import flow, tracking, video  # noqa: E402
from wsp_eval.backends import judge_net  # noqa: E402
from wsp_eval.backends.flow import DISFlow  # noqa: E402
from wsp_eval.backends.judge import JUDGE_FRAMES  # noqa: E402
from wsp_eval.release_format import split_config  # noqa: E402
from wsp_eval.score import COPY_MAD  # noqa: E402
from wsp_eval.submission import VIDEO_NAME, test_configs  # noqa: E402
from wsp_eval.suites import reference  # noqa: E402


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _cpu(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def measure(before: Path, release: Path, submission: Path, repeat: int) -> list[dict]:
    """Per config: instances, videos, and CPU seconds of each tree on them."""
    old_video = _module("before_video", before / "wsp_eval" / "video.py")
    old_judge = _module("before_judge_net", before / "wsp_eval" / "backends" / "judge_net.py")
    old_reference = _module("before_reference", before / "wsp_eval" / "suites" / "reference.py")
    old_flow = _module("before_flow", before / "wsp_eval" / "flow.py")
    old_tracking = _module("before_tracking", before / "wsp_eval" / "tracking.py")
    seeds = json.loads((submission / "submission.json").read_text())["seeds"]
    out = []
    for config in test_configs(release):
        suite, platform = split_config(config)
        videos = sorted((submission / config).glob("episode_*/seed*.mp4"))
        row = {"config": config, "instances": pq.read_metadata(release / config / "instances.parquet").num_rows,
               "videos": len(videos), "decode": [0.0, 0.0], "judge": [0.0, 0.0], "copy": [0.0, 0.0],
               "rmfa": [0.0, 0.0], "object": [0.0, 0.0]}
        judges = (old_judge.NetJudge(), judge_net.NetJudge()) if suite == "t5" else ()
        for path in videos:
            frames = video.read_video(path)[0]
            assert np.array_equal(old_video.read_video(path)[0], frames), path
            for k, read in enumerate((old_video.read_video, video.read_video)):
                row["decode"][k] += _cpu(lambda: read(path), repeat)
            if judges:
                clip = frames[np.linspace(0, len(frames) - 1, JUDGE_FRAMES).round().astype(int)]
                px = (120.0, 130.0)
                logits = [j.logits(clip, px, platform) for j in judges]
                assert np.array_equal(*logits), path
                for k, j in enumerate(judges):
                    row["judge"][k] += _cpu(lambda: j.logits(clip, px, platform), repeat)
        for instance in pq.read_table(release / config / "instances.parquet").to_pylist():
            decoded = [{role: video.read_video(submission / config / episode / VIDEO_NAME.format(seed=seed))[0]
                        for role, episode in zip(instance["roles"], instance["episode_ids"])} for seed in seeds]
            verdicts = []
            for k, module in enumerate((old_reference, reference)):
                def check(module=module):
                    ref = module.InstanceReference(release / config, instance)
                    verdicts.append([ref.equals(r, v, COPY_MAD) for videos in decoded for r, v in videos.items()])
                row["copy"][k] += _cpu(check, repeat)
            assert all(v == verdicts[0] for v in verdicts), (config, instance["instance_id"])
            if suite in ("t2", "t3"):
                _rmfa(row, (old_flow, flow), release / config, instance, [d["reference"] for d in decoded], repeat)
            if suite == "t4":
                _object(row, (old_tracking, tracking), release / config, instance, [d["reference"] for d in decoded],
                        repeat)
        out.append(row)
    return out


def _rmfa(row: dict, trees: tuple, config_dir: Path, instance: dict, videos: list[np.ndarray], repeat: int) -> None:
    """RMFA's window scoring of one instance's seeds by each tree, on flows computed once (DIS, as `wsp score`)."""
    ref = reference.InstanceReference(config_dir, instance)
    flows = []
    for frames in videos:
        duration = min(flow.clip_duration(ref.num_frames("reference"), ref.fps),
                       flow.clip_duration(len(frames), ref.fps))
        star = ref.reference_flows("reference", duration, DISFlow())
        needed = flow.active_flows(star.flows, star.masks)
        flows.append((star, flow.video_flows(frames, ref.fps, duration, DISFlow(), needed)))
    scores = []
    for k, tree in enumerate(trees):
        def windows(tree=tree):
            scores.append([tree.score_windows(f_hat, tree.windowed_reference(star.flows, star.masks))
                           for star, f_hat in flows])
        row["rmfa"][k] += _cpu(windows, repeat)
    assert all(s == scores[0] for s in scores), (row["config"], instance["instance_id"])


def _object(row: dict, trees: tuple, config_dir: Path, instance: dict, videos: list[np.ndarray], repeat: int
            ) -> None:
    """The evaluated object's tracks in each seed's video by each tree (T4's default tracker)."""
    mask0 = reference.InstanceReference(config_dir, instance).first_mask("reference")
    px = np.asarray(instance["object_pixel_256"], np.float64)
    tracks = []
    for k, tree in enumerate(trees):
        def track(tree=tree):
            found = [tree.object_tracks(tree.scoring_video(frames), px, mask0) for frames in videos]
            tracks.append([(t.positions, t.visible) for t in found])
        row["object"][k] += _cpu(track, repeat)
    for found in tracks[1:]:
        for (p, v), (p0, v0) in zip(found, tracks[0]):
            assert np.array_equal(p, p0) and np.array_equal(v, v0), (row["config"], instance["instance_id"])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before", type=Path, help="the other source tree (e.g. a git worktree of an earlier commit)")
    p.add_argument("pairs", type=Path, nargs="+", metavar="RELEASE SUBMISSION")
    p.add_argument("--repeat", type=int, default=5, help="timings per video and tree; the least counts (default 5)")
    args = p.parse_args(argv)
    if len(args.pairs) % 2:
        p.error("give RELEASE SUBMISSION pairs")
    cv2.setNumThreads(1)
    rows = [r for release, submission in zip(args.pairs[::2], args.pairs[1::2])
            for r in measure(args.before, release, submission, args.repeat)]
    print("CPU seconds over each config's videos (before → this checkout), outputs identical:")
    print("| config | videos | decode | copy check | RMFA windows | T4 object | judge | saved ms per instance |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    saved = 0.0
    for r in rows:
        per_instance = sum(r[k][0] - r[k][1] for k in ("decode", "copy", "rmfa", "object", "judge")) / r["instances"]
        suite, platform = split_config(r["config"])
        saved += per_instance * FULL_COUNTS[platform][suite]
        rmfa, obj, judge = (f"{r[k][0]:.3f} → {r[k][1]:.3f}" if r[k][0] else "—" for k in ("rmfa", "object", "judge"))
        print(f"| {r['config']} | {r['videos']} | {r['decode'][0]:.3f} → {r['decode'][1]:.3f} | "
              f"{r['copy'][0]:.3f} → {r['copy'][1]:.3f} | {rmfa} | {obj} | {judge} | "
              f"{1000 * per_instance:.1f} |")
    print(f"saved at the paper's counts: {saved:.0f} core-seconds, {saved / 120:.2f} min on 2 cores")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
