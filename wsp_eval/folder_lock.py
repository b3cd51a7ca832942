"""One writer per output folder: `wsp score`, `wsp generate` and `wsp build` hold an exclusive lock on what they
write into, so that a second process into the same folder stops at once instead of overwriting the first's work.

The lock is an advisory `flock` on a small file that names its holder (pid, host, command), removed when the
holder is done, so a finished run leaves nothing in its folder. The kernel drops the lock when its holder exits,
however it exits, so the file a killed process leaves behind is simply taken over by the next run. A process that
locks a file another has just removed sees that the path no longer names it and tries again, so two processes can
never both hold a folder.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

LOCK_NAME = ".wsp-lock"


class FolderBusy(RuntimeError):
    """Another live process holds the folder's lock; the message names it."""


@contextmanager
def exclusive(folder: Path, what: str, name: str = LOCK_NAME, *, wait: bool = False) -> Iterator[Path]:
    """Hold `folder`'s lock (file `name` in it; the folder is created) while the block runs; FolderBusy when
    another process holds it, or with `wait`, once it has let go."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            os.close(fd)
            raise FolderBusy(f"{folder}: {_holder(path)} is writing into this folder; wait for it to finish, or "
                             f"choose another folder") from None
        try:
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)  # the holder removed this file as we locked it: lock the path's file afresh
    try:
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "command": what,
                                 "argv": sys.argv}).encode())
        yield path
    finally:
        path.unlink(missing_ok=True)  # while still held: a process waiting on this file then locks afresh
        os.close(fd)


def _holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text())
        return f"`{info['command']}` (pid {info['pid']} on {info['host']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"
