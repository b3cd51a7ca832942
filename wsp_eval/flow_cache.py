"""Reference-flow cache: the reference side of RMFA (T2, T3), computed once per release and flow backend and
reused by every later scoring of any submission (it was ≈ 40 % of T2's scoring time).

Key: the SHA-256 of the release's `release.json` (which lists every file's checksum) with the flow backend's
name and version, so a rebuilt release or another evaluator never reads stale flows. Location: `<release>/.cache/
reference_flows/<key>/` when the release folder is writable (`release.json` ignores `.cache`), otherwise
`$XDG_CACHE_HOME/worldsimprobe/reference_flows/<key>/` (default `~/.cache`). One file per (config, episode,
common duration), written atomically: float32 flows and bool masks, bit for bit what a fresh computation gives.
An unreadable entry is recomputed and rewritten.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wsp_eval.flow import ReferenceFlows
from wsp_eval.release_format import RELEASE_JSON

SUBDIR = Path(".cache") / "reference_flows"
ENTRY = "{episode:06d}_{ms}ms.npz"


def cache_dir(release: Path, backend_name: str, backend_version: str) -> Path:
    """This release's and backend's cache folder (created), in the release when writable, else the user's cache."""
    release = Path(release)
    h = hashlib.sha256((release / RELEASE_JSON).read_bytes())
    h.update(f"\0{backend_name}\0{backend_version}".encode())
    key = h.hexdigest()[:24]
    for base in (release / SUBDIR,
                 Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "worldsimprobe" / "reference_flows"):
        folder = base / key
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=folder, prefix=".write-test"):
                pass
            return folder
        except OSError:
            continue
    raise OSError(f"no writable place for the reference-flow cache (tried {release / SUBDIR} and the user cache)")


def load_or_compute(folder: Path, config: str, episode: int, duration: float,
                    compute: Callable[[], ReferenceFlows]) -> ReferenceFlows:
    """The cached reference flows of (config, episode, duration), or `compute()` stored for the next scoring."""
    path = Path(folder) / config / ENTRY.format(episode=episode, ms=int(round(duration * 1000)))
    try:
        with np.load(path) as z:
            return ReferenceFlows(z["flows"], z["masks"])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError):
        pass  # absent or damaged: compute it
    flows = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial.npz")
    try:
        np.savez(tmp, flows=flows.flows, masks=flows.masks)
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)  # a full disk costs the cache, never the score
    return flows
