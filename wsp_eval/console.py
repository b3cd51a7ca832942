"""The terminal and the log file of a long command.

While `library_output_to(log)` is active, everything written to this process's stdout and stderr file
descriptors — C libraries (x264, FFmpeg, SAPIEN, MuJoCo), Python warnings and logging, and every worker process
started meanwhile, which inherits the descriptors — goes to `log`. Progress bars go to `terminal()`, the real
terminal. When the command fails, `failure_hint()` gives the log's path and last lines for the error message.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TextIO

TAIL_LINES = 15
HEADER = "=== wsp run"  # starts each run's part of a log
LOG_NAME = "wsp.log"  # under a scoring or calibration output folder

_terminal: TextIO | None = None
_active_log: Path | None = None
_failed_log: Path | None = None


def terminal() -> TextIO:
    """Where progress bars go: the real terminal while library output is redirected, else stderr."""
    return _terminal or sys.stderr


def _flush_all() -> None:
    """Flush Python's streams and C stdio's buffers, so nothing written before a switch lands after it."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


@contextmanager
def library_output_to(log: Path) -> Iterator[Path]:
    """Send file descriptors 1 and 2 (this process and workers started inside) to `log`, appending; yields the
    log that collects the output (the outer one when nested inside another long command)."""
    global _terminal, _active_log, _failed_log
    if _terminal is not None:  # nested inside another long command: its log already collects everything
        yield _active_log
        return
    log = Path(log)
    log.parent.mkdir(parents=True, exist_ok=True)
    _failed_log = None
    _flush_all()
    saved: dict[int, int] = {}
    try:
        with open(log, "ab") as f:
            f.write(f"\n{HEADER} {time.strftime('%Y-%m-%d %H:%M:%S')}: {' '.join(sys.argv[1:])}\n".encode())
            f.flush()
            for fd in (1, 2):
                saved[fd] = os.dup(fd)
                os.dup2(f.fileno(), fd)
        _terminal = os.fdopen(os.dup(saved[2]), "w", buffering=1)
        _active_log = log
        yield log
    except BaseException as e:
        if not isinstance(e, KeyboardInterrupt) and _active_log is not None:
            _failed_log = log
        raise
    finally:
        _flush_all()
        for fd, keep in saved.items():
            os.dup2(keep, fd)
            os.close(keep)
        if _terminal is not None:
            _terminal.close()
        _terminal = _active_log = None


def tail(log: Path, lines: int = TAIL_LINES) -> list[str]:
    """The last `lines` non-empty lines this run wrote to `log` (after its header; progress-bar carriage
    returns folded), or [] if there are none or the log is unreadable."""
    try:
        with open(log, "rb") as f:
            f.seek(max(0, f.seek(0, os.SEEK_END) - 64 * 1024))
            text = f.read().decode("utf-8", "replace")
    except OSError:
        return []
    rows = [r.rsplit("\r", 1)[-1].rstrip() for r in text.splitlines()]
    starts = [i for i, r in enumerate(rows) if r.startswith(HEADER)]
    rows = rows[starts[-1] + 1:] if starts else rows
    return [r for r in rows if r][-lines:]


def failure_hint() -> str:
    """The path and last lines of the log of the command that just failed, or '' when there is none."""
    global _failed_log
    log, _failed_log = _failed_log, None  # said once
    if log is None:
        return ""
    rows = tail(log)
    if not rows:
        return ""
    body = "\n".join(f"  | {r[:300]}" for r in rows)
    return f"library output log: {log}; its last {len(rows)} line(s):\n{body}"
