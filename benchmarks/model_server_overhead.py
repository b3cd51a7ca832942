"""What the model server adds (`wsp-serve` and `wsp generate --model ws://…`, docs/guides/model-server.md): the
same numpy model called in process and behind a server on the same machine (a `python -m wsp_serve` process on
127.0.0.1), side by side in one run.

- per video: one request of a 100-frame 128×128 video (8-D actions), the model call in process against the whole
  round trip (encode, send, the server's call and checks, the reply, decode, the client's checks), median of
  `--rounds`;
- per release config: `wsp generate` of one config of `release` (seed 0), in process against served, wall time.

Both for a fast model (the first frame shifted by the summed first action, a few ms) and for the same model
sleeping `--sleep` seconds per video (a stand-in for a generative model's compute). Prints the ratios.

    .venv/bin/python benchmarks/model_server_overhead.py /path/to/release --rounds 5
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wsp_eval.generate import generate
from wsp_eval.model_client import ModelServerClient, generate_remote
from wsp_eval.submission import test_configs
from wsp_serve.callables import Request
from wsp_serve.protocol import Episode

ROOT = Path(__file__).resolve().parent.parent
SLEEP = 1.0  # seconds per video of the slow model; the server reads it from here too


def fast(first_frame: np.ndarray, actions: np.ndarray, fps: float, seed: int) -> np.ndarray:
    """Frame t: the first frame rolled sideways by round(20 · cumsum(action[:, 0])[t]) + seed pixels."""
    shifts = np.rint(20.0 * np.cumsum(actions[:, 0])).astype(int) + seed
    return np.stack([np.roll(first_frame, s, axis=1) for s in shifts])


def slow(first_frame: np.ndarray, actions: np.ndarray, fps: float, seed: int) -> np.ndarray:
    """`fast` after sleeping SLEEP seconds."""
    time.sleep(SLEEP)
    return fast(first_frame, actions, fps, seed)


class Server:
    """`python -m wsp_serve benchmarks.model_server_overhead:NAME --port 0` from the repository root."""

    def __init__(self, name: str):
        self.process = subprocess.Popen([sys.executable, "-m", "wsp_serve", f"benchmarks.model_server_overhead:{name}",
                                         "--port", "0"], cwd=ROOT, stderr=subprocess.PIPE, text=True)
        line = self.process.stderr.readline()
        match = re.search(r"on (ws://\S+);", line)
        if not match:
            raise SystemExit(f"the server did not start: {line}{self.process.stderr.read()}")
        self.url = match.group(1)

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=30)


def per_video(model: Callable, url: str, rounds: int) -> tuple[float, float]:
    """Median seconds of one 100-frame video: in process, and through the server at `url`."""
    rng = np.random.default_rng(0)
    request = Request(rng.integers(0, 256, (128, 128, 3), dtype=np.uint8),
                      rng.normal(0, 0.01, (100, 8)).astype(np.float32), 20.0, 0)
    client = ModelServerClient(url)
    client.connect()
    local, served = [], []
    for _ in range(rounds):
        t = time.perf_counter()
        model(*request)
        local.append(time.perf_counter() - t)
        t = time.perf_counter()
        client.generate("bench", [Episode("bench/episode_000000/seed0", request)])
        served.append(time.perf_counter() - t)
    client.close()
    return statistics.median(local), statistics.median(served)


def per_config(model: Callable, url: str, release: Path, config: str, rounds: int) -> tuple[float, float, int]:
    """Median wall seconds of `wsp generate` of `config` (seed 0) in process and served, alternating, after one
    unmeasured in-process run (the reference videos then come from the page cache), and the videos written."""
    def run(served: bool, out: Path) -> tuple[float, int]:
        t = time.perf_counter()
        if served:
            result, _ = generate_remote(url, release, out, seeds=(0,), configs=[config], name="m", progress=False)
        else:
            result = generate(model, release, out, seeds=(0,), configs=[config], name="m", progress=False)
        return time.perf_counter() - t, result.written

    with tempfile.TemporaryDirectory() as tmp:
        generate(fast, release, Path(tmp) / "warm", seeds=(0,), configs=[config], name="m", progress=False)
        local, served = [], []
        for i in range(rounds):
            local.append(run(False, Path(tmp) / f"local{i}"))
            served.append(run(True, Path(tmp) / f"served{i}"))
    return statistics.median(t for t, _ in local), statistics.median(t for t, _ in served), local[0][1]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("release", type=Path, nargs="?", default=Path("worldsimprobe"))
    p.add_argument("--config", help="config to generate (default: the release's first scored one)")
    p.add_argument("--rounds", type=int, default=5, help="rounds of the slow model per video (the fast model runs "
                                                         "4× as many) and of the fast model per config (median)")
    args = p.parse_args(argv)
    config = args.config or test_configs(args.release)[0]
    for name, model, rounds in (("fast", fast, args.rounds * 4), ("slow", slow, args.rounds)):
        server = Server(name)
        try:
            local, served = per_video(model, server.url, rounds)
            print(f"{name} model, one 100-frame 128×128 video (median of {rounds}): in process {local * 1e3:.1f} ms, "
                  f"served {served * 1e3:.1f} ms: +{(served - local) * 1e3:.1f} ms ({(served / local - 1) * 100:+.1f} %)")
            n = args.rounds if name == "fast" else 1
            local, served, videos = per_config(model, server.url, args.release, config, n)
            print(f"{name} model, wsp generate of {config} ({videos} videos, seed 0, median of {n}): in process "
                  f"{local:.2f} s, served {served:.2f} s ({(served / local - 1) * 100:+.1f} %)")
        finally:
            server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
