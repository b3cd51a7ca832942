"""Final assembly time against size: is `assemble` linear in episodes, and what do workers buy?

Takes one staged config (a `.wsp-staging/<config>` folder, left untouched) and assembles copies of it holding
the first N kept episodes, for each N asked, into fresh folders; the copies' slots link to the staged rollouts
and cycle through the staged kept instances when N needs more than were staged (the assembly cost of an
instance does not depend on its slot). Prints wall and CPU seconds (all threads of this process) per episode at
each size: flat means linear; CPU time is the steadier of the two on a shared machine.

    .venv/bin/python benchmarks/assembly_speed.py --stage 16 --platform aloha --suite t4 DIR   # decide 16 slots
    .venv/bin/python benchmarks/assembly_speed.py DIR/.wsp-staging/t4_aloha --episodes 32 128 384 --workers 2
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from wsp_data.build import assemble, decide_slots, open_staging, prepare_output
from wsp_data.builders import BuildConfig
from wsp_data.platforms import kit
from wsp_data.schema import STAGING_DIR
from wsp_data.staging import CONFIG_JSON, SLOT_JSON, Staging
from wsp_eval.console import library_output_to


def stage(out: Path, platform: str, suite: str, count: int) -> Path:
    """Decide `count` slots of the config into `out`'s staging with one worker, without assembling."""
    config = BuildConfig(suite, platform, count, tuple(kit(platform).tasks()))
    staging = open_staging(prepare_output(out), config, restart=False)
    for _ in decide_slots(config, staging, [k for k in range(count) if not staging.is_decided(k)], workers=1):
        pass
    return staging.root


def staged_copy(source: Staging, episodes: int, root: Path) -> tuple[BuildConfig, Staging, int]:
    """A staging under `root` whose slots are the first kept instances (cycled) holding ≥ `episodes` episodes."""
    config = BuildConfig.from_json(json.loads((source.root / CONFIG_JSON).read_text()))
    kept = [r for r in (source.read_slot(k) for k in range(config.count) if source.is_decided(k)) if r.kept]
    copy = Staging(root / config.name)
    copy.root.mkdir(parents=True)
    slot = total = 0
    while total < episodes:
        record = kept[slot % len(kept)]
        (copy.slot_dir(slot)).mkdir()
        for role in record.roles:
            (copy.slot_dir(slot) / f"{role}.npz").symlink_to(source.slot_dir(record.slot) / f"{role}.npz")
        text = json.dumps({**vars(record), "slot": slot}, sort_keys=True)
        (copy.slot_dir(slot) / SLOT_JSON).write_text(text)
        slot, total = slot + 1, total + len(record.roles)
    config = replace(config, count=slot)
    (copy.root / CONFIG_JSON).write_text(json.dumps(config.to_json(), sort_keys=True))
    return config, copy, total


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("staging", type=Path, help="a .wsp-staging/<config> folder (with --stage: the release folder)")
    p.add_argument("--episodes", type=int, nargs="+", default=[32, 128, 384])
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--stage", type=int, metavar="COUNT", help="first decide COUNT slots into STAGING/.wsp-staging")
    p.add_argument("--platform", default="aloha")
    p.add_argument("--suite", default="t4")
    p.add_argument("--scratch", type=Path, help="where the copies are assembled (default: the system temp folder)")
    args = p.parse_args()
    source = stage(args.staging, args.platform, args.suite, args.stage) if args.stage else args.staging
    import lerobot.datasets.lerobot_dataset  # noqa: F401 - its import (seconds) is not the assembly's
    rows = []
    for n in args.episodes:
        with tempfile.TemporaryDirectory(prefix="wsp-assembly-", dir=args.scratch) as tmp:
            out = Path(tmp) / "worldsimprobe"
            config, copy, episodes = staged_copy(Staging(source), n, out / STAGING_DIR)
            start, cpu = time.perf_counter(), time.process_time()
            with library_output_to(Path(tmp) / "assembly.log"):  # x264's and LeRobot's output
                assemble(config, prepare_output(out), copy, workers=args.workers)
            seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        rows.append((episodes, seconds, cpu))
        print(f"{episodes} episodes: {seconds:.1f} s ({seconds / episodes:.3f} s/episode), CPU {cpu:.1f} s", flush=True)
    print(f"\n{config.name}, workers {args.workers}\n| episodes | wall s | wall s / episode | CPU s / episode |")
    print("|---|---|---|---|")
    for episodes, seconds, cpu in rows:
        print(f"| {episodes} | {seconds:.1f} | {seconds / episodes:.3f} | {cpu / episodes:.3f} |")


if __name__ == "__main__":
    main()
