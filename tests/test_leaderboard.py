"""`wsp leaderboard` over real score reports of calibration baselines on the shared tiny ManiSkill release.

The oracle (the references themselves) must rank first on T2–T4, where it scores 100, and the static baseline
below it; an identical copy of a report under another model name differs by exactly 0 on every instance, so it
must be marked tied in every column (a paired bootstrap interval of [0, 0] contains 0); a report made against
another release goes to its own table. The HTML is sorted by clicking in real headless Chromium.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wsp_eval.cli import main
from wsp_eval.baselines import write_baseline


@pytest.fixture(scope="module")
def reports(suites_release, tmp_path_factory):
    root = tmp_path_factory.mktemp("leaderboard")
    out = {}
    for name in ("oracle", "static"):
        write_baseline(name, suites_release, root / "subs" / name, seeds=(0,))
        assert main(["score", str(root / "subs" / name), "--release", str(suites_release), "--out",
                     str(root / name), "--quiet"]) == 0
        out[name] = root / name
    twin = json.loads((out["oracle"] / "report.json").read_text())
    twin["submission"]["model"] = "oracle-twin"
    (root / "twin").mkdir()
    (root / "twin" / "report.json").write_text(json.dumps(twin))
    out["twin"] = root / "twin"
    other = json.loads((out["static"] / "report.json").read_text())
    other["submission"]["model"] = "static-elsewhere"
    other["release"]["release_json_sha256"] = "0" * 64
    (root / "other").mkdir()
    (root / "other" / "report.json").write_text(json.dumps(other))
    out["other"] = root / "other"
    out["fewer"] = _without_t4(out["static"], "static-without-t4", root / "fewer")  # the same release, less T4
    return out


def _without_t4(report: Path, model: str, out: Path) -> Path:
    """A copy of a real report under another model name, as if its submission had not been made for T4."""
    r = json.loads((report / "report.json").read_text())
    r["submission"]["model"] = model
    del r["platforms"]["maniskill"]["suites"]["t4"], r["release"]["configs"]["t4_maniskill"]
    r["instances"] = [x for x in r["instances"] if x["config"] != "t4_maniskill"]
    out.mkdir()
    (out / "report.json").write_text(json.dumps(r))
    return out


def test_ranks_ties_and_separate_tables(reports, tmp_path, capsys):
    out = tmp_path / "lb"
    assert main(["leaderboard", str(reports["oracle"]), str(reports["static"]), str(reports["twin"]),
                 str(reports["other"]), "--out", str(out)]) == 0
    assert "not comparable" in capsys.readouterr().out.lower()
    board = json.loads((out / "leaderboard.json").read_text())
    main_rows = board["main"]["rows"]
    assert set(main_rows) == {"baseline:oracle", "baseline:static", "oracle-twin"}
    for col in ("maniskill t2", "maniskill t3", "maniskill t4"):
        oracle, static, twin = (main_rows[m]["cells"][col] for m in ("baseline:oracle", "baseline:static", "oracle-twin"))
        assert oracle["score"] > static["score"] and static["rank"] == 3
        assert {oracle["rank"], twin["rank"]} == {1} and (oracle["tied_with_above"] or twin["tied_with_above"])
    twin_cells = main_rows["oracle-twin"]["cells"]
    assert all(c["rank"] == main_rows["baseline:oracle"]["cells"][k]["rank"] for k, c in twin_cells.items())
    [apart] = board["not_comparable"]
    assert apart["differs_in"] == ["release"] and list(apart["rows"]) == ["static-elsewhere"]
    md = (out / "leaderboard.md").read_text()
    assert "1=." in md and "release.json sha256" in md
    assert main_rows["baseline:oracle"]["cells"]["maniskill overall"]["partial"]  # no T1 in this release: marked *
    assert "100.0* [" in md


def test_reports_of_another_scoring_version_or_lossy_scoring_go_apart(reports, tmp_path):
    from wsp_eval.score import ENCODING_OFF

    paths = [reports["oracle"]]
    for name, change in (("older", {"scoring_version": 1}), ("lossy", {"encoding_check": ENCODING_OFF})):
        report = {**json.loads((reports["static"] / "report.json").read_text()), **change}
        report["submission"]["model"] = name
        (tmp_path / name).mkdir()
        (tmp_path / name / "report.json").write_text(json.dumps(report))
        paths.append(tmp_path / name)
    assert main(["leaderboard", *map(str, paths), "--out", str(tmp_path / "lb")]) == 0
    board = json.loads((tmp_path / "lb" / "leaderboard.json").read_text())
    assert list(board["main"]["rows"]) == ["baseline:oracle"]
    assert sorted((t["differs_in"], list(t["rows"])) for t in board["not_comparable"]) == [
        (["encoding check"], ["lossy"]), (["scoring version"], ["older"])]


def test_a_report_of_fewer_configs_of_the_same_release_is_ranked_beside_the_others(reports, tmp_path):
    out = tmp_path / "lb"
    assert main(["leaderboard", str(reports["oracle"]), str(reports["fewer"]), "--out", str(out)]) == 0
    board = json.loads((out / "leaderboard.json").read_text())
    assert board["not_comparable"] == [] and set(board["main"]["rows"]) == {"baseline:oracle", "static-without-t4"}
    cells = board["main"]["rows"]["static-without-t4"]["cells"]
    assert "maniskill t4" not in cells and cells["maniskill t2"]["rank"] == 2
    twin = _without_t4(reports["oracle"], "oracle-without-t4", tmp_path / "twin")  # the oracle's scores, less T4
    assert main(["leaderboard", str(reports["oracle"]), str(twin), "--out", str(tmp_path / "lb2")]) == 0
    rows = json.loads((tmp_path / "lb2" / "leaderboard.json").read_text())["main"]["rows"]
    cells = rows["oracle-without-t4"]["cells"]
    assert cells["maniskill t2"]["tied_with_above"]  # identical scores on a config both scored
    # its Overall averages fewer suites than the oracle's, equal on every shared one: ranked by score, not tied
    assert not cells["maniskill overall"]["tied_with_above"] and cells["maniskill overall"]["rank"] == 2


def test_refuses_bad_input(reports, tmp_path, capsys):
    assert main(["leaderboard", str(tmp_path / "nope"), "--out", str(tmp_path / "x")]) == 2
    assert "not a `wsp score` report" in capsys.readouterr().err
    assert main(["leaderboard", str(reports["oracle"]), str(reports["oracle"]), "--out", str(tmp_path / "y")]) == 2
    assert "one report per model" in capsys.readouterr().err


def test_html_sorts_in_a_browser(reports, tmp_path):
    from selenium.webdriver.common.by import By

    from test_teleop import _browser

    out = tmp_path / "lb"
    assert main(["leaderboard", str(reports["static"]), str(reports["oracle"]), "--out", str(out)]) == 0
    driver = _browser()
    try:
        driver.get((out / "leaderboard.html").as_uri())
        overall, suites = (driver.find_element(By.CSS_SELECTOR, f"table.{c}") for c in ("overall", "suites"))
        assert [h.text for h in overall.find_elements(By.CSS_SELECTOR, "thead th")] == [
            "model", "macro average", "maniskill Overall"]  # the headline first: macro, then each platform
        assert [h.text for h in suites.find_elements(By.CSS_SELECTOR, "th.platform")] == ["maniskill"]

        def first(table) -> str:
            return table.find_elements(By.CSS_SELECTOR, "tbody tr")[0].find_elements(By.TAG_NAME, "td")[0].text

        t2 = suites.find_element(By.CSS_SELECTOR, 'th[data-col="maniskill t2"]')
        assert t2.text == "T2"  # under its platform's grouped header
        t2.click()
        assert first(suites) == "baseline:oracle"  # sorted by T2, best first
        suites.find_element(By.CSS_SELECTOR, 'th[data-col="model"]').click()
        assert first(suites) == "baseline:oracle"  # by name: "baseline:oracle" < "baseline:static"
        overall.find_element(By.CSS_SELECTOR, 'th[data-col="macro overall"]').click()
        assert first(overall) == "baseline:oracle"
        driver.save_screenshot(str(tmp_path / "leaderboard.png"))
    finally:
        driver.quit()


def test_report_shows_the_worst_instances(reports):
    """The static baseline's report (scored in the fixture) holds frame strips of its worst instances per config,
    generated above reference, with the evidence that decided each (T4: d and the gate; T5: the judge's verdict)."""
    import cv2

    folder = reports["static"]
    report = json.loads((folder / "report.json").read_text())
    strips = report["strips"]
    assert {s["config"] for s in strips} == {"t2_maniskill", "t3_maniskill", "t4_maniskill", "t5_maniskill"}
    by_config = {}
    for s in strips:
        by_config.setdefault(s["config"], []).append(s)
        image = cv2.imread(str(folder / s["image"]))
        assert image is not None and image.shape[0] > image.shape[1] / 6 * 2 - 1  # two rows of six tiles
    scores = {(r["config"], r["instance_id"]): r["score"] for r in report["instances"]}
    for config, items in by_config.items():
        worst = sorted(v for (c, _), v in scores.items() if c == config)[:len(items)]
        assert [scores[(config, s["instance_id"])] for s in items] == worst  # the lowest-scoring, in order
    assert any("arm gate failed" in s["evidence"] for s in by_config["t4_maniskill"])  # static: the arm never moves
    assert all("judged" in s["evidence"] for s in by_config["t5_maniskill"])
    assert all("per 2 s window" in s["evidence"] for s in by_config["t2_maniskill"])
    page = (folder / "report.html").read_text()
    assert all(f'src="{s["image"]}"' in page for s in strips) and "Worst-scoring instances" in page


def _synthetic(model: str, scores: dict[str, dict[str, float]]) -> dict:
    """A report of per-platform suite and Overall scores only (no instances: every rank is a tie)."""
    platforms = {p: {"overall": {"score": s["overall"], "ci": None},
                     "suites": {k: {"score": v, "ci": None, "config": f"{k}_{p}"} for k, v in s.items()
                                if k != "overall"}} for p, s in scores.items()}
    macro = float(np.mean([s["overall"] for s in scores.values()]))
    return {"submission": {"model": model}, "platforms": platforms, "instances": [],
            "macro_average": {"score": macro, "ci": None}, "release": {"release_json_sha256": "a" * 64}}


def test_ranking_consistency(tmp_path):
    """Spearman ρ per pair of platforms against SciPy's on the same scores; the note under four models."""
    from scipy.stats import spearmanr

    rng = np.random.default_rng(3)
    platforms = ("aloha", "libero", "maniskill")
    scores = {f"m{k}": {p: {"overall": float(rng.uniform(0, 100)), "t2": float(rng.uniform(0, 100))}
                        for p in platforms} for k in range(5)}
    paths = []
    for m, s in scores.items():
        (tmp_path / m).mkdir()
        (tmp_path / m / "report.json").write_text(json.dumps(_synthetic(m, s)))
        paths.append(tmp_path / m)
    assert main(["leaderboard", *map(str, paths), "--out", str(tmp_path / "lb")]) == 0
    c = json.loads((tmp_path / "lb" / "leaderboard.json").read_text())["main"]["consistency"]
    assert c["note"] is None and len(c["pairs"]) == 3
    for pair in c["pairs"]:
        a, b = pair["platforms"]
        for suite in ("overall", "t2"):
            expected = spearmanr([scores[m][a][suite] for m in scores], [scores[m][b][suite] for m in scores])[0]
            assert pair["suites"][suite]["spearman"] == pytest.approx(expected, abs=1e-12)
            assert pair["suites"][suite]["meaningful"] and pair["suites"][suite]["models"] == 5
    overall = [p["suites"]["overall"]["spearman"] for p in c["pairs"]]
    assert c["mean_pairwise_overall"] == pytest.approx(np.mean(overall))
    page = (tmp_path / "lb" / "leaderboard.html").read_text()
    assert "Ranking consistency" in page and page.index("macro average") < page.index("Suites per platform")
    assert main(["leaderboard", *map(str, paths[:3]), "--out", str(tmp_path / "few")]) == 0
    few = json.loads((tmp_path / "few" / "leaderboard.json").read_text())["main"]["consistency"]
    assert "at least 4" in few["note"] and not few["pairs"][0]["suites"]["overall"]["meaningful"]
    assert "†" in (tmp_path / "few" / "leaderboard.md").read_text()

    (tmp_path / "two").mkdir()  # a model of two platforms: in the table, its macro average marked partial
    two = {p: {"overall": 50.0, "t2": 50.0} for p in ("libero", "maniskill")}
    (tmp_path / "two" / "report.json").write_text(json.dumps(_synthetic("two-platforms", two)))
    assert main(["leaderboard", *map(str, paths), str(tmp_path / "two"), "--out", str(tmp_path / "six")]) == 0
    six = json.loads((tmp_path / "six" / "leaderboard.json").read_text())["main"]
    assert six["rows"]["two-platforms"]["cells"]["macro overall"]["partial"]
    assert not any(r["cells"]["macro overall"]["partial"] for m, r in six["rows"].items() if m != "two-platforms")
    models = {tuple(p["platforms"]): p["suites"]["overall"]["models"] for p in six["consistency"]["pairs"]}
    assert models == {("aloha", "libero"): 5, ("aloha", "maniskill"): 5, ("libero", "maniskill"): 6}
