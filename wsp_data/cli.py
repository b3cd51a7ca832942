"""`wsp`: the WorldSimProbe command line.

    wsp build --platform maniskill --suite t1 --count N --out DIR   build (or resume) a config of a release
    wsp info DIR                                                     what a release holds
    wsp sources [--seeds N]                                          scripted expert success per task
    wsp validate SUBMISSION --release DIR                            check a submission, score nothing
    wsp baseline NAME --release DIR --out SUBMISSION                 write a calibration-baseline submission
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from wsp_data.schema import DEFAULT_RELEASE_NAME, PLATFORMS, SUITES

PAPER_COUNTS = {"t1": 1000, "t2": 1500, "t3": 750, "t4": 1000, "t5": 2360}  # ManiSkill, paper Table S3


class CliError(Exception):
    pass


def _shard(text: str) -> tuple[int, int]:
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected i/n (e.g. 0/4), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise argparse.ArgumentTypeError(f"expected 0 <= i < n, got {text!r}")
    return i, n


def _positive(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {v}")
    return v


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wsp", description="WorldSimProbe: build and inspect benchmark releases.")
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build", help="build (or resume) one suite×platform config of a release")
    b.add_argument("--platform", choices=PLATFORMS, default="maniskill")
    b.add_argument("--suite", choices=SUITES, required=True)
    b.add_argument("--count", type=_positive,
                   help="instances to build (default: the paper's count; train: 100 episodes per task)")
    b.add_argument("--out", type=Path, default=Path(DEFAULT_RELEASE_NAME), help="release folder (default: ./worldsimprobe)")
    b.add_argument("--tasks", nargs="+", help="restrict to these tasks (default: all solved benchmark tasks)")
    b.add_argument("--seed", type=int, default=0, help="build seed (default 0)")
    b.add_argument("--max-attempts", type=_positive, default=8, help="proposals per instance slot before giving up")
    b.add_argument("--shard", type=_shard, default=(0, 1), help="build only slots k with k %% n == i (i/n)")
    b.add_argument("--workers", type=_positive, default=1, help="worker processes (each holds its own simulators)")
    b.add_argument("--restart", action="store_true", help="discard a staged unfinished build of this config")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    i = sub.add_parser("info", help="summarise a release folder")
    i.add_argument("release", type=Path)
    s = sub.add_parser("sources", help="scripted expert success rate per task")
    s.add_argument("--seeds", type=_positive, default=20)
    s.add_argument("--tasks", nargs="+")
    s.add_argument("--out", type=Path, help="also write the Markdown table here")
    v = sub.add_parser("validate", help="check a submission against a release without scoring it")
    v.add_argument("submission", type=Path)
    v.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    bl = sub.add_parser("baseline", help="write a calibration-baseline submission (oracle, static)")
    bl.add_argument("name")
    bl.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    bl.add_argument("--out", type=Path, required=True)
    return p


def cmd_build(args) -> int:
    from wsp_data.build import BuildError, build, format_report
    from wsp_data.builders import BuildConfig, builder_class
    from wsp_data.builders.train import EPISODES_PER_TASK
    from wsp_data.sources.experts import TASKS

    try:
        builder_class(args.suite)
    except KeyError as e:
        raise CliError(e.args[0]) from None
    tasks = tuple(args.tasks or TASKS)
    unknown = [t for t in tasks if t not in TASKS]
    if unknown:
        raise CliError(f"unknown task(s) {', '.join(unknown)}; known: {', '.join(TASKS)}")
    try:
        count = args.count or PAPER_COUNTS.get(args.suite) or EPISODES_PER_TASK * len(tasks)
        config = BuildConfig(args.suite, args.platform, count, tasks, args.seed, args.max_attempts)
        result = build(config, args.out, shard=args.shard, workers=args.workers, restart=args.restart,
                       progress=not args.quiet)
    except (BuildError, ValueError) as e:
        raise CliError(str(e)) from None
    if result.up_to_date:
        print(f"{config.name} in {result.release} is up to date (same build config); nothing to do")
        return 0
    per = result.seconds / max(1, result.rendered_steps) * 1000
    print(f"decided {result.decided_now} slot(s) in {result.seconds:.1f} s; {result.rendered_steps} rendered steps "
          f"({per:.0f} ms per rendered step, all costs included)")
    if result.assembled:
        print(format_report(result.report))
        from wsp_data.release import describe

        print()
        print(describe(result.release))
    else:
        print(f"{result.remaining} slot(s) of {config.name} are not decided yet (other shards); run the remaining "
              f"shards, then any `wsp build` with the same arguments assembles the config")
    return 0


def cmd_info(args) -> int:
    from wsp_data.release import ReleaseError, describe

    try:
        print(describe(args.release))
    except ReleaseError as e:
        raise CliError(str(e)) from None
    return 0


def cmd_sources(args) -> int:
    from wsp_data.sources import survey

    argv = ["--seeds", str(args.seeds)] + (["--tasks", *args.tasks] if args.tasks else [])
    argv += ["--out", str(args.out)] if args.out else []
    return survey.main(argv) or 0


def _release_or_error(path: Path) -> Path:
    from wsp_data.release import ReleaseError, load_release

    try:
        load_release(path)
    except ReleaseError as e:
        raise CliError(str(e)) from None
    return path


def cmd_validate(args) -> int:
    from wsp_eval.submission import validate

    problems = validate(args.submission, _release_or_error(args.release))
    for p in problems:
        print(f"{args.submission}/{p}")
    print(f"{len(problems)} problem(s) in {args.submission}" if problems else f"{args.submission}: valid")
    return 1 if problems else 0


def cmd_baseline(args) -> int:
    from wsp_eval.baselines import write_baseline

    try:
        n = write_baseline(args.name, _release_or_error(args.release), args.out)
    except KeyError as e:
        raise CliError(e.args[0]) from None
    print(f"wrote {n} videos of baseline {args.name!r} to {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        commands = {"build": cmd_build, "info": cmd_info, "sources": cmd_sources, "validate": cmd_validate,
                    "baseline": cmd_baseline}
        return commands[args.command](args)
    except CliError as e:
        print(f"wsp: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("wsp: interrupted; staged instances are kept, re-run the same command to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
