"""Reports for people: Markdown, self-contained HTML with inline SVG plots, and the baseline table."""

from __future__ import annotations

import json
import re

from wsp_eval.report import baseline_table, html, markdown, write_reports

EVIL = "<script>alert(1)</script>"
LABELS = ["push", "pull", "drag", "rotate", "shake", "tap", "knock-over", "drop"]


def _suite(title: str, score: float, ci: list[float] | None, n: int, groups: dict | None = None) -> dict:
    suite = {"config": "x", "title": title, "score": score, "ci": ci, "n": n, "missing_rollouts": 0}
    return suite | ({"groups": groups} if groups else {})


def _groups(by: str, names: list, base: float) -> dict:
    return {"by": by, "rows": [{"group": g, "score": base + i, "ci": [base + i - 3, base + i + 3], "n": 10}
                               for i, g in enumerate(names)]}


def _t5(score: float) -> dict:
    suite = _suite("Interaction dynamics", score, [score - 5, score + 5], 16, _groups("primitive", LABELS, 30))
    matrix = [[2 if i == j else 0 for j in range(len(LABELS))] + [i % 2] for i in range(len(LABELS))]
    return suite | {"confusion": {"labels": LABELS, "columns": LABELS + ["unparsed"], "matrix": matrix},
                    "judge_agreement": 0.875}


def make_report(model: str = EVIL) -> dict:
    maniskill = {
        "t1": _suite("Local action calibration", 71.25, [68.0, 74.5], 120,
                     _groups("task", ["PickCube", "Push|Cube"], 70)),
        "t2": _suite("Global trajectory coverage", 55.04, [50.0, 60.0], 100,
                     _groups("mismatch decile", list(range(10, 0, -1)), 40)),  # deciles given out of order
        "t3": _suite("Action-source behaviour preservation", 48.0, None, 1),
        "t4": _suite("Interaction grounding", 80.0, [75.0, 85.0], 90, _groups("kind", ["a", "b", "c"], 60)),
        "t5": _t5(33.33),
    }
    libero = {k: v for k, v in maniskill.items() if k != "t3"}
    libero["t1"] = _suite("Local action calibration", 62.06, [60.0, 64.0], 50) | {"missing_rollouts": 3}
    return {
        "wsp_report_version": 1,
        "submission": {"path": "/subs/<model>", "model": model, "seeds": [0, 1], "hardware": None,
                       "generation_seconds": 12.5},
        "release": {"path": "worldsimprobe", "version": "0.1.0", "code_version": "abc123"},
        "backends": {"flow": {"name": "dis", "version": "opencv 4.12.0"},
                     "judge": {"name": "rules", "version": "1"}},
        "allow_missing": True,
        "platforms": {
            "maniskill": {"overall": {"score": 57.5, "ci": [55.0, 60.0], "suites": list(maniskill), "complete": True},
                          "suites": maniskill},
            "libero": {"overall": {"score": 57.6, "ci": None, "suites": ["t1", "t2", "t4", "t5"], "complete": False},
                       "suites": libero},
        },
        "macro_average": {"score": 57.55, "platforms": ["maniskill", "libero"]},
        "timing": {"seconds": 3.0, "workers": 2, "instances": 4},
        "instances": [{"id": i} for i in range(4)],
    }


def test_write_reports(tmp_path):
    report = make_report()
    paths = write_reports(report, tmp_path / "out")
    assert set(paths) == {"json", "markdown", "html"} and all(p.is_file() for p in paths.values())
    assert json.loads(paths["json"].read_text()) == report
    assert paths["markdown"].read_text() == markdown(report)


def test_html_is_self_contained_escaped_and_plotted():
    page = html(make_report())
    assert not re.search(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//""", page, re.I)
    assert not re.search(r"<(?:link|script|img|iframe)\b", page, re.I)
    assert EVIL not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    # 1 suite chart; groups: maniskill t1 t2 t4 t5 + libero t2 t4 t5; 2 confusion heatmaps
    assert page.count("<svg") == 1 + 7 + 2
    assert "unparsed" in page


def test_markdown_scores_partial_and_breakdowns():
    text = markdown(make_report())
    for score in ("71.2", "55.0", "48.0", "80.0", "33.3", "62.1", "57.5", "57.6"):
        assert score in text
    assert "57.6 (partial: T1, T2, T4, T5)" in text and "57.5 (partial" not in text
    libero = text[text.index("### libero"):text.index("## Cross-platform")]
    assert re.search(r"\| T3 [^|]+ \| — \| — \| — \| — \|", libero)
    assert "| T3 Action-source behaviour preservation | 48.0 | — | 1 | 0 |" in text  # CI None
    assert "Push\\|Cube" in text  # pipes cannot break a table
    deciles = re.findall(r"^\| (\d+) \| ", text, re.M)[:10]
    assert deciles == [str(d) for d in range(1, 11)]
    assert "| intended \\ judged | " + " | ".join(LABELS) + " | unparsed |" in text
    assert "| push | 2 | 0 | 0 | 0 | 0 | 0 | 0 | 0 | 0 |" in text
    assert "0.875" in text and "3 (allowed; libero T1: 3)" in text


def test_baseline_table():
    static = make_report("static")
    del static["platforms"]["libero"]
    table = baseline_table({"oracle": make_report("oracle"), "static": static})
    head, _, *body = [[c.strip() for c in line.strip("|").split("|")] for line in table.splitlines()
                      if line.startswith("|")]
    rows = {row[0]: row[1:] for row in body}
    assert len(body) == 2 and set(rows) == {"oracle", "static"}
    assert head[1:7] == ["maniskill T1", "maniskill T2", "maniskill T3", "maniskill T4", "maniskill T5",
                         "maniskill Overall"] and len(head) == 1 + 2 * 6
    assert rows["oracle"] == ["71.2", "55.0", "48.0", "80.0", "33.3", "57.5",
                              "62.1", "55.0", "—", "80.0", "33.3", "57.6*"]
    assert rows["static"][6:] == ["—"] * 6
    assert "partial Overall" in table


def test_minimal_report_does_not_crash():
    minimal = {"platforms": {"maniskill": {"suites": {"t1": {"score": 50.0}}}}}
    assert "| T1 Local action calibration | 50.0 | — | — | 0 |" in markdown(minimal)
    assert html(minimal).count("<svg") == 1
    assert baseline_table({"m": minimal}).count("—") == 5


def test_a_score_just_outside_its_ci_is_plotted():
    """A balanced mean can fall just outside its bootstrap interval (seen on a T5 config whose every instance scores
    100 but one at 99.99): the chart draws a zero-length bar on that side instead of failing."""
    report = make_report()
    report["platforms"]["maniskill"]["suites"]["t4"] = _suite("Interaction grounding", 100.0, [99.9, 99.99], 16,
                                                              _groups("kind", ["a", "b", "c"], 60))
    assert html(report).count("<svg") == 1 + 7 + 2
