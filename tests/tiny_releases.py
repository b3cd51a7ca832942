"""The test suite's shared tiny releases: each is built once per test run and shared by every test module and
every pytest-xdist worker.

`shared_release(name, root)` builds release `name` into `root/<name>/worldsimprobe`, each config under a file lock
of its own, or returns it at once when other processes have built it (a fixture asking for a config still being
built waits for it). `scripts/test.sh` starts `python tests/tiny_releases.py ROOT` beside pytest, so the releases are built
while the tests that need none run (both cores stay busy), and hands ROOT to the fixtures through
`WSP_TEST_RELEASES`; a run without it (one test file, say) builds what it needs on first use, in the run's
temp folder shared by its xdist workers.

Rule of the repo: a new test uses these releases (or adds a config to one of them) unless it needs a build of
its own; a build of its own is for tests of building itself (sharding, resume, bad arguments).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from filelock import FileLock

from wsp_eval.release_format import DEFAULT_RELEASE_NAME  # the folder users load by name

DONE = ".built"  # marker beside the release: `.built.<config>` once that config is assembled

TINY = dict(suite="t1", platform="maniskill", count=4, tasks=("PickCube", "PushCube"), seed=0, max_attempts=8)
T2_TASKS = ("PickCube", "PushCube", "PullCube")
LIBERO_TASKS = ("libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket",
                "libero_object/pick_up_the_butter_and_place_it_in_the_basket")
LIBERO_SUITES = (("t1", 2), ("t2", 2), ("t3", 8), ("t4", 3), ("t5", 4), ("train", 2))
ALOHA_TASKS = ("transfer_cube", "lift_cube")  # a two-arm hand-over and a one-arm lift
ALOHA_SUITES = (("t1", 2), ("t2", 2), ("t3", 8), ("t4", 3), ("t5", 8), ("train", 2))
# T5 on ALOHA: the peg task first, where a push stays in sight of the top camera (on the cube tasks the hand hides
# the cube while it pushes, a reference T5 cannot score); drop and pull go to the cube tasks
ALOHA_T5_TASKS = ("peg_insertion", "transfer_cube", "lift_cube")

# name → the configs built into it, in order: (suite, platform, count, tasks, extra BuildConfig fields)
RELEASES: dict[str, tuple[tuple[str, str, int, tuple[str, ...], dict], ...]] = {
    # 4 T1 triplets over two tasks
    "t1": ((TINY["suite"], TINY["platform"], TINY["count"], TINY["tasks"],
            {"seed": TINY["seed"], "max_attempts": TINY["max_attempts"]}),),
    # T2 (3 replays over T2_TASKS), T3 (8, PickCube: one group of all eight sources), T4 (6, PickCube: two of
    # each kind) and T5 (8, PickCube: one per primitive)
    "suites": (("t2", "maniskill", 3, T2_TASKS, {}), ("t3", "maniskill", 8, ("PickCube",), {}),
               ("t4", "maniskill", 6, ("PickCube",), {}), ("t5", "maniskill", 8, ("PickCube",), {})),
    # LIBERO over a tall can and a flat box (push and tap need the low one): T1 (2 triplets), T2 (2 cross-task
    # replays), T3 (one group of all eight sources, on the first task), T4 (one per kind), T5 (one per
    # primitive), train (2)
    "libero": tuple((suite, "libero", count, LIBERO_TASKS, {}) for suite, count in LIBERO_SUITES),
    # ALOHA (two arms, 320x240) over ALOHA_TASKS: T1 (2 triplets), T2 (2 cross-task replays), T3 (one group of
    # all eight sources, on the hand-over), T4 (one per kind), T5 (one per primitive, over ALOHA_T5_TASKS), train (2)
    "aloha": tuple((suite, "aloha", count, ALOHA_T5_TASKS if suite == "t5" else ALOHA_TASKS,
                    {"max_attempts": 16} if suite == "t5" else {}) for suite, count in ALOHA_SUITES),
}


def build_config(out: Path, suite: str, platform: str, count: int, tasks: tuple[str, ...], **config) -> Path:
    """Build one config of a tiny real release into the release folder `out`."""
    from wsp_data.build import build
    from wsp_data.builders import BuildConfig

    result = build(BuildConfig(suite, platform, count, tuple(tasks), **config), out, progress=False)
    assert result.assembled or result.up_to_date, f"{suite}_{platform} did not assemble"
    if result.report and not result.up_to_date:  # the prebuild's log shows where its time goes
        r = result.report
        print(f"[tiny releases]   {r['config']}: {result.seconds:.0f} s, kept {r['kept']}/{r['requested']} of "
              f"{r['proposed']} proposals, {result.rendered_steps} rendered steps, dropped {r['dropped'] or 'none'}, "
              f"peak worker memory {result.peak_worker_rss_mb / 1024:.1f} GB",
              flush=True)
    return out


def shared_config(name: str, index: int, root: Path) -> Path:
    """Config `index` of release `name` under `root`, built by whichever process asks first; the others wait for
    it. Configs of one release build side by side (each has its lock; `wsp build` assembles one at a time)."""
    suite, platform, count, tasks, extra = RELEASES[name][index]
    folder = root / name
    folder.mkdir(parents=True, exist_ok=True)
    out, tag = folder / DEFAULT_RELEASE_NAME, f"{suite}_{platform}"
    with FileLock(str(folder / f".lock.{tag}")):
        if not (folder / f"{DONE}.{tag}").exists():
            build_config(out, suite, platform, count, tasks, **extra)
            (folder / f"{DONE}.{tag}").touch()
    return out


def shared_release(name: str, root: Path) -> Path:
    """Release `name` under `root` with every config of it built (`shared_config`)."""
    if name not in RELEASES:
        raise KeyError(f"no shared tiny release {name!r}; known: {', '.join(RELEASES)}")
    for index in range(len(RELEASES[name])):
        out = shared_config(name, index, root)
    return out


def offline_environment() -> None:
    """What every test process gets: Hugging Face caches in a temp folder, every hub access offline (nothing
    downloads), no progress bars."""
    os.environ.update(HF_HOME=tempfile.mkdtemp(prefix="wsp-hf-"), HF_HUB_OFFLINE="1", HF_DATASETS_OFFLINE="1",
                      TQDM_DISABLE="1")


PREBUILD_ORDER = ("libero", "t1", "suites", "aloha")  # the longest first; then in the order tests use them


def prebuild_jobs(names: list[str]) -> list[tuple[str, int]]:
    """Every config of `names` as one job, each release's configs in order, LIBERO's (the longest chain, which the
    last tests wait for) taking turns with the others': a worker that finishes the short releases joins LIBERO's
    chain instead of idling."""
    libero = [(n, k) for n in names if n == "libero" for k in range(len(RELEASES[n]))]
    others = [(n, k) for n in names if n != "libero" for k in range(len(RELEASES[n]))]
    turns = [job for pair in zip(libero, others) for job in pair]
    return turns + libero[len(turns) // 2:] + others[len(turns) // 2:]


def _build(name: str, index: int, root: Path) -> str:
    shared_config(name, index, root)
    return name


def main(argv: list[str] | None = None) -> int:
    offline_environment()
    p = argparse.ArgumentParser(description="Build the test suite's shared tiny releases into ROOT.")
    p.add_argument("root", type=Path)
    p.add_argument("--workers", type=int, default=2, help="configs built at once (default 2)")
    p.add_argument("names", nargs="*", default=list(PREBUILD_ORDER), help=f"default: {' '.join(PREBUILD_ORDER)}")
    args = p.parse_args(argv)
    unknown = set(args.names) - set(RELEASES)
    if unknown:
        p.error(f"unknown release(s) {', '.join(sorted(unknown))}; known: {', '.join(RELEASES)}")
    start = time.perf_counter()
    print(f"[tiny releases] building {', '.join(args.names)} into {args.root}, {args.workers} at a time", flush=True)
    jobs = prebuild_jobs(args.names)
    left = Counter(name for name, _ in jobs)
    with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as pool:
        for job in as_completed([pool.submit(_build, n, k, args.root) for n, k in jobs]):
            name = job.result()
            left[name] -= 1
            if not left[name]:
                print(f"[tiny releases] {name}: done after {time.perf_counter() - start:.0f} s", flush=True)
    print(f"[tiny releases] done in {time.perf_counter() - start:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
