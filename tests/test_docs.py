"""The documentation as a reader meets it, checked without a build: the site builds in strict mode, every
"spec §N.M" citation in code, tests and docs names a numbered heading of docs/spec.md, no file points outside the
repository, the README is a short usage manual, the reading path tells no history, and every `wsp` and `make`
command line of a fenced shell block parses with the real command-line parser (spec §6 and §7 for what the
commands produce)."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import re
import shlex
import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "docs" / "spec.md"
THIS = Path(__file__).resolve().relative_to(ROOT).as_posix()
LOG_DIR = "lab/"  # the experiment logs: history only, outside the docs site, never cited (lab/README.md)
CITED_SUFFIXES = (".py", ".md", ".j2", ".html")

HEADING = re.compile(r"^#{1,6}\s+(\d+(?:\.\d+)*)\.?\s")
# "spec §3.4", "spec §3, §4 and §6", "spec §4.2/§4.4": the numbers after the section signs
CITATION = re.compile(r"\bspec\s*§\s*\d+(?:\.\d+)*(?:(?:\s*,\s*|\s+and\s+|\s+or\s+|\s*/\s*)§\s*\d+(?:\.\d+)*)*",
                      re.IGNORECASE)
NUMBER = re.compile(r"\d+(?:\.\d+)*")
# The project's own input documents, which a clone does not have: cited by name, they resolve nowhere.
FOREIGN_CITATION = re.compile(r"\b(?:SPEC|DESIGN)\b")
OUTSIDE_PATHS = (re.compile(re.escape("../" + "shared")), re.compile(r"(?<![\w./-])/" + r"work/"))


@lru_cache(maxsize=None)
def tracked() -> tuple[str, ...]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        pytest.skip(f"not a git checkout ({e}): the documentation checks read the tracked files")
    return tuple(p for p in out.decode().split("\0") if p and (ROOT / p).is_file())


def text(path: str) -> str | None:
    """A tracked file's text, or None for a binary file (a NUL byte in it) or one that is not UTF-8."""
    data = (ROOT / path).read_bytes()
    if b"\0" in data[:8192]:
        return None
    try:
        return data.decode()
    except UnicodeDecodeError:
        return None


def reading_path() -> list[str]:
    """README.md and every tracked page under docs/ (the changelog and the experiment logs are outside it)."""
    return ["README.md"] + [p for p in tracked() if p.startswith("docs/") and p.endswith(".md")]


def spec_sections() -> set[str]:
    sections = set()
    for line in SPEC.read_text().splitlines():
        if m := HEADING.match(line):
            sections.add(m.group(1))
    return sections


# -- the site ------------------------------------------------------------------------------------------------
def test_site_builds_in_strict_mode(tmp_path):
    """`mkdocs build --strict` (mkdocs.yml: a broken link, an unknown anchor, a page missing from the nav fail)."""
    if importlib.util.find_spec("mkdocs") is None or importlib.util.find_spec("material") is None:
        pytest.skip("MkDocs and its Material theme are not installed (the `docs` extra, part of `make setup`)")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
                        "--site-dir", str(tmp_path / "site")], cwd=ROOT, capture_output=True, text=True, timeout=600,
                       env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})  # Material's end-of-life banner
    assert r.returncode == 0, f"mkdocs build --strict failed:\n{r.stdout[-3000:]}{r.stderr[-6000:]}"
    spec = (tmp_path / "site" / "spec.html").read_text()
    assert 'id="s3.4"' in spec and 'id="s4.2"' in spec  # the anchors pages link to: spec.md#s3.4


# -- citations and paths ---------------------------------------------------------------------------------------
def test_spec_sections_are_numbered_as_cited():
    """The fixed top-level numbering every citation relies on."""
    sections = spec_sections()
    expected = {"1", "2", "3", "3.1", "3.2", "3.3", "3.4", "3.5", "4", "4.1", "4.2", "4.3", "4.4", "4.5", "4.6",
                "4.7", "5", "6", "7", "8"}
    assert expected <= sections, f"missing numbered headings in docs/spec.md: {sorted(expected - sections)}"


def test_every_spec_citation_resolves():
    """Every "spec §N.M" in tracked code, tests, templates and docs names a numbered heading of docs/spec.md, in
    the lower-case form, and nothing cites the project's input documents (SPEC, DESIGN) that a clone lacks."""
    sections = spec_sections()
    unresolved, wrong_form, foreign, cited = [], [], [], 0
    for path in tracked():
        if not path.endswith(CITED_SUFFIXES) or path.startswith(LOG_DIR) or path == THIS:
            continue
        body = text(path)
        if body is None:
            continue
        for lineno, line in enumerate(body.splitlines(), 1):
            for m in CITATION.finditer(line):
                cited += 1
                if not m.group(0).startswith("spec"):
                    wrong_form.append(f"{path}:{lineno}: {m.group(0)!r} (write 'spec §N.M')")
                for number in NUMBER.findall(m.group(0)):
                    if number.rstrip(".") not in sections:
                        unresolved.append(f"{path}:{lineno}: {m.group(0)!r}: no section {number} in docs/spec.md")
            if FOREIGN_CITATION.search(line):
                foreign.append(f"{path}:{lineno}: {line.strip()[:120]}")
    assert cited > 0, "no spec citation found at all: the pattern or the file list is broken"
    assert not unresolved, "unresolved spec citations:\n" + "\n".join(unresolved)
    assert not wrong_form, "spec citations in another form:\n" + "\n".join(wrong_form)
    assert not foreign, ("citations of SPEC / DESIGN, which a clone does not have (cite docs/spec.md as "
                         "'spec §N.M'):\n" + "\n".join(foreign))


def test_no_path_outside_the_repository():
    """No tracked file points at the shared input folder or at an absolute path of the build machines."""
    found = []
    for path in tracked():
        if path == THIS or (body := text(path)) is None:
            continue
        for lineno, line in enumerate(body.splitlines(), 1):
            if any(p.search(line) for p in OUTSIDE_PATHS):
                found.append(f"{path}:{lineno}: {line.strip()[:120]}")
    assert not found, "paths outside the repository:\n" + "\n".join(found)


DOCS_PATH = re.compile(r"(?<![\w./-])docs/[A-Za-z0-9_./-]*[A-Za-z0-9_-]\.(?:md|py|png|jpe?g|svg|gif|html)\b")
LOG_CITATION = re.compile(r"(?<![\w./-])" + re.escape(LOG_DIR))


def test_cited_docs_paths_exist():
    """Every `docs/…` file named in a tracked file (a docstring's pointer, a README link) exists, and no code or
    test cites the experiment logs."""
    missing, logs = [], []
    for path in tracked():
        if path.startswith(LOG_DIR) or path == THIS or (body := text(path)) is None:
            continue
        for lineno, line in enumerate(body.splitlines(), 1):
            missing += [f"{path}:{lineno}: {m.group(0)}" for m in DOCS_PATH.finditer(line)
                        if not (ROOT / m.group(0)).exists()]
            if path.endswith((".py", ".sh")) and LOG_CITATION.search(line):
                logs.append(f"{path}:{lineno}: {line.strip()[:120]}")
    assert not missing, "docs files named but not in the repository:\n" + "\n".join(missing)
    assert not logs, "code or tests citing the experiment logs (history only):\n" + "\n".join(logs)


# -- the README and the reading path ---------------------------------------------------------------------------
def test_readme_is_a_short_usage_manual():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines; at most 200 (details belong in docs/)"
    assert any("wsp score" in line for line in lines[:80]), "how to score a model (`wsp score`) is not in the " \
                                                            "README's first 80 lines"


def _current_versions() -> set[str]:
    """The version numbers that are today's, not history: the scoring version reports print and the frozen label
    judge's version (its reported column names it)."""
    from wsp_eval.backends import judge_net
    from wsp_eval.score import SCORING_VERSION

    return {str(SCORING_VERSION), str(judge_net.VERSION)}


DATE = re.compile(r"\b20\d\d-[01]\d-[0-3]\d\b")
VERSION_N = re.compile(r"\b[Vv]ersion\s+(\d+)\b(?![.\d])")  # "Version 16", not "version 0.3.0" or "1.6.1"
LOG_MARKER = re.compile(r"\b(?:[Ss]top|[Ss]ession)\s+\d+\b"
                        r"(?!\s*(?:steps?|frames?|seconds?|s|ms|px|cm|mm|m|rad|times)\b|\s*%)")


def test_no_history_in_the_reading_path():
    """README and docs say what is true now: no dated entries, no earlier versions, no log markers ("stop 35",
    "session 4"). History lives in git, CHANGELOG.md and the experiment logs under lab/."""
    current, found = _current_versions(), []
    for path in reading_path():
        body = text(path) or ""
        for lineno, line in enumerate(body.splitlines(), 1):
            hits = DATE.findall(line) + LOG_MARKER.findall(line)
            hits += [m.group(0) for m in VERSION_N.finditer(line) if m.group(1) not in current]
            if hits:
                found.append(f"{path}:{lineno}: {', '.join(hits)}: {line.strip()[:100]}")
    assert not found, "history in the reading path:\n" + "\n".join(found)


# -- commands in the docs --------------------------------------------------------------------------------------
SHELL_LANGUAGES = {"bash", "sh", "shell", "console", "zsh"}
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([\w+-]*)")
ASSIGNMENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*=")
PLACEHOLDER = re.compile(r"^<[^<>]+>$")  # <release>, <submission>: a path the reader fills in
EXPANSION = re.compile(r"\$")  # $1, $RELEASE, ${N}: a value the shell fills in
REDIRECT = re.compile(r"^\d*(?:>>?|<)(&\d+)?$")  # `>`, `2>`, `>&2`, `<`: the next token is its file
REDIRECT_JOINED = re.compile(r"^\d*(?:>>?|<)\S+$")  # `>out.txt`, `2>/dev/null`, `2>&1`
SEPARATOR = re.compile(r"^[;&|]+$")
PREFIXES = {"time", "nice", "exec", "command"}


def shell_blocks(path: str) -> list[tuple[int, str]]:
    """(line number, command line) of every fenced shell block of a Markdown file: continuation lines joined; in a
    `console` block only the lines after a `$ ` prompt."""
    out, fence, language, pending, start = [], None, "", "", 0
    for lineno, line in enumerate((ROOT / path).read_text().splitlines(), 1):
        m = FENCE.match(line)
        if fence is None:
            if m:
                fence, language = m.group(2), m.group(3).lower()
            continue
        if m and m.group(2).startswith(fence) and not m.group(3):
            fence, pending = None, ""
            continue
        if language not in SHELL_LANGUAGES:
            continue
        stripped = line.strip()
        if language == "console" and not pending:
            if not stripped.startswith("$ "):
                continue
            stripped = stripped[2:]
        if not pending:
            start = lineno
        if stripped.endswith("\\"):
            pending += stripped[:-1] + " "
            continue
        out.append((start, pending + stripped))
        pending = ""
    return out


def simple_commands(line: str) -> list[list[str]]:
    """The simple commands of a shell line (split at ;, &&, ||, |, &), comments and redirections removed, leading
    variable assignments and `time`/`nice` dropped."""
    lex = shlex.shlex(line, posix=True, punctuation_chars=";&|")
    lex.whitespace_split = True
    commands, current, skip = [], [], False
    for token in lex:
        if SEPARATOR.match(token):
            commands.append(current)
            current = []
            continue
        if skip:
            skip = False
            continue
        if not PLACEHOLDER.match(token):
            if REDIRECT.match(token):
                skip = True
                continue
            if REDIRECT_JOINED.match(token):
                continue
        current.append(token)
    commands.append(current)
    out = []
    for argv in commands:
        while argv and (ASSIGNMENT.match(argv[0]) or argv[0] in PREFIXES):
            argv = argv[1:]
        if argv:
            out.append(argv)
    return out


def make_targets() -> set[str]:
    targets = set()
    for line in (ROOT / "Makefile").read_text().splitlines():
        if m := re.match(r"^([A-Za-z0-9_][A-Za-z0-9_.-]*)\s*:(?!=)", line):
            targets.add(m.group(1))
    return targets


def _parse(argv: list[str]) -> str | None:
    """None when the CLI's parser for `argv` (`wsp_eval.cli.parser(argv)`: the scoring commands and the plug-in
    command `argv` names) accepts it, else argparse's message. A value argparse refuses is accepted when it is a
    placeholder (<release>) or a shell expansion ($1): the reader or the shell fills it in."""
    from wsp_eval.cli import parser

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            parser(argv).parse_args(argv)
    except SystemExit as e:
        if e.code not in (0, None):
            message = err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else f"exit {e.code}"
            filled_in = [a for a in argv if PLACEHOLDER.match(a) or EXPANSION.search(a)]
            if not any(f"'{a}'" in message for a in filled_in):
                return message
    return None


def test_every_documented_command_parses():
    """Every `wsp …` line of a ```bash / ```sh / ```console block in the README and the docs parses with
    the parser `wsp` runs (`wsp_eval.cli.parser`), every `make X` names a Makefile target, and every script a
    documented `python …` / `bash …` line runs is in the repository. Placeholders such as <release> stand for
    paths."""
    targets = make_targets()
    failures, checked = [], 0
    for path in reading_path():
        for lineno, line in shell_blocks(path):
            try:
                commands = simple_commands(line)
            except ValueError as e:  # unbalanced quotes
                failures.append(f"{path}:{lineno}: `{line}`: not a shell line ({e})")
                continue
            for argv in commands:
                name = Path(argv[0]).name
                if name == "wsp":
                    checked += 1
                    if (why := _parse(argv[1:])) is not None:
                        failures.append(f"{path}:{lineno}: `{' '.join(argv)}`: {why}")
                elif name == "make":
                    checked += 1
                    named = [a for a in argv[1:] if not a.startswith("-") and not ASSIGNMENT.match(a)]
                    failures += [f"{path}:{lineno}: `{' '.join(argv)}`: no Makefile target {t!r}"
                                 for t in named if t not in targets]
                elif re.fullmatch(r"python(3(\.\d+)?)?|bash|sh", name) and len(argv) > 1 and \
                        argv[1].endswith((".py", ".sh")):
                    checked += 1
                    if not (ROOT / argv[1]).is_file():
                        failures.append(f"{path}:{lineno}: `{' '.join(argv)}`: no file {argv[1]} in the repository")
    assert checked > 0, "no documented command found: the block parser is broken"
    assert not failures, "documented commands that do not parse:\n" + "\n".join(failures)


def test_command_checker_reads_shell_lines_as_a_shell_does():
    """The line splitting the check above relies on: continuation, prompts, comments, chains, redirections."""
    assert simple_commands("wsp info worldsimprobe  # what a release holds") == [["wsp", "info", "worldsimprobe"]]
    assert simple_commands("HF_HUB_OFFLINE=1 wsp score s --release r --out o 2>&1 | tee log && make test") == [
        ["wsp", "score", "s", "--release", "r", "--out", "o"], ["tee", "log"], ["make", "test"]]
    assert simple_commands("wsp validate <submission> --release <release> > problems.txt") == [
        ["wsp", "validate", "<submission>", "--release", "<release>"]]
    assert _parse(["score", "<submission>", "--release", "<release>", "--out", "report"]) is None
    assert "invalid choice" in _parse(["build", "--suite", "t9"])  # a plug-in command's own arguments are checked
    assert _parse(["build", "--suite", "$1", "--count", "$2"]) is None  # a shell function's arguments
    assert _parse(["score", "sub", "--release", "r", "--out", "o", "--no-such-flag"]) is not None
