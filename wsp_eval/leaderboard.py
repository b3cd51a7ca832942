"""`wsp leaderboard`: models × (platform, suite, Overall) from any number of score reports (`wsp score`).

Comparable reports only: the main table holds the reports made against the same release (`release.json` checksum,
and the same fingerprint, `wsp_eval.integrity`, for every config both scored), benchmark version, evaluators
(backend names and versions), scoring version and encoding check (`--accept-lossy` or not) as the first one given;
every other report goes to a table of its own, headed by what differs, never mixed in. A report of some of the
release's platforms (a model of one robot) has cells for those; its macro average, over fewer platforms than the
table's, is marked partial. Scores and 95 % CIs are the reports' own. **Ties**: within each column the models are
ranked by score, and a model whose difference to the one ranked just above it is not significant shares its rank
("=") — a paired bootstrap over the instances both reports scored (`BOOTSTRAP` resamples, seeded; T5 resampled
within primitives as its score is), the difference's 95 % interval containing 0. Overall and macro differences
resample every suite at once, as their CIs do. An Overall or macro average over other configs than the one ranked
just above it is ranked by its score alone and never marked "=" (paired differences do not compare means over
different configs).

**Ranking consistency**: per pair of platforms, Spearman's ρ between the models' Overall scores on the two (the
models scored on both; ρ of scores is ρ of their ranks), and per suite both platforms have; the mean over the
pairs is the paper's "mean pairwise Spearman ρ". With fewer than `MIN_MODELS` models a ρ is recorded but marked
not meaningful (two models give ±1, three only four values).

The page reads as a leaderboard: first the macro average and each platform's Overall, then every platform's suites
under its own header (HTML: one table, platforms as grouped column headers; Markdown: one table per platform).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from html import escape
from pathlib import Path

import numpy as np

from wsp_eval.release_format import split_config
from wsp_eval.score import bootstrap_means
from wsp_eval.studies.agreement import spearman
from wsp_eval.studies.stats import interval_text
from wsp_eval.suites import SCORERS

BOOTSTRAP = 2000
DIFFERS = ("release", "benchmark version", "evaluators", "scoring version", "encoding check",  # `Entry.key`'s parts
           "release files scored")
SEED = 0
MIN_MODELS = 4  # fewer models than this make a rank correlation meaningless


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
        return (rel.get("release_json_sha256"), rel.get("version"), backends, self.report.get("scoring_version"),
                self.report.get("encoding_check"))

    @property
    def fingerprints(self) -> dict[str, str | None]:
        return {c: v.get("fingerprint") for c, v in self.report.get("release", {}).get("configs", {}).items()}

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


def _scored(entry: Entry, platform: str) -> set[str]:
    """The configs a report's Overall (of `platform`) or macro average (`platform` "macro") is the mean over."""
    return {c for p in entry.report["platforms"] if platform in (p, "macro") for c in _configs(entry, p)}


def tied(a: Entry, b: Entry, platform: str, suite: str) -> bool:
    """Whether a and b do not differ significantly in this column (paired bootstrap, module docstring)."""
    rng = np.random.default_rng(SEED)
    if suite != "overall":
        config = a.report["platforms"][platform]["suites"][suite]["config"]
        diffs = _suite_diffs(a, b, config, rng)
    else:
        platforms = [platform] if platform != "macro" else sorted(a.report["platforms"])
        if _scored(a, platform) != _scored(b, platform):
            return False  # means over different configs: ranked by score alone, never marked "="
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
    platforms = {p for p, _ in cols if p != "macro"}
    rows = {e.model: {"report": e.path, "cells": {}} for e in entries}
    for platform, suite in cols:
        have = [(e, c) for e in entries if (c := _cell(e, platform, suite)) and c.get("score") is not None]
        have.sort(key=lambda x: -x[1]["score"])
        rank = 0
        for k, (e, c) in enumerate(have):
            tie = k > 0 and tied(have[k - 1][0], e, platform, suite)
            rank = rank if tie else k + 1
            partial = (c.get("complete") is False if platform != "macro"
                       else set(e.report["platforms"]) < platforms)
            rows[e.model]["cells"][f"{platform} {suite}"] = {"score": c["score"], "ci": c.get("ci"), "rank": rank,
                                                             "tied_with_above": tie, "partial": partial}
    first = entries[0].report
    t = {"columns": [f"{p} {s}" for p, s in cols], "rows": rows,
         "release": first.get("release", {}), "backends": first.get("backends", {}),
         "benchmark_version": first.get("release", {}).get("version")}
    t["consistency"] = consistency(t)
    return t


def consistency(t: dict) -> dict:
    """Per pair of platforms, Spearman ρ between the models' scores on them, Overall and per shared suite."""
    cols = [c.split(" ", 1) for c in t["columns"]]
    platforms = sorted({p for p, _ in cols if p != "macro"})
    pairs = []
    for i, a in enumerate(platforms):
        for b in platforms[i + 1:]:
            suites = [s for p, s in cols if p == a and [b, s] in cols]
            per = {}
            for suite in sorted(suites, key=lambda s: (s == "overall", s)):
                both = [r["cells"] for r in t["rows"].values() if f"{a} {suite}" in r["cells"]
                        and f"{b} {suite}" in r["cells"]]
                rho = spearman([c[f"{a} {suite}"]["score"] for c in both], [c[f"{b} {suite}"]["score"] for c in both])
                per[suite] = {"spearman": rho, "models": len(both), "meaningful": len(both) >= MIN_MODELS}
            pairs.append({"platforms": [a, b], "suites": per})
    overall = [p["suites"]["overall"]["spearman"] for p in pairs if p["suites"].get("overall", {}).get("spearman")
               is not None]
    n = len(t["rows"])
    note = (None if n >= MIN_MODELS else
            f"{n} model{'s' if n != 1 else ''}: a rank correlation needs at least {MIN_MODELS} to mean anything")
    return {"pairs": pairs, "mean_pairwise_overall": float(np.mean(overall)) if overall else None, "note": note}


def build(paths: list[Path]) -> dict:
    """The leaderboard: the main comparable table and, apart, any report that is not comparable with it."""
    entries = load(paths)
    models = [e.model for e in entries]
    dupes = sorted({m for m in models if models.count(m) > 1})
    if dupes:
        raise LeaderboardError(f"more than one report of model(s) {', '.join(dupes)}: give one report per model")
    first = entries[0]
    main_files: dict[str, str | None] = {}  # the fingerprint of every config the main table's reports scored
    groups: dict[tuple, list[Entry]] = {}
    for e in entries:  # a report of the main table's release must have its content in every config it scored
        same_files = e.key != first.key or all(main_files.get(c, f) == f for c, f in e.fingerprints.items())
        if same_files and e.key == first.key:
            main_files.update(e.fingerprints)
        groups.setdefault((*e.key, same_files), []).append(e)
    main_key = (*first.key, True)
    apart = []
    for key, members in groups.items():
        if key == main_key:
            continue
        why = [w for w, x, y in zip(DIFFERS, key, main_key) if x != y]
        apart.append({"differs_in": why, **table(members)})
    return {"main": table(groups[main_key]), "not_comparable": apart}


def _fmt(cell: dict | None) -> str:
    if not cell:
        return "—"
    partial = "*" if cell.get("partial") else ""
    tie = "=" if cell["tied_with_above"] else ""
    return f"{cell['rank']}{tie}. {cell['score']:.1f}{partial}{interval_text(cell.get('ci'), '.1f')}"


def _header(t: dict) -> list[str]:
    rel, be = t["release"], t["backends"]
    return [f"Release {rel.get('path', '?')} (release.json sha256 {str(rel.get('release_json_sha256'))[:12]}), "
            f"benchmark {t['benchmark_version']}; evaluators: "
            + ", ".join(f"{r} {b['name']} ({b['version']})" for r, b in sorted(be.items()))]


def _order(t: dict) -> list[str]:
    """Models, best macro average first (models without one last)."""
    return sorted(t["rows"], key=lambda m: -(t["rows"][m]["cells"].get("macro overall", {}).get("score") or -1))


def _groups(t: dict) -> tuple[list[str], dict[str, list[str]]]:
    """The headline columns (macro, then each platform's Overall) and, per platform, its suite columns."""
    headline = ["macro overall"] + [c for c in t["columns"] if c.endswith(" overall") and c != "macro overall"]
    suites: dict[str, list[str]] = {}
    for c in t["columns"]:
        platform, suite = c.split(" ", 1)
        if suite != "overall":
            suites.setdefault(platform, []).append(c)
    return headline, suites


def _consistency_suites(c: dict) -> list[str]:
    return sorted({s for p in c["pairs"] for s in p["suites"]}, key=lambda s: (s != "overall", s))


def _consistency_title(c: dict) -> str:
    mean = c["mean_pairwise_overall"]
    return ("Ranking consistency (Spearman ρ between the models' scores on two platforms"
            + (f"; mean pairwise Overall ρ {mean:.3f}" if mean is not None else "") + "):")


def _consistency_lines(c: dict) -> list[str]:
    if not c["pairs"]:
        return []
    suites = _consistency_suites(c)
    lines = [_consistency_title(c), "", "| platforms | " + " | ".join(suites) + " |", "|---|" + "---|" * len(suites)]
    for p in c["pairs"]:
        cells = " | ".join(_rho(p["suites"].get(s)) for s in suites)
        lines.append(f"| {' – '.join(p['platforms'])} | {cells} |")
    return lines + (["", f"Note: {c['note']}."] if c["note"] else [])


def _rho(cell: dict | None) -> str:
    if not cell or cell["spearman"] is None:
        return "—"
    return f"{cell['spearman']:.2f}{'' if cell['meaningful'] else '†'} ({cell['models']})"


LEGEND = ("Cells: rank (\"=\": not significantly different from the model ranked just above, paired bootstrap), "
          "score [95 % CI]; \"*\": partial, an Overall without all of T1–T5 or a macro average without every "
          "platform of the table. Ranking consistency: ρ (models compared); \"†\": fewer than 4 models, not "
          "meaningful.")


def markdown(board: dict) -> str:
    def table(t: dict, columns: list[str], names: list[str]) -> list[str]:
        lines = ["| model | " + " | ".join(names) + " |", "|---|" + "---|" * len(columns)]
        for m in _order(t):
            lines.append(f"| {m} | " + " | ".join(_fmt(t["rows"][m]["cells"].get(c)) for c in columns) + " |")
        return lines

    def one(t: dict) -> list[str]:
        headline, suites = _groups(t)
        lines = _header(t) + ["", "Overall:", ""] + table(t, headline, _headline_names(headline))
        for platform, cols in suites.items():
            lines += ["", f"{platform}:", ""] + table(t, cols, [c.split(" ", 1)[1] for c in cols])
        return lines + ([""] + _consistency_lines(t["consistency"]) if t["consistency"]["pairs"] else [])

    out = [LEGEND, ""] + one(board["main"])
    for t in board["not_comparable"]:
        out += ["", f"Not comparable with the table above (different {', '.join(t['differs_in'])}):", ""] + one(t)
    return "\n".join(out) + "\n"


def _th(label: str, col: str, attrs: str = "") -> str:
    """A sortable header cell of column `col`."""
    return f"<th data-col=\"{escape(col)}\" onclick=\"sortBy(this)\"{attrs}>{escape(label)}</th>"


def _body(t: dict, columns: list[str]) -> str:
    rows = []
    for m in _order(t):
        cells = "".join(f"<td data-col=\"{escape(col)}\" data-v=\"{c['score'] if c else -1}\">{escape(_fmt(c))}</td>"
                        for col, c in ((col, t["rows"][m]["cells"].get(col)) for col in columns))
        rows.append(f"<tr><td data-col=\"model\" data-v=\"{escape(m)}\">{escape(m)}</td>{cells}</tr>")
    return f"<tbody>{''.join(rows)}</tbody>"


def _headline_names(headline: list[str]) -> list[str]:
    return ["macro average" if c == "macro overall" else c.replace(" overall", " Overall") for c in headline]


def _html_overall(t: dict, headline: list[str]) -> str:
    names = _headline_names(headline)
    head = _th("model", "model") + "".join(_th(n, c) for n, c in zip(names, headline))
    return f"<table class=\"overall\"><thead><tr>{head}</tr></thead>{_body(t, headline)}</table>"


def _html_suites(t: dict, suites: dict[str, list[str]]) -> str:
    cols = [c for cs in suites.values() for c in cs]
    if not cols:
        return ""
    groups = "".join(f"<th colspan=\"{len(cs)}\" class=\"platform\">{escape(p)}</th>" for p, cs in suites.items())
    names = "".join(_th(c.split(" ", 1)[1].upper(), c) for c in cols)
    return (f"<h2>Suites per platform</h2><table class=\"suites\"><thead><tr>{_th('model', 'model', ' rowspan=\"2\"')}"
            f"{groups}</tr><tr>{names}</tr></thead>{_body(t, cols)}</table>")


def _html_consistency(c: dict) -> str:
    if not c["pairs"]:
        return ""
    suites = _consistency_suites(c)
    rows = "".join(f"<tr><td>{escape(' – '.join(p['platforms']))}</td>"
                   + "".join(f"<td>{escape(_rho(p['suites'].get(s)))}</td>" for s in suites) + "</tr>"
                   for p in c["pairs"])
    note = f"<p class=\"note\">Note: {escape(c['note'])}.</p>" if c["note"] else ""
    return (f"<h2>Ranking consistency</h2><p>{escape(_consistency_title(c))}</p><table class=\"consistency\"><thead>"
            "<tr><th>platforms</th>" + "".join(f"<th>{escape(s)}</th>" for s in suites)
            + f"</tr></thead><tbody>{rows}</tbody></table>{note}")


def html(board: dict) -> str:
    def one(t: dict) -> str:
        headline, suites = _groups(t)
        return (f"<p>{escape(_header(t)[0])}</p>{_html_overall(t, headline)}{_html_suites(t, suites)}"
                f"{_html_consistency(t['consistency'])}")

    parts = [one(board["main"])] + [f"<h2>Not comparable (different {escape(', '.join(t['differs_in']))})</h2>"
                                   + one(t) for t in board["not_comparable"]]
    return ("<!doctype html><html><head><meta charset=\"utf-8\"><title>WorldSimProbe leaderboard</title><style>"
            "body{font-family:system-ui,sans-serif;margin:1.5em}table{border-collapse:collapse;margin-bottom:1em}"
            "th,td{border:1px solid #ccc;padding:.3em .6em;text-align:right;white-space:nowrap}"
            "th{cursor:pointer;background:#f3f3f3}th.platform{text-align:center;cursor:default;background:#e6e9f5}"
            "td:first-child{text-align:left}</style></head><body><h1>WorldSimProbe leaderboard</h1>"
            f"<p>Click a column to sort. {escape(LEGEND)}</p>" + "".join(parts) +
            "<script>function sortBy(th){const t=th.closest('table'),col=th.dataset.col,b=t.tBodies[0],r=[...b.rows],"
            "num=col!=='model',v=x=>x.querySelector('td[data-col=\"'+col+'\"]').dataset.v;"
            "r.sort((x,y)=>num?(+v(y))-(+v(x)):v(x).localeCompare(v(y)));r.forEach(x=>b.appendChild(x));}"
            "</script></body></html>\n")


def write(board: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "leaderboard.json").write_text(json.dumps(board, indent=1))
    (out / "leaderboard.md").write_text(markdown(board))
    (out / "leaderboard.html").write_text(html(board))
