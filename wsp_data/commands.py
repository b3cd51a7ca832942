"""The build side's `wsp` commands: `build`, `sources` and `teleop`.

Each is a `wsp_eval.command.Command` that `wsp` finds through the `worldsimprobe.commands` entry-point group
(pyproject.toml) and loads only when it is asked for; what a command runs (builders, simulators) is imported when
it runs, so in the scoring-only install it stops with one line naming the extra to install.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from wsp_data.platforms import KITS
from wsp_data.schema import DEFAULT_RELEASE_NAME, PRIVATE_RANGE, SEED_BASE, SUITES
from wsp_eval.command import CliError, Command, positive


def shard(text: str) -> tuple[int, int]:
    """An argparse type: `i/n`, shard i of n."""
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected i/n (e.g. 0/4), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise argparse.ArgumentTypeError(f"expected 0 <= i < n, got {text!r}")
    return i, n


def build_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--platform", choices=KITS, default="maniskill")
    p.add_argument("--suite", choices=SUITES, required=True)
    p.add_argument("--count", type=positive,
                   help="instances to build (default: the paper's count; train: 100 episodes per task)")
    p.add_argument("--out", type=Path, default=Path(DEFAULT_RELEASE_NAME), help="release folder (default: ./worldsimprobe)")
    p.add_argument("--tasks", nargs="+", help="restrict to these tasks (default: all solved benchmark tasks)")
    p.add_argument("--primitives", nargs="+", default=[], metavar="PRIMITIVE",
                   help="T5 only: restrict the slots to these scripted primitives (default: all the platform's, "
                        "balanced); for judge data rich in one primitive")
    p.add_argument("--seed", type=int, default=0,
                   help="build seed (default 0): seeds the proposals' random choices (T1's perturbation, T2's donor, "
                        "T4's intervention); it chooses the scenes only with --seed-range private")
    p.add_argument("--seed-range", choices=[*sorted(SEED_BASE), PRIVATE_RANGE], default="",
                   help="draw scene seeds from this suite's range instead of the config's own (e.g. `train` for "
                        "judge-training data that never shares a scene with a test suite), or from the private "
                        "range: scenes keyed by --seed that no public release holds (private test sets, fresh checks)")
    p.add_argument("--max-attempts", type=positive, default=8, help="proposals per instance slot before giving up")
    p.add_argument("--shard", type=shard, default=(0, 1), help="build only slots k with k %% n == i (i/n)")
    p.add_argument("--workers", type=positive, default=1, help="worker processes (each holds its own simulators)")
    p.add_argument("--executor", choices=("local", "ray"), default="local",
                   help="local (this machine's processes, default) or ray (slots as Ray tasks on a cluster)")
    p.add_argument("--address", help="with --executor ray: the cluster to join (`auto`, or host:port); default: "
                                     "a local Ray instance with --workers CPUs")
    p.add_argument("--restart", action="store_true", help="discard a staged unfinished build of this config")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def sources_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--platform", choices=KITS, default="maniskill")
    p.add_argument("--seeds", type=positive, default=20)
    p.add_argument("--tasks", nargs="+")
    p.add_argument("--out", type=Path, help="also write the Markdown table here")


def teleop_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", default="PickCube", help="ManiSkill task (default PickCube)")
    p.add_argument("--seed", type=int, default=0, help="scene seed of the episode (default 0)")
    p.add_argument("--operator", required=True, help="operator name recorded in the provenance")
    p.add_argument("--out", type=Path, default=Path("teleop"), help="folder for saved trajectories (default ./teleop)")
    p.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (default 8765; 0 = any free port)")
    p.add_argument("--step", type=float, default=0.01, help="TCP translation per command, m (default 0.01)")
    p.add_argument("--yaw-step", type=float, default=0.1, help="TCP yaw per command, rad (default 0.1)")


def cmd_build(args) -> int:
    from wsp_data.build import BuildError, build, format_report
    from wsp_data.builders import BuildConfig, builder_class
    from wsp_data.builders.train import EPISODES_PER_TASK
    from wsp_data.platforms import kit

    try:
        builder_class(args.suite)
        known = kit(args.platform).tasks()
    except KeyError as e:
        raise CliError(e.args[0]) from None
    except ModuleNotFoundError:
        raise
    except ImportError as e:
        raise CliError(f"the {args.platform} platform is not installed ({e}); run `make setup`") from None
    tasks = tuple(args.tasks or known)
    unknown = [t for t in tasks if t not in known]
    if unknown:
        listed = "\n  ".join(known)
        raise CliError(f"unknown task(s) {', '.join(unknown)}; the {len(known)} known {args.platform} tasks:\n  {listed}")
    if args.seed and args.seed_range != PRIVATE_RANGE:
        print(f"note: --seed {args.seed} changes the proposals' random choices, not the scenes: slot k, attempt a "
              f"still draws scene seed {SEED_BASE[args.seed_range or args.suite]:,} + 100·k + a; for scenes of this "
              f"seed's own, add --seed-range private", file=sys.stderr)
    try:
        count = args.count or kit(args.platform).default_counts.get(args.suite) or EPISODES_PER_TASK * len(tasks)
        config = BuildConfig(args.suite, args.platform, count, tasks, args.seed, args.max_attempts, args.seed_range,
                             tuple(args.primitives))
        result = build(config, args.out, shard=args.shard, workers=args.workers, restart=args.restart,
                       progress=not args.quiet, executor=args.executor, address=args.address)
    except (BuildError, ValueError) as e:
        raise CliError(str(e)) from None
    if result.up_to_date:
        print(f"{config.name} in {result.release} is up to date (same build config); nothing to do")
        return 0
    per = result.seconds / max(1, result.rendered_steps) * 1000
    memory = (f"; peak memory of a build worker {result.peak_worker_rss_mb / 1024:.1f} GB"
              if result.peak_worker_rss_mb else "")
    assembly = (f"; the config written in {result.assembly_seconds:.1f} s "
                f"({result.assembly_seconds / max(result.seconds, 1e-9):.0%} of this run)" if result.assembled else "")
    print(f"decided {result.decided_now} slot(s) in {result.seconds:.1f} s; {result.rendered_steps} rendered steps "
          f"({per:.0f} ms per rendered step, all costs included){memory}{assembly}")
    if result.assembled:
        print(format_report(result.report))
        from wsp_data.schema import BUILD_REPORT

        print(f"report: {result.release / config.name / BUILD_REPORT}; library output: {result.log}; "
              f"the release: wsp info {result.release}")
    else:
        print(f"{result.remaining} slot(s) of {config.name} are not decided yet (other shards); run the remaining "
              f"shards, then any `wsp build` with the same arguments assembles the config")
    return 0

def cmd_sources(args) -> int:
    from wsp_data.sources import survey

    argv = ["--platform", args.platform, "--seeds", str(args.seeds)] + (["--tasks", *args.tasks] if args.tasks else [])
    argv += ["--out", str(args.out)] if args.out else []
    return survey.main(argv) or 0

def cmd_teleop(args) -> int:
    from wsp_data.platforms.maniskill import teleop

    return teleop.run(args)


BUILD = Command("build (or resume) one suite×platform config of a release", build_arguments, cmd_build)
SOURCES = Command("scripted expert success rate per task", sources_arguments, cmd_sources)
TELEOP = Command("serve the browser teleoperation page; record operator source trajectories", teleop_arguments, cmd_teleop)
