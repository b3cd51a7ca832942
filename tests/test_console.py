"""A quiet terminal: library, simulator and encoder output goes to a log file, progress bars to the terminal,
and a failure prints the log's path and last lines."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from wsp_data.schema import LOG_DIR, RELEASE_JSON

# A long command in miniature: a bar on the terminal, C-level and Python output from this process and from a
# spawned worker process (as a build's simulator workers write it), then a failure.
SCRIPT = textwrap.dedent("""
    import ctypes, multiprocessing as mp, os, sys
    from pathlib import Path
    from tqdm import tqdm
    from wsp_eval import console

    def worker(i):
        os.write(2, b"[libx264 @ 0x1] worker C-level stderr %d\\n" % i)
        print("worker python stdout", i, flush=True)
        return i

    if __name__ == "__main__":
        log = Path(sys.argv[1])
        try:
            with console.library_output_to(log):
                with mp.get_context("spawn").Pool(2) as pool:
                    for _ in tqdm(pool.imap(worker, range(3)), total=3, desc="stage", file=console.terminal()):
                        pass
                os.write(1, b"parent C-level stdout\\n")
                ctypes.CDLL(None).printf(b"parent libc printf, buffered\\n")  # C stdio's own buffer
                print("mani_skill - WARNING - parent python stderr", file=sys.stderr)
                raise RuntimeError("simulated failure")
        except RuntimeError:
            print(console.failure_hint(), file=sys.stderr)
        print("summary after the command", flush=True)
""")


def test_library_output_goes_to_the_log_and_bars_to_the_terminal(tmp_path):
    script, log = tmp_path / "long_command.py", tmp_path / "out" / "wsp.log"
    script.write_text(SCRIPT)
    r = subprocess.run([sys.executable, str(script), str(log)], capture_output=True, text=True, timeout=120,
                       env={"PYTHONPATH": ":".join(sys.path), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    text = log.read_text()
    for line in ("worker C-level stderr 0", "worker C-level stderr 2", "worker python stdout 1",
                 "parent C-level stdout", "parent libc printf, buffered", "parent python stderr"):
        assert line in text, text
    # The terminal got the bar, the failure hint (the log's path and its last lines), and the summary printed
    # after the command — and none of the library lines except inside the hint.
    assert "stage: 100%" in r.stderr and "3/3" in r.stderr
    hint = r.stderr[r.stderr.index("library output log:"):]
    assert str(log) in hint and "| mani_skill - WARNING - parent python stderr" in hint
    assert "worker C-level" not in r.stderr[:r.stderr.index("library output log:")]
    assert r.stdout == "summary after the command\n"


def test_a_release_build_keeps_encoder_output_in_its_log(t1_release):
    # The shared tiny release was built by the real builder: x264's statistics went to the build's log, which
    # release.json does not list (it is not part of the dataset's checksums).
    log = t1_release / LOG_DIR / "build_t1_maniskill.log"
    assert "libx264" in log.read_text(errors="replace")
    assert not any(name.startswith(LOG_DIR) for name in json.loads((t1_release / RELEASE_JSON).read_text())["files"])
