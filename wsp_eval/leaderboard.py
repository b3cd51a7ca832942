"""`wsp leaderboard`: models × (platform, suite, Overall) from any number of score reports (`wsp score`).

Comparable reports only: the main table holds the reports made against the same release (`release.json`
checksum and the fingerprints of the configs scored, `wsp_eval.integrity`), benchmark version and evaluators (backend names and versions) as the first one given; every other
report goes to a table of its own, headed by what differs, never mixed in. Scores and 95 % CIs are the reports'
own. **Ties**: within each column the models are ranked by score, and a model whose difference to the one ranked
just above it is not significant shares its rank ("=") — a paired bootstrap over the instances both reports
scored (`BOOTSTRAP` resamples, seeded; T5 resampled within primitives as its score is), the difference's 95 %
interval containing 0. Overall and macro differences resample every suite at once, as their CIs do.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from html import escape
from pathlib import Path

import numpy as np

from wsp_eval.release_format import split_config
from wsp_eval.score import bootstrap_means
from wsp_eval.suites import SCORERS

BOOTSTRAP = 2000
SEED = 0


class LeaderboardError(RuntimeError):
    """An unreadable report, or none given."""


@dataclass
class Entry:
    """One report: its model, comparability key and per-(config, instance) scores with their groups."""

    path: str
    report: dict

    @property
    def model(self) -> str:
        return str(self.report["submission"]["model"])

    @property
    def key(self) -> tuple:
        rel = self.report.get("release", {})
        backends = tuple(sorted((r, b["name"], b["version"]) for r, b in self.report.get("backends", {}).items()))
        content = tuple(sorted((c, v.get("fingerprint")) for c, v in rel.get("configs", {}).items()))
        return (rel.get("release_json_sha256"), content), rel.get("version"), backends

    def scores(self, config: str) -> dict[str, tuple[float, str]]:
        return {r["instance_id"]: (float(r["score"]), str(r.get("group", ""))) for r in self.report["instances"]
                if r["config"] == config}


def load(paths: list[Path]) -> list[Entry]:
    if not paths:
        raise LeaderboardError("no report given")
    out = []
    for p in paths:
        path = p / "report.json" if p.is_dir() else p
        try:
            report = json.loads(path.read_text())
            _ = report["submission"]["model"], report["platforms"], report["instances"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise LeaderboardError(f"{path}: not a `wsp score` report ({type(e).__name__}: {e})") from None
        out.append(Entry(str(path), report))
    return out


def _columns(entries: list[Entry]) -> list[tuple[str, str]]:
    """(platform, suite or 'overall') columns present in any report, platforms sorted, suites in order."""
    cols = []
    for platform in sorted({p for e in entries for p in e.report["platforms"]}):
        suites = sorted({s for e in entries for s in e.report["platforms"].get(platform, {}).get("suites", {})})
        cols += [(platform, s) for s in suites] + [(platform, "overall")]
    return cols + [("macro", "overall")]


def _cell(entry: Entry, platform: str, suite: str) -> dict | None:
    if platform == "macro":
        return entry.report.get("macro_average")
    p = entry.report["platforms"].get(platform)
    if p is None:
        return None
    return p.get("overall") if suite == "overall" else p["suites"].get(suite)


def _suite_diffs(a: Entry, b: Entry, config: str, rng: np.random.Generator) -> np.ndarray | None:
    """BOOTSTRAP resampled differences of a config's suite score (a − b) over the instances both scored."""
    sa, sb = a.scores(config), b.scores(config)
    shared = sorted(sa.keys() & sb.keys())
    if len(shared) < 2:
        return None
    d = np.array([sa[i][0] - sb[i][0] for i in shared])
    balanced = SCORERS[split_config(config)[0]].BALANCED
    return bootstrap_means(d, [sa[i][1] for i in shared] if balanced else None, rng, BOOTSTRAP)


def _configs(entry: Entry, platform: str) -> list[str]:
    return [s["config"] for s in entry.report["platforms"].get(platform, {}).get("suites", {}).values()]


def tied(a: Entry, b: Entry, platform: str, suite: str) -> bool:
    """Whether a and b do not differ significantly in this column (paired bootstrap, module docstring)."""
    rng = np.random.default_rng(SEED)
    if suite != "overall":
        config = a.report["platforms"][platform]["suites"][suite]["config"]
        diffs = _suite_diffs(a, b, config, rng)
    else:
        platforms = [platform] if platform != "macro" else sorted(a.report["platforms"])
        per_platform = []
        for p in platforms:
            parts = [x for c in _configs(a, p) if (x := _suite_diffs(a, b, c, rng)) is not None]
            if parts:
                per_platform.append(np.mean(parts, axis=0))
        diffs = np.mean(per_platform, axis=0) if per_platform else None
    if diffs is None:
        return True  # nothing shared to tell them apart
    lo, hi = np.percentile(diffs, [2.5, 97.5])
    return bool(lo <= 0 <= hi)


def table(entries: list[Entry]) -> dict:
    """One comparable group: columns, and per model its cells (score, CI, rank, tied with the one above)."""
    cols = _columns(entries)
    rows = {e.model: {"report": e.path, "cells": {}} for e in entries}
    for platform, suite in cols:
        have = [(e, c) for e in entries if (c := _cell(e, platform, suite)) and c.get("score") is not None]
        have.sort(key=lambda x: -x[1]["score"])
        rank = 0
        for k, (e, c) in enumerate(have):
            tie = k > 0 and tied(have[k - 1][0], e, platform, suite)
            rank = rank if tie else k + 1
            rows[e.model]["cells"][f"{platform} {suite}"] = {"score": c["score"], "ci": c.get("ci"), "rank": rank,
                                                             "tied_with_above": tie,
                                                             "partial": c.get("complete") is False}
    first = entries[0].report
    return {"columns": [f"{p} {s}" for p, s in cols], "rows": rows,
            "release": first.get("release", {}), "backends": first.get("backends", {}),
            "benchmark_version": first.get("release", {}).get("version")}


def build(paths: list[Path]) -> dict:
    """The leaderboard: the main comparable table and, apart, any report that is not comparable with it."""
    entries = load(paths)
    models = [e.model for e in entries]
    dupes = sorted({m for m in models if models.count(m) > 1})
    if dupes:
        raise LeaderboardError(f"more than one report of model(s) {', '.join(dupes)}: give one report per model")
    groups: dict[tuple, list[Entry]] = {}
    for e in entries:
        groups.setdefault(e.key, []).append(e)
    main_key = entries[0].key
    apart = []
    for key, members in groups.items():
        if key == main_key:
            continue
        why = [w for w, x, y in (("release" if key[0][0] != main_key[0][0] else "release files scored", key[0],
                                  main_key[0]), ("benchmark version", key[1], main_key[1]),
                                 ("evaluators", key[2], main_key[2])) if x != y]
        apart.append({"differs_in": why, **table(members)})
    return {"main": table(groups[main_key]), "not_comparable": apart}


def _fmt(cell: dict | None) -> str:
    if not cell:
        return "—"
    ci = f" [{cell['ci'][0]:.1f}, {cell['ci'][1]:.1f}]" if cell.get("ci") else ""
    partial = "*" if cell.get("partial") else ""
    return f"{cell['rank']}{'=' if cell['tied_with_above'] else ''}. {cell['score']:.1f}{partial}{ci}"


def _header(t: dict) -> list[str]:
    rel, be = t["release"], t["backends"]
    return [f"Release {rel.get('path', '?')} (release.json sha256 {str(rel.get('release_json_sha256'))[:12]}), "
            f"benchmark {t['benchmark_version']}; evaluators: "
            + ", ".join(f"{r} {b['name']} ({b['version']})" for r, b in sorted(be.items()))]


def markdown(board: dict) -> str:
    def one(t: dict) -> list[str]:
        lines = _header(t) + ["", "| model | " + " | ".join(t["columns"]) + " |",
                              "|---|" + "---|" * len(t["columns"])]
        order = sorted(t["rows"], key=lambda m: -(t["rows"][m]["cells"].get(t["columns"][-1], {}).get("score") or -1))
        for m in order:
            lines.append(f"| {m} | " + " | ".join(_fmt(t["rows"][m]["cells"].get(c)) for c in t["columns"]) + " |")
        return lines

    out = ["Cells: rank (\"=\": not significantly different from the model ranked just above, paired bootstrap), "
           "score [95 % CI]; \"*\": a partial Overall (not all of T1–T5 scored).", ""] + one(board["main"])
    for t in board["not_comparable"]:
        out += ["", f"Not comparable with the table above (different {', '.join(t['differs_in'])}):", ""] + one(t)
    return "\n".join(out) + "\n"


def html(board: dict) -> str:
    def one(t: dict) -> str:
        head = "".join(f"<th onclick=\"sortBy(this)\">{escape(c)}</th>" for c in ["model"] + t["columns"])
        body = []
        for m, row in t["rows"].items():
            cells = "".join(f"<td data-v=\"{c['score'] if c else -1}\">{escape(_fmt(c))}</td>"
                            for c in (row["cells"].get(col) for col in t["columns"]))
            body.append(f"<tr><td data-v=\"{escape(m)}\">{escape(m)}</td>{cells}</tr>")
        return (f"<p>{escape(_header(t)[0])}</p><table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}"
                "</tbody></table>")

    parts = [one(board["main"])] + [f"<h2>Not comparable (different {escape(', '.join(t['differs_in']))})</h2>"
                                   + one(t) for t in board["not_comparable"]]
    return ("<!doctype html><html><head><meta charset=\"utf-8\"><title>WorldSimProbe leaderboard</title><style>"
            "body{font-family:system-ui,sans-serif;margin:1.5em}table{border-collapse:collapse}"
            "th,td{border:1px solid #ccc;padding:.3em .6em;text-align:right;white-space:nowrap}th{cursor:pointer;background:#f3f3f3}"
            "td:first-child{text-align:left}</style></head><body><h1>WorldSimProbe leaderboard</h1>"
            "<p>Click a column to sort. Cells: rank (\"=\": not significantly different from the model ranked just "
            "above, paired bootstrap), score [95 % CI]; \"*\": a partial Overall (not all of T1–T5 scored).</p>"
            + "".join(parts) +
            "<script>function sortBy(th){const t=th.closest('table'),i=[...th.parentNode.children].indexOf(th),"
            "b=t.tBodies[0],r=[...b.rows],num=i>0;r.sort((x,y)=>{const a=x.cells[i].dataset.v,c=y.cells[i].dataset.v;"
            "return num?(+c)-(+a):a.localeCompare(c)});r.forEach(x=>b.appendChild(x));}</script></body></html>\n")


def write(board: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "leaderboard.json").write_text(json.dumps(board, indent=1))
    (out / "leaderboard.md").write_text(markdown(board))
    (out / "leaderboard.html").write_text(html(board))
