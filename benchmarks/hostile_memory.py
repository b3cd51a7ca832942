"""Peak memory (ru_maxrss) of decoding hostile uploads, each case in a fresh subprocess, for the code of this
working tree and, with `--before REV`, for the code of a git revision (e.g. the commit before bounded decoding):
a 1920×1080 many-frame mp4, read alone and validated in place of one video of a real submission, and a
512×512 (allowed) raw h264 stream named .mp4 whose header gives no frame count, validated.

    .venv/bin/python benchmarks/hostile_memory.py RELEASE SUBMISSION [--frames 200] [--long 2900] [--before REV]

SUBMISSION must be valid for RELEASE (e.g. `wsp baseline oracle`); it is copied, never changed. The unbounded
"before" decoder holds every frame twice (a list, then the stacked array: 6.2 MB per 1080p frame, 0.8 MB per
512² frame, each), so `--frames` stays modest by default; each subprocess runs under an 8 GiB address-space
cap (a case over it reports the MemoryError).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import av
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CAP = 8 << 30
CASE = """
import resource, sys
from pathlib import Path
kind, path, release = sys.argv[1:4]
try:
    if kind == "read":
        from wsp_eval.video import read_video
        out = "decoded %s frames" % (read_video(path)[0].shape,)
    elif kind == "validate":
        from wsp_eval.submission import validate
        out = "; ".join(map(str, validate(Path(path), Path(release)))) or "valid"
    else:
        import numpy, av
        out = "imports only"
except BaseException as e:
    out = "%s: %s" % (type(e).__name__, str(e)[:160])
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024, out)
"""


def write_hostile(path: Path, frames: int, width: int, height: int, fmt: str | None = None) -> None:
    """A small file of many large frames (a moving gradient, h264 yuv420p): what a model export can upload."""
    ramp = np.linspace(0, 255, width, dtype=np.float32)
    with av.open(str(path), "w", format=fmt) as container:
        stream = container.add_stream("libx264", rate=20)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        stream.options = {"preset": "ultrafast"}
        for i in range(frames):
            row = ((ramp + 4 * i) % 256).astype(np.uint8)
            frame = np.broadcast_to(row[None, :, None], (height, width, 3))
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def checkout(rev: str, dest: Path) -> Path:
    """The `wsp_eval` and `wsp_data` packages of git revision `rev`, extracted under `dest`."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "wsp_eval", "wsp_data"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest


def run_case(code_root: Path, kind: str, path: Path, release: Path) -> tuple[int, str]:
    """(peak RSS in MiB, outcome) of one case in a fresh interpreter importing the code under `code_root`."""
    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))

    r = subprocess.run([sys.executable, "-c", CASE, kind, str(path), str(release)], capture_output=True, text=True,
                       cwd=code_root, env={"PYTHONPATH": str(code_root), "PATH": "/usr/bin:/bin"}, preexec_fn=cap)
    if r.returncode != 0:
        return -1, f"exit {r.returncode}: {r.stderr.strip()[-200:]}"
    mib, outcome = r.stdout.strip().splitlines()[-1].split(" ", 1)
    return int(mib), outcome


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("release", type=Path)
    p.add_argument("submission", type=Path)
    p.add_argument("--frames", type=int, default=200, help="frames of the 1920×1080 video (default 200)")
    p.add_argument("--long", type=int, default=2900, help="frames of the 512×512 headerless one (default 2900)")
    p.add_argument("--before", help="also measure the code of this git revision")
    args = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="wsp-hostile-") as tmp:
        tmp = Path(tmp)
        wide, long = tmp / "wide", tmp / "long"
        for sub in (wide, long):
            shutil.copytree(args.submission, sub)
        target = sorted(wide.rglob("seed*.mp4"))[0]
        write_hostile(target, args.frames, 1920, 1080)
        write_hostile(long / target.relative_to(wide), args.long, 512, 512, fmt="h264")
        for sub, n, what in ((wide, args.frames, "1920×1080 mp4"),
                             (long, args.long, "512×512 raw h264 stream, no frame count in its header")):
            size = (sub / target.relative_to(wide)).stat().st_size / 1e6
            print(f"{sub.name}: {target.relative_to(wide)} replaced by a {what}, {n} frames, {size:.1f} MB")
        roots = {"after (this tree)": ROOT}
        if args.before:
            (tmp / "before").mkdir()
            roots = {f"before ({args.before})": checkout(args.before, tmp / "before"), **roots}
        print(f"{'code':<22} {'case':<14} {'peak RSS MiB':>12}  outcome")
        for label, root in roots.items():
            for kind, path, case in (("imports", target, "imports"), ("read", target, "read wide"),
                                     ("validate", wide, "validate wide"), ("validate", long, "validate long")):
                mib, outcome = run_case(root, kind, path, args.release)
                print(f"{label:<22} {case:<14} {mib:>12}  {outcome[:150]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
