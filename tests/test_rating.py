"""`wsp rate` in real headless Chromium (scripted ratings through the page's buttons and keys), resuming, and
`wsp study agreement` on the saved ratings against real score reports of two calibration baselines.

Needs the Debian packages `chromium` and `chromium-driver` and the pip package `selenium` (the project setup
installs them). The agreement numbers are checked against SciPy's `spearmanr` on the same pairs (to 1e-9): ratings
that follow the scores' order give a positive ρ and full binary agreement (the oracle scores ≥ 50 and is rated
≥ 3, the static baseline below both), the reversed ratings the opposite ρ.
"""

from __future__ import annotations

import json
import threading
import urllib.error
import urllib.request

import pytest

from test_teleop import _browser, _wait
from wsp_eval.cli import main
from wsp_eval.baselines import write_baseline
from wsp_eval.studies.rating import RatingServer, RatingSession, collect_items


@pytest.fixture(scope="module")
def driver():
    d = _browser()
    yield d
    d.quit()


@pytest.fixture(scope="module")
def subs(suites_release, tmp_path_factory):
    root = tmp_path_factory.mktemp("rating-subs")
    out = {}
    for name in ("oracle", "static"):
        write_baseline(name, suites_release, root / name, seeds=(0,))
        out[name] = root / name
    return out


def _serve(session):
    srv = RatingServer(session, 0)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    return srv, thread


def _stop(srv, thread):
    srv.shutdown()
    srv.server_close()
    thread.join(10)


def _get(url: str):
    try:
        with urllib.request.urlopen(url, timeout=30) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def _post(url: str, body: bytes):
    req = urllib.request.Request(url, body, {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def test_page_rates_blind_in_random_order_and_resumes(driver, suites_release, subs, tmp_path):
    from selenium.webdriver.common.by import By

    items, skipped = collect_items(suites_release, [subs["oracle"], subs["static"]], ("t2",))
    assert len(items) == 6 and not skipped  # 3 T2 instances × 2 submissions × seed 0
    out = tmp_path / "ratings"
    srv, thread = _serve(RatingSession(suites_release, items, out, "Ann Example"))
    try:
        driver.get(srv.url)
        first = _wait(lambda: driver.find_element(By.TAG_NAME, "body").get_attribute("data-item"), what="first item")
        # both videos decoded and drawn: the canvases hold non-blank pixels
        drawn = "return (() => { const c = document.getElementById(arguments[0]); const d = c.getContext('2d')" \
                ".getImageData(0, 0, c.width, c.height).data; let s = 0; for (let i = 0; i < d.length; i += 4) s += d[i];" \
                " return s > 0; })()"
        _wait(lambda: driver.execute_script(drawn, "generated") and driver.execute_script(drawn, "reference"),
              what="both videos drawn")
        html = driver.page_source
        assert "baseline:" not in html and "oracle" not in html and "static" not in html  # model identity hidden
        order = [first]
        for k in range(3):  # three ratings through the buttons, then stop
            driver.find_element(By.CSS_SELECTOR, f'[data-rating="{k + 2}"]').click()
            order.append(_wait(lambda: (v := driver.find_element(By.TAG_NAME, "body").get_attribute("data-item"))
                               != order[-1] and v, what="next item"))
        assert "3 of 6 rated" in driver.find_element(By.ID, "progress").text
    finally:
        _stop(srv, thread)
    saved = [json.loads(line) for line in (out / "ratings_Ann_Example.jsonl").read_text().splitlines()]
    assert [r["item_id"] for r in saved] == order[:3] and [r["rating"] for r in saved] == [2, 3, 4]
    assert {r["annotator"] for r in saved} == {"Ann Example"} and all(r["model"].startswith("baseline:") for r in saved)
    # another annotator sees another order; the same one resumes where they stopped
    assert [i.item_id for i in RatingSession(suites_release, items, out, "Bo").items] != \
        [i.item_id for i in RatingSession(suites_release, items, out, "Ann Example").items]
    srv, thread = _serve(RatingSession(suites_release, items, out, "Ann Example"))
    try:
        driver.get(srv.url)
        assert _wait(lambda: driver.find_element(By.TAG_NAME, "body").get_attribute("data-item"),
                     what="resumed item") == order[3]
        from selenium.webdriver.common.keys import Keys

        for _ in range(3):
            current = driver.find_element(By.TAG_NAME, "body").get_attribute("data-item")
            driver.find_element(By.TAG_NAME, "body").send_keys("5")
            _wait(lambda: driver.find_element(By.TAG_NAME, "body").get_attribute("data-item") != current
                  or driver.find_element(By.ID, "done").is_displayed(), what="rated by key")
        _wait(lambda: driver.find_element(By.ID, "done").is_displayed(), what="done message")
        assert Keys  # keys 1–5 rate (the page's documented shortcut)
    finally:
        _stop(srv, thread)
    assert len((out / "ratings_Ann_Example.jsonl").read_text().splitlines()) == 6


def test_api_refuses_bad_ratings_and_paths(suites_release, subs, tmp_path):
    items, _ = collect_items(suites_release, [subs["oracle"]], ("t2",))
    srv, thread = _serve(RatingSession(suites_release, items, tmp_path / "r", "C"))
    try:
        item = json.loads(_get(srv.url + "state")[1])["item"]["item_id"]
        for body, why in ((json.dumps({"item_id": item, "rating": 6}), "1 to 5"),
                          (json.dumps({"item_id": item, "rating": True}), "1 to 5"),
                          (json.dumps({"item_id": "nope", "rating": 3}), "unknown item"),
                          ("not json", "not JSON"), ("x" * 5000, "too large")):
            status, reply = _post(srv.url + "rate", body.encode())
            assert status == 400 and why in reply["error"], (body[:40], reply)
        assert _get(srv.url + "media/../../etc/passwd")[0] == 404
        assert _get(srv.url + f"media/{'0' * 16}/generated.png")[0] == 400
        status, png = _get(srv.url + f"media/{item}/generated.png")
        assert status == 200 and png[:4] == b"\x89PNG"
    finally:
        _stop(srv, thread)
    assert not (tmp_path / "r" / "ratings_C.jsonl").exists()  # nothing refused was saved


def test_agreement_of_scores_with_ratings(suites_release, subs, tmp_path, capsys):
    reports = []
    for name, sub in subs.items():
        assert main(["score", str(sub), "--release", str(suites_release), "--out", str(tmp_path / name),
                     "--quiet"]) == 0
        reports.append(tmp_path / name)
    capsys.readouterr()
    report = {name: json.loads((tmp_path / name / "report.json").read_text()) for name in subs}
    items, _ = collect_items(suites_release, list(subs.values()), ("t2",))
    score = {(r["config"], r["instance_id"], name): r["seeds"][0]["score"]
             for name in subs for r in report[name]["instances"]}
    ranked = sorted(items, key=lambda it: score[(it.config, it.instance_id, it.model.split(":")[1])])

    def write(folder, ratings):
        folder.mkdir()
        with open(folder / "ratings_A.jsonl", "w") as f:
            for it, rating in zip(ranked, ratings):
                f.write(json.dumps({"model": it.model, "config": it.config, "instance_id": it.instance_id,
                                    "seed": it.seed, "rating": rating, "annotator": "A"}) + "\n")

    from scipy.stats import spearmanr

    scores = [score[(it.config, it.instance_id, it.model.split(":")[1])] for it in ranked]
    assert scores[2] < 50 <= scores[3]  # static below, oracle above: the binary split the ratings follow
    for name, ratings in (("agree", [1, 1, 2, 4, 5, 5]), ("reverse", [5, 5, 4, 2, 1, 1])):
        write(tmp_path / name, ratings)
        assert main(["study", "agreement", "--ratings", str(tmp_path / name), "--reports", *map(str, reports),
                     "--out", str(tmp_path / f"{name}-out")]) == 0
        result = json.loads((tmp_path / f"{name}-out" / "agreement.json").read_text())
        expected = spearmanr(scores, ratings).statistic
        assert result["rollouts"] == 6 and result["groups"]["all"]["spearman"] == pytest.approx(expected, abs=1e-9)
        assert (expected > 0.5 and result["groups"]["all"]["binary_agreement"] == 1.0) if name == "agree" else \
            (expected < -0.5 and result["groups"]["all"]["binary_agreement"] == 0.0)
    assert "Spearman" in capsys.readouterr().out
    assert main(["study", "agreement", "--ratings", str(tmp_path / "none"), "--reports", *map(str, reports)]) == 2
    assert "no ratings_" in capsys.readouterr().err
