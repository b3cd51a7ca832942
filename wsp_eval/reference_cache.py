"""Where the reference side of scoring is kept between scorings, and its per-instance results.

The reference side of an instance depends only on the release and the evaluator, never on a submission, so it is
computed once and reused by every later scoring of any submission: RMFA's reference flows (T2, T3;
`wsp_eval.flow_cache`) and the reference's own results (T4: the evaluated object's visible fraction in the
reference and its presence reference; T5: the judge's verdict on the reference), which spare every scoring of T4
and T5 decoding and tracking or judging each reference (docs/performance.md).

A folder is named by a key: the SHA-256 of what the entries depend on besides the release (the evaluator and the
scoring code), so another backend or changed scoring code never reads stale entries. Inside it, each config's
entries sit in `<config>@<fingerprint>/`, the fingerprint of the config's verified files
(`wsp_eval.integrity`): a rebuilt or changed config never meets the entries of its old content, and the same
content at another path shares them. Location: `<release>/.cache/<kind>/<key>/` when the release folder is
writable (`release.json` ignores `.cache`), otherwise `$XDG_CACHE_HOME/worldsimprobe/<kind>/<key>/` (default
`~/.cache`); no writable place only costs the cache. Entries are written atomically; an unreadable one is
recomputed and rewritten.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Callable, Iterable
from functools import lru_cache
from pathlib import Path


RESULTS = "reference_results"
RESULTS_FORMAT = 1  # bump when a result entry's layout changes
RESULT_ENTRY = "{episode:06d}.json"


def cache_folder(release: Path, kind: str, key_parts: Iterable[bytes]) -> Path | None:
    """The folder (created) of `kind` entries for this key, in the release when writable, else in the user's
    cache; None when neither can be written."""
    release = Path(release)
    h = hashlib.sha256(kind.encode())
    for part in key_parts:
        h.update(b"\0" + part)
    key = h.hexdigest()[:24]
    user = os.environ.get("XDG_CACHE_HOME") or (os.environ.get("HOME") and Path(os.environ["HOME"]) / ".cache")
    bases = [release / ".cache" / kind] + ([Path(user) / "worldsimprobe" / kind] if user else [])
    for base in bases:
        folder = base / key
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=folder, prefix=".write-test"):
                pass
            return folder
        except OSError:
            continue
    return None


def write_atomic(path: Path, write: Callable[[object], None], suffix: str) -> None:
    """`write(file)` into a temporary file beside `path`, then rename it to `path`; a full disk costs the
    entry, never the caller."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".partial{suffix}")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except OSError:
        pass
    finally:
        Path(tmp).unlink(missing_ok=True)


def results_folder(release: Path, suite: str, backends: dict, spec: dict) -> Path | None:
    """The result cache of one suite: keyed by the suite, the name and version of each backend it uses
    (`Backends.describe()`), their `BackendSpec` fields (choice, checkpoint paths, each checkpoint's size and
    modification time) and the source of every `wsp_eval` module (any change to scoring code starts a new
    folder)."""
    checkpoints = []
    for value in spec.values():
        if isinstance(value, str) and os.path.isfile(value):
            st = os.stat(value)
            checkpoints.append(f"{value}:{st.st_size}:{st.st_mtime_ns}")
    parts = [f"{RESULTS_FORMAT}", suite, json.dumps(backends, sort_keys=True), json.dumps(spec, sort_keys=True),
             *checkpoints, _scoring_source()]
    return cache_folder(release, RESULTS, [p.encode() for p in parts])


@lru_cache(maxsize=1)
def _scoring_source() -> str:
    """SHA-256 of every `wsp_eval` module's source, read once per process."""
    h = hashlib.sha256()
    for path in sorted(Path(__file__).parent.rglob("*.py")):
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


def entry_folder(config: str, fingerprint: str) -> str:
    """The subfolder of a config's entries: its name and its content's fingerprint."""
    return f"{config}@{fingerprint[:16]}" if fingerprint else config


def load_or_compute_result(folder: Path, config: str, episode: int, compute: Callable[[], dict],
                           keys: Iterable[str] = ()) -> dict:
    """The cached JSON result of (config, episode) (`config`: the entry folder, `entry_folder`), or `compute()`
    (JSON-ready; floats round-trip exactly) stored for the next scoring; an entry lacking one of `keys` is
    damaged and recomputed."""
    path = Path(folder) / config / RESULT_ENTRY.format(episode=episode)
    try:
        cached = json.loads(path.read_text())
        if isinstance(cached, dict) and all(k in cached for k in keys):
            return cached
    except (OSError, ValueError):
        pass  # absent or damaged: compute it
    result = compute()
    write_atomic(path, lambda f: f.write(json.dumps(result).encode()), ".json")
    return result
