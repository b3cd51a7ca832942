"""What checking a release against `release.json` costs (`wsp_eval.integrity`): the first verification, which
hashes every file, against a later one, which finds every file in the memo by (size, mtime, inode) and hashes
nothing, side by side in one run, on the release given (default `make release`'s `worldsimprobe`).

Each round copies nothing: the memo is removed before a first verification and kept for a later one; the file
contents come from the page cache after the first round, so the first verification's figure is hashing speed,
not disk speed (a cold disk adds its read time).

    .venv/bin/python benchmarks/verify_speed.py worldsimprobe --rounds 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from wsp_eval import integrity
from wsp_eval.release_format import RELEASE_JSON


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("release", type=Path, nargs="?", default=Path("worldsimprobe"))
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args(argv)
    files = json.loads((args.release / RELEASE_JSON).read_text())["files"]
    configs = sorted({f.split("/", 1)[0] for f in files if "/" in f})
    checked = [f for f in files if f.split("/", 1)[0] in configs]
    size = sum((args.release / f).stat().st_size for f in checked)
    memo = integrity.memo_path(args.release)  # removed before each first verification
    first, later = [], []
    for _ in range(args.rounds):
        memo.unlink(missing_ok=True)
        t = time.perf_counter()
        integrity.verify(args.release, configs)
        first.append(time.perf_counter() - t)
        t = time.perf_counter()
        integrity.verify(args.release, configs)
        later.append(time.perf_counter() - t)
    a, b = statistics.median(first), statistics.median(later)
    print(f"{args.release}: {len(configs)} configs, {len(checked)} files, {size / 1e6:.1f} MB "
          f"(median of {args.rounds} rounds)")
    print(f"  first verification (hashes every file): {a:.2f} s ({size / 1e6 / a:.0f} MB/s)")
    print(f"  later verification (memo, no hashing):  {b * 1000:.1f} ms ({b / len(checked) * 1e6:.0f} µs per file)")
    print(f"  ratio first / later: {a / b:.0f}×")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
