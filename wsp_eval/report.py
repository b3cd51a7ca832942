"""Human reports of a score report (spec §6): Markdown, one self-contained HTML page with inline SVG plots,
and a compact Markdown table comparing several reports (baselines).

Both renderers walk the same list of blocks (`_blocks`), so the Markdown and the HTML hold the same
header and tables; the HTML adds the plots. Every optional key of the report may be absent.
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Sequence
from html import escape
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from wsp_eval.release_format import SCORED_SUITES as SUITES  # noqa: E402

TITLES = {"t1": "Local action calibration", "t2": "Global trajectory coverage",
          "t3": "Action-source behaviour preservation", "t4": "Interaction grounding",
          "t5": "Interaction dynamics"}
DASH = "—"
JUDGE_FALSE_ACCEPT = "49–63 %"  # of generated-video negatives, by platform (docs/validity.md, T5: `wsp study t5-negatives`)
SVG_RC = {"svg.fonttype": "none"}  # text stays text: no font files, small, searchable
SVG_METADATA = {"Date": None, "Creator": None, "Format": None, "Type": None}

Table = tuple[list[str], list[list[str]]]
# Blocks: ("h", level, text) | ("items", [(label, value)]) | ("p", text) | ("table", Table)
#         | ("plot", caption, make_svg)
Block = tuple


# ---------------------------------------------------------------- formatting
def _num(x: float | None) -> str:
    return DASH if x is None else f"{x:.1f}"


def _ci(ci: Sequence[float] | None) -> str:
    return DASH if not ci else f"{ci[0]:.1f}–{ci[1]:.1f}"


def _label(key: str, suite: dict | None = None) -> str:
    return f"{key.upper()} {(suite or {}).get('title') or TITLES.get(key, '')}".strip()


def _platforms(report: dict) -> dict[str, dict]:
    return report.get("platforms") or {}


def _suites(platform: dict) -> dict[str, dict]:
    return platform.get("suites") or {}


def _partial(platform: dict) -> list[str] | None:
    """The suites a partial Overall averages (not all of T1–T5 scored); None when it is complete."""
    overall, suites = platform.get("overall") or {}, _suites(platform)
    included = overall.get("suites") or [k for k in SUITES if (suites.get(k) or {}).get("score") is not None]
    return None if overall.get("complete", set(SUITES) <= set(included)) else included


def _overall_score(platform: dict) -> str:
    score, partial = (platform.get("overall") or {}).get("score"), _partial(platform)
    if score is None or partial is None:
        return _num(score)
    return f"{_num(score)} (partial: {', '.join(k.upper() for k in partial)})"


def _group_rows(groups: dict) -> list[dict]:
    """Group rows in display order: numerically when every group is a number (T2 deciles 1..10)."""
    rows = list(groups.get("rows") or [])
    try:
        return sorted(rows, key=lambda r: float(r["group"]))
    except (TypeError, ValueError):
        return rows


# ---------------------------------------------------------------- tables
def _header(report: dict) -> list[tuple[str, str]]:
    sub, rel = report.get("submission") or {}, report.get("release") or {}
    items = [("Model", str(sub.get("model", DASH))), ("Submission", str(sub.get("path", DASH))),
             ("Release", f"{rel.get('version', DASH)} (code {rel.get('code_version', DASH)}), "
                         f"{rel.get('path', DASH)}")]
    backends = report.get("backends") or {}
    items.append(("Backends", "; ".join(f"{role}: {b.get('name', DASH)} ({b.get('version', DASH)})"
                                        for role, b in backends.items()) or DASH))
    items.append(("Seeds", ", ".join(map(str, sub.get("seeds") or [])) or DASH))
    if sub.get("hardware"):
        items.append(("Hardware", str(sub["hardware"])))
    if sub.get("generation_seconds") is not None:
        items.append(("Generation time", f"{sub['generation_seconds']:.1f} s"))
    server = sub.get("model_server") or {}
    if server:
        seconds = server.get("generation_seconds")
        items.append(("Model server", f"{server.get('model', DASH)} version {server.get('version', DASH)} at "
                                      f"{server.get('url', DASH)}"
                                      + (f", {seconds:.1f} s in the model" if isinstance(seconds, (int, float))
                                         else "")))
    resampled = _resampled(sub.get("resampling") or {})
    if resampled:
        items.append(("Resampled", resampled))
    items.append(("Missing rollouts", _missing(report)))
    if str(report.get("encoding_check", "")).startswith("off"):
        items.append(("Encoding check", f"{report['encoding_check']}: not comparable with lossless submissions"))
    copies = report.get("copy_check") or {}
    if copies.get("probable_copy"):
        items.append(("Copy check", f"PROBABLE COPY OF THE REFERENCES: {copies['equal_to_reference']} of "
                                    f"{copies['videos']} videos equal their reference frame for frame (a model's "
                                    "output never does; the oracle baseline is such a copy by design)"))
    elif copies:
        items.append(("Copy check", f"{copies['equal_to_reference']} of {copies['videos']} videos equal their "
                                    "reference"))
    timing = report.get("timing") or {}
    n = len(report.get("instances") or []) or timing.get("instances")
    if n is not None or timing:
        items.append(("Scored", f"{n if n is not None else DASH} instances"
                      + (f" in {timing['seconds']:.1f} s" if timing.get("seconds") is not None else "")
                      + (f" with {timing['workers']} workers" if timing.get("workers") else "")))
    return items


def _resampled(resampling: dict) -> str:
    """The conversions `wsp generate` made for a model server of another size or frame rate, in words."""
    parts = []
    size, fps = resampling.get("size") or {}, resampling.get("fps") or {}
    if size:
        parts.append(f"generated at {'×'.join(map(str, size.get('model') or []))}, converted from and to "
                     f"{', '.join('×'.join(map(str, s)) for s in size.get('reference') or [])} "
                     f"({size.get('method', DASH)})")
    if fps:
        parts.append(f"generated at {fps.get('model', DASH)} fps, converted from and to "
                     f"{', '.join(map(str, fps.get('release') or []))} fps ({fps.get('method', DASH)})")
    return "; ".join(parts)


def _missing(report: dict) -> str:
    counts = [(f"{p} {k.upper()}", s.get("missing_rollouts") or 0)
              for p, plat in _platforms(report).items() for k, s in _suites(plat).items()]
    total = sum(c for _, c in counts)
    detail = ", ".join(f"{where}: {c}" for where, c in counts if c)
    allowed = "allowed" if report.get("allow_missing") else "not allowed"
    return f"{total} ({allowed}{'; ' + detail if detail else ''})"


def _suite_table(platform: dict) -> Table:
    suites, rows = _suites(platform), []
    for key in SUITES:
        s = suites.get(key)
        rows.append([_label(key, s), DASH, DASH, DASH, DASH] if s is None else
                    [_label(key, s), _num(s.get("score")), _ci(s.get("ci")), str(s.get("n", DASH)),
                     str(s.get("missing_rollouts", 0))])
    overall = platform.get("overall") or {}
    rows.append(["Overall", _overall_score(platform), _ci(overall.get("ci")), "", ""])
    return ["Suite", "Score", "95% CI", "n", "Missing"], rows


def _group_table(groups: dict) -> Table:
    rows = [[str(r.get("group")), _num(r.get("score")), _ci(r.get("ci")), str(r.get("n", DASH))]
            for r in _group_rows(groups)]
    return [str(groups.get("by", "group")), "Score", "95% CI", "n"], rows


def _confusion_table(confusion: dict) -> Table:
    rows = [[label, *map(str, counts)] for label, counts in zip(confusion["labels"], confusion["matrix"])]
    return ["intended \\ judged", *confusion["columns"]], rows


def _macro(report: dict) -> str:
    macro = report.get("macro_average") or {}
    names = macro.get("platforms") or list(_platforms(report))
    partial = [p for p in names if _partial(_platforms(report).get(p) or {}) is not None]
    return (f"{_num(macro.get('score'))} over {', '.join(names) or DASH}"
            + (f" (partial Overall on {', '.join(partial)})" if partial else ""))


# ---------------------------------------------------------------- plots
def _svg(fig: plt.Figure, salt: str) -> str:
    """The figure as an inline <svg> element (no XML prolog); closes the figure."""
    buf = io.StringIO()
    try:
        with matplotlib.rc_context({**SVG_RC, "svg.hashsalt": salt}):  # ids: reproducible, unique per plot
            fig.savefig(buf, format="svg", metadata=SVG_METADATA, bbox_inches="tight")
    finally:
        plt.close(fig)
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _yerr(entries: Sequence[dict]) -> list[list[float]]:
    """Asymmetric error bars from each entry's CI; NaN (no bar) where the CI or score is missing, 0 on a side where
    the score lies outside its CI (a balanced mean can fall just outside its bootstrap interval)."""
    lo, hi = [], []
    for e in entries:
        ok = e.get("ci") and e.get("score") is not None
        lo.append(max(0.0, e["score"] - e["ci"][0]) if ok else math.nan)
        hi.append(max(0.0, e["ci"][1] - e["score"]) if ok else math.nan)
    return [lo, hi]


def _score_axes(ax: plt.Axes, title: str) -> None:
    ax.set_ylim(0, 100)
    ax.set_ylabel("score")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    ax.set_axisbelow(True)


def _suite_plot(report: dict) -> str:
    """Bars per suite with 95% CIs, one group of bars per platform."""
    names = list(_platforms(report))
    fig, ax = plt.subplots(figsize=(max(4.0, 2.2 * len(names) + 1.5), 3.2))
    width = 0.8 / (len(SUITES) + 1)
    for i, key in enumerate((*SUITES, "overall")):
        entries = [(_platforms(report)[p].get("overall") or {}) if key == "overall"
                   else (_suites(_platforms(report)[p]).get(key) or {}) for p in names]
        xs = [j + (i - len(SUITES) / 2) * width for j in range(len(names))]
        heights = [math.nan if e.get("score") is None else e["score"] for e in entries]
        ax.bar(xs, heights, width, yerr=_yerr(entries), capsize=2, label=key.upper() if key in SUITES
               else "Overall", color="0.35" if key == "overall" else None)
    ax.set_xticks(range(len(names)), names)
    _score_axes(ax, "Scores by suite (95% CI)")
    ax.legend(ncols=len(SUITES) + 1, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12),
              frameon=False)
    return _svg(fig, "suites")


def _group_plot(platform: str, key: str, suite: dict) -> str:
    rows = _group_rows(suite["groups"])
    fig, ax = plt.subplots(figsize=(max(4.0, 0.45 * len(rows) + 1.5), 3.0))
    ax.bar(range(len(rows)), [math.nan if r.get("score") is None else r["score"] for r in rows],
           yerr=_yerr(rows), capsize=2, color="tab:blue")
    labels = [str(r.get("group")) for r in rows]
    ax.set_xticks(range(len(rows)), labels, rotation=30 if max(map(len, labels), default=0) > 4 else 0,
                  ha="right" if max(map(len, labels), default=0) > 4 else "center")
    ax.set_xlabel(str(suite["groups"].get("by", "group")))
    _score_axes(ax, f"{platform} · {_label(key, suite)}")
    return _svg(fig, f"{platform}-{key}-groups")


def _confusion_plot(platform: str, confusion: dict) -> str:
    """Annotated heatmap of intended × judged counts (vector cells, not an embedded bitmap)."""
    rows, cols, matrix = confusion["labels"], confusion["columns"], confusion["matrix"]
    fig, ax = plt.subplots(figsize=(0.55 * len(cols) + 2.0, 0.45 * len(rows) + 1.6))
    ax.pcolormesh(matrix, cmap="Blues", edgecolors="white", linewidth=0.5)
    peak = max((max(r) for r in matrix if r), default=0)
    for i, counts in enumerate(matrix):
        for j, c in enumerate(counts):
            ax.text(j + 0.5, i + 0.5, str(c), ha="center", va="center", fontsize=8,
                    color="white" if peak and c > peak / 2 else "black")
    ax.set_xticks([j + 0.5 for j in range(len(cols))], cols, rotation=45, ha="right")
    ax.set_yticks([i + 0.5 for i in range(len(rows))], rows)
    ax.invert_yaxis()
    ax.set_xlabel("judged")
    ax.set_ylabel("intended")
    ax.set_title(f"{platform} · T5 primitive confusion")
    return _svg(fig, f"{platform}-t5-confusion")


# ---------------------------------------------------------------- document
def _blocks(report: dict) -> list[Block]:
    model = (report.get("submission") or {}).get("model", DASH)
    blocks: list[Block] = [("h", 1, f"WorldSimProbe report: {model}"), ("items", _header(report)),
                           ("h", 2, "Scores")]
    for name, plat in _platforms(report).items():
        blocks += [("h", 3, name), ("table", _suite_table(plat))]
    if _platforms(report):
        blocks.append(("plot", "Per-suite scores with 95% CIs", lambda: _suite_plot(report)))
    blocks += [("h", 2, "Cross-platform macro average"), ("p", _macro(report))]
    breakdowns = [b for p, plat in _platforms(report).items() for k, s in sorted(_suites(plat).items())
                  for b in _breakdown(p, k, s)]
    blocks += [("h", 2, "Breakdowns"), *breakdowns] if breakdowns else []
    strips = report.get("strips") or []
    if strips:
        blocks += [("h", 2, "Worst-scoring instances"),
                   ("p", "Per config, the lowest-scoring instances (their lowest-scoring seed): six frames spread over "
                         "the clip, generated above the reference; for T4 and T5 the evaluated object's frame-0 "
                         "position is ringed.")]
        for config in dict.fromkeys(e["config"] for e in strips):
            blocks.append(("h", 3, config))
            for e in (x for x in strips if x["config"] == config):
                blocks.append(("image", e["image"], f"{e['instance_id']} ({e['task']}, seed {e['seed']}, "
                                                    f"{e['role']}): {e['evidence']}"))
    return blocks


def _breakdown(platform: str, key: str, suite: dict) -> list[Block]:
    groups, confusion, agreement = suite.get("groups") or {}, suite.get("confusion"), suite.get("judge_agreement")
    if not (groups.get("rows") or confusion or agreement is not None):
        return []
    blocks: list[Block] = [("h", 3, f"{platform} · {_label(key, suite)}")]
    if groups.get("rows"):
        blocks += [("p", f"By {groups.get('by', 'group')}:"), ("table", _group_table(groups)),
                   ("plot", f"{_label(key, suite)} by {groups.get('by', 'group')}",
                    lambda: _group_plot(platform, key, suite))]
    if suite.get("primitive_recognised") is not None:
        blocks.append(("p", f"Primitive recognised (paper protocol, the label judge; not part of the score): "
                            f"{suite['primitive_recognised']:.1f}. The judge credits {JUDGE_FALSE_ACCEPT} of "
                            "generated-video negatives in which the object does not respond as the simulator's "
                            "(docs/validity.md, T5), so this column is an upper bound."))
    if confusion:
        blocks += [("p", "Confusion matrix of the label judge (rows: intended primitive, columns: judged label):"),
                   ("table", _confusion_table(confusion)),
                   ("plot", "Primitive confusion heatmap", lambda: _confusion_plot(platform, confusion))]
    if agreement is not None:
        blocks.append(("p", f"Label judge agreement with the intended labels on the simulator references: "
                            f"{agreement:.3g}"))
    return blocks


# ---------------------------------------------------------------- Markdown
def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _md_table(table: Table) -> str:
    head, rows = table
    lines = [head, ["---"] * len(head), *rows]
    return "\n".join("| " + " | ".join(map(_md_cell, line)) + " |" for line in lines)


def markdown(report: dict) -> str:
    """The report for people, as Markdown (no plots)."""
    out = []
    for block in _blocks(report):
        match block:
            case ("h", level, text):
                out.append(f"{'#' * level} {text}")
            case ("items", items):
                out.append("\n".join(f"- **{label}:** {value}" for label, value in items))
            case ("p", text):
                out.append(text)
            case ("table", table):
                out.append(_md_table(table))
            case ("image", src, caption):
                out.append(f"![{caption}]({src})\n\n{caption}")
    return "\n\n".join(out) + "\n"


# ---------------------------------------------------------------- HTML
CSS = """
body { font-family: system-ui, sans-serif; max-width: 72rem; margin: 2rem auto; padding: 0 1rem;
       color: #222; line-height: 1.45; }
h1 { font-size: 1.6rem; } h2 { border-bottom: 1px solid #ddd; margin-top: 2rem; } h3 { margin-top: 1.5rem; }
table { border-collapse: collapse; margin: 0.5rem 0 1rem; font-size: 0.92rem; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.6rem; text-align: right; }
th:first-child, td:first-child { text-align: left; }
th { background: #f3f3f3; }
dl { display: grid; grid-template-columns: max-content auto; gap: 0.2rem 1rem; }
dt { font-weight: 600; } dd { margin: 0; word-break: break-all; }
figure { margin: 0.5rem 0 1.5rem; } figcaption { color: #555; font-size: 0.85rem; }
svg { max-width: 100%; height: auto; }
"""


def _html_table(table: Table) -> str:
    head, rows = table
    th = "".join(f"<th>{escape(h)}</th>" for h in head)
    trs = "".join("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{th}</tr></thead><tbody>{trs}</tbody></table>"


def _html_block(block: Block) -> str:
    match block:
        case ("h", level, text):
            return f"<h{level}>{escape(text)}</h{level}>"
        case ("items", items):
            return "<dl>" + "".join(f"<dt>{escape(k)}</dt><dd>{escape(v)}</dd>" for k, v in items) + "</dl>"
        case ("p", text):
            return f"<p>{escape(text)}</p>"
        case ("table", table):
            return _html_table(table)
        case ("plot", caption, make_svg):
            return f"<figure>{make_svg()}<figcaption>{escape(caption)}</figcaption></figure>"
        case ("image", src, caption):
            return (f'<figure><img src="{escape(src)}" alt="{escape(caption)}" style="max-width:100%">'
                    f"<figcaption>{escape(caption)}</figcaption></figure>")
    raise ValueError(f"unknown block {block[0]!r}")


def html(report: dict) -> str:
    """The report for people, as one self-contained HTML page with inline SVG plots."""
    model = (report.get("submission") or {}).get("model", DASH)
    body = "\n".join(map(_html_block, _blocks(report)))
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>WorldSimProbe report: {escape(str(model))}</title>\n<style>{CSS}</style>\n</head>\n"
            f"<body>\n{body}\n</body>\n</html>\n")


# ---------------------------------------------------------------- files and baselines
def write_reports(report: dict, out_dir: Path) -> dict[str, Path]:
    """Write report.json, report.md and report.html into `out_dir`; returns their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"json": out_dir / "report.json", "markdown": out_dir / "report.md", "html": out_dir / "report.html"}
    paths["json"].write_text(json.dumps(report, indent=1, sort_keys=False) + "\n", encoding="utf-8")
    paths["markdown"].write_text(markdown(report), encoding="utf-8")
    paths["html"].write_text(html(report), encoding="utf-8")
    return paths


def baseline_table(reports: dict[str, dict]) -> str:
    """Compact Markdown table: one row per report name, T1..T5 and Overall scores for every platform.
    A partial Overall (not all of T1–T5 scored) carries a `*`, explained under the table."""
    platforms = list(dict.fromkeys(p for r in reports.values() for p in _platforms(r)))
    head = ["model"] + [f"{p} {c}" for p in platforms for c in (*(k.upper() for k in SUITES), "Overall")]
    rows = [[name] + [c for p in platforms for c in _baseline_cells(_platforms(r).get(p))]
            for name, r in reports.items()]
    partial = any(c.endswith("*") for row in rows for c in row[1:])
    return _md_table((head, rows)) + ("\n\n\\* partial Overall: not all of T1–T5 scored" if partial else "")


def _baseline_cells(platform: dict | None) -> list[str]:
    if platform is None:
        return [DASH] * (len(SUITES) + 1)
    score = (platform.get("overall") or {}).get("score")
    mark = "*" if score is not None and _partial(platform) is not None else ""
    return [_num((_suites(platform).get(k) or {}).get("score")) for k in SUITES] + [_num(score) + mark]
