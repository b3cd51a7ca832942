"""Reference-flow cache: the reference side of RMFA (T2, T3), computed once per release and flow backend and
reused by every later scoring of any submission (it was ≈ 40 % of T2's scoring time).

Key: the flow backend's name and version and the source of `wsp_eval/flow.py` with this module's format number,
so another evaluator or changed RMFA code never reads stale flows; each config's entries sit in
`<config>@<fingerprint>/` (`wsp_eval.reference_cache.entry_folder`), named by the config's verified content, so a
rebuilt or changed config never meets its old flows. Location: `<release>/.cache/
reference_flows/<key>/` when the release folder is writable (`release.json` ignores `.cache`), otherwise
`$XDG_CACHE_HOME/worldsimprobe/reference_flows/<key>/` (default `~/.cache`). One file per (config, episode,
common duration), named by the number of 5 Hz samples the duration holds (what the flows depend on), written
atomically: float32 flows and bool masks, bit for bit what a fresh computation gives. An unreadable entry, or
one of another length, is recomputed and rewritten; no writable place only costs the cache.
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wsp_eval import flow
from wsp_eval.flow import ReferenceFlows, sample_times
from wsp_eval.reference_cache import cache_folder, write_atomic

FORMAT = 1  # bump when an entry's layout changes
KIND = "reference_flows"
ENTRY = "{episode:06d}_{samples}samples.npz"


def cache_dir(release: Path, backend_name: str, backend_version: str) -> Path | None:
    """This release's and backend's cache folder (created), in the release when writable, else the user's cache;
    None when neither can be written (scoring then recomputes the flows)."""
    parts = [f"{backend_name}\0{backend_version}\0{FORMAT}\0".encode(), Path(flow.__file__).read_bytes()]
    return cache_folder(release, KIND, parts)


def load_or_compute(folder: Path, config: str, episode: int, duration: float,
                    compute: Callable[[], ReferenceFlows]) -> ReferenceFlows:
    """The cached reference flows of (config, episode, duration) (`config`: the entry folder), or `compute()`
    stored for the next scoring."""
    samples = len(sample_times(duration))
    path = Path(folder) / config / ENTRY.format(episode=episode, samples=samples)
    try:
        with np.load(path) as z:
            cached = ReferenceFlows(z["flows"], z["masks"])
        if len(cached.flows) == len(cached.masks) == samples - 1:
            return cached
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError):
        pass  # absent or damaged: compute it
    flows = compute()
    write_atomic(path, lambda f: np.savez(f, flows=flows.flows, masks=flows.masks), ".npz")
    return flows
