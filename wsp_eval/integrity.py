"""The release as published: every file that scoring reads checked against its SHA-256 in `release.json`.

`release.json` lists the checksum of every file of the release. `verify` hashes each file of the configs being
scored (instance tables, masks, LeRobot data and metadata, reference videos) and stops at the first run of
mismatches with the file, the expected and the found hash, and how to get a good copy. A file is hashed once:
its (size, mtime, inode) and hash are remembered in `<release>/.cache/verified.json` (or the user's cache when
the release is read-only), so a later run costs one `stat` per file. A config's *fingerprint* (the hash of its
files' verified hashes) names it in score reports and keys the reference caches, so a changed file can never
meet a cache entry of its old content.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from wsp_eval.console import terminal
from wsp_eval.release_format import RELEASE_JSON, load_release, rebuild_command

MEMO = "verified.json"
MEMO_FORMAT = 1  # bump when the memo's layout changes
HASH_THREADS = 4  # hashlib releases the GIL on large blocks: a few threads keep a disk busy
SHOWN = 5  # mismatches named in an error


class IntegrityError(RuntimeError):
    """A release file differs from its `release.json` checksum, or is missing; the message names each one."""


@dataclass(frozen=True)
class FileProblem:
    """One file that does not match `release.json`: `found` None = missing; `expected` None = not listed."""

    path: str
    expected: str | None
    found: str | None

    @property
    def reason(self) -> str:
        if self.found is None:
            return f"missing (release.json lists sha256 {self.expected})"
        if self.expected is None:
            return f"not listed in release.json (sha256 {self.found}): not part of the release as built"
        return f"sha256 {self.found}, release.json lists {self.expected}"

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def config_files(release: dict, config: str) -> dict[str, str]:
    """The files `release.json` lists under `config/`, path → sha256."""
    prefix = f"{config}/"
    return {p: h for p, h in release.get("files", {}).items() if p.startswith(prefix)}


def fingerprint(files: dict[str, str]) -> str:
    """The SHA-256 of a set of files' paths and hashes (order-free): a config's content, named in one hash."""
    h = hashlib.sha256()
    for path, digest in sorted(files.items()):
        h.update(f"{path}\0{digest}\n".encode())
    return h.hexdigest()


def memo_path(root: Path) -> Path | None:
    """Where the memo of verified files lives: the release's `.cache` when writable, else the user's cache."""
    candidates = [root / ".cache"]
    user = os.environ.get("XDG_CACHE_HOME") or (os.environ.get("HOME") and Path(os.environ["HOME"]) / ".cache")
    if user:
        key = hashlib.sha256(str(root.resolve()).encode()).hexdigest()[:24]
        candidates.append(Path(user) / "worldsimprobe" / "verified" / key)
    for folder in candidates:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            if os.access(folder, os.W_OK):
                return folder / MEMO
        except OSError:
            continue
    return None


def _read_memo(path: Path | None) -> dict[str, list]:
    if path is None:
        return {}
    try:
        memo = json.loads(path.read_text())
        return memo["files"] if memo.get("format") == MEMO_FORMAT else {}
    except (OSError, ValueError, KeyError, TypeError):
        return {}  # absent or damaged: every file is hashed again


def _write_memo(path: Path | None, files: dict[str, list]) -> None:
    if path is None:
        return
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        tmp.write_text(json.dumps({"format": MEMO_FORMAT, "files": files}))
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)  # no room: the next run hashes again


def _stamp(st: os.stat_result) -> list[int]:
    return [st.st_size, st.st_mtime_ns, st.st_ino]


def check(root: Path, configs: Iterable[str] | None = None, *, unlisted: bool = False,
          progress: bool = False) -> tuple[dict[str, str], list[FileProblem]]:
    """Hash the files of `configs` (default: every config) that `release.json` lists, each once (remembered by
    size, mtime and inode); with `unlisted`, also name files in those config folders that it does not list.
    Returns each config's fingerprint and the problems found."""
    from tqdm import tqdm

    root = Path(root)
    release = load_release(root)
    names = sorted(release.get("configs", {})) if configs is None else list(configs)
    listed = {c: config_files(release, c) for c in names}
    memo_file = memo_path(root)
    memo = _read_memo(memo_file)
    problems: list[FileProblem] = []
    todo: list[tuple[str, list[int]]] = []
    found: dict[str, str] = {}
    for files in listed.values():
        for rel in files:
            try:
                stamp = _stamp(os.stat(root / rel))
            except OSError:
                problems.append(FileProblem(rel, files[rel], None))
                continue
            entry = memo.get(rel)
            if entry and entry[:3] == stamp:
                found[rel] = entry[3]
            else:
                todo.append((rel, stamp))
    if todo:
        bar = tqdm(total=sum(s[0] for _, s in todo), unit="B", unit_scale=True, desc="verifying release files",
                   disable=not progress, file=terminal())

        def hashed(item: tuple[str, list[int]]) -> tuple[str, list[int], str]:
            rel, stamp = item
            digest = sha256(root / rel)
            bar.update(stamp[0])
            return rel, stamp, digest

        with ThreadPoolExecutor(HASH_THREADS) as pool:
            for rel, stamp, digest in pool.map(hashed, todo):
                found[rel] = digest
                memo[rel] = [*stamp, digest]
        bar.close()
        _write_memo(memo_file, memo)
    for files in listed.values():
        problems += [FileProblem(rel, h, found[rel]) for rel, h in files.items() if rel in found and found[rel] != h]
    if unlisted:
        for c in names:
            folder = root / c
            extra = sorted(str(p.relative_to(root)) for p in folder.rglob("*")
                           if p.is_file() and str(p.relative_to(root)) not in listed[c]) if folder.is_dir() else []
            problems += [FileProblem(rel, None, sha256(root / rel)) for rel in extra]
    problems.sort(key=lambda p: p.path)
    return {c: fingerprint(listed[c]) for c in names}, problems


def repair(root: Path, config: str) -> str:
    """How to get a good copy of `config`: download it again, or rebuild it from its recorded build config."""
    root = Path(root)
    entry = load_release(root).get("configs", {}).get(config)
    how = f"; or rebuild it: {rebuild_command(root.parent / f'{root.name}-rebuilt', config, entry)}" if entry else ""
    return f"re-download config {config} (a damaged download or an edited copy scores wrongly){how}"


def describe(root: Path, problems: list[FileProblem]) -> str:
    """The error text for `problems`: the files (the first few), which configs they break and how to repair them."""
    root = Path(root)
    lines = [f"{root}: {len(problems)} file(s) differ from release.json, the release as built:"]
    lines += [f"  {root / p.path}: {p.reason}" for p in problems[:SHOWN]]
    if len(problems) > SHOWN:
        lines.append(f"  … and {len(problems) - SHOWN} more (`wsp verify {root}` lists every one)")
    lines += [f"  fix: {repair(root, c)}" for c in sorted({p.path.split('/', 1)[0] for p in problems})]
    return "\n".join(lines)


def verify(root: Path, configs: Iterable[str] | None = None, *, progress: bool = False) -> dict[str, str]:
    """Each config's fingerprint once its files match `release.json`; IntegrityError naming the files otherwise."""
    prints, problems = check(root, configs, progress=progress)
    if problems:
        raise IntegrityError(describe(root, problems))
    return prints


def release_json_sha256(root: Path) -> str:
    return hashlib.sha256((Path(root) / RELEASE_JSON).read_bytes()).hexdigest()
