"""The paper's analyses (`wsp study coverage`, `t1-response`, `t2-mismatch`, `t3-sources`, `ordering`,
`idm-train`, `idm`) on the shared tiny releases and real score reports of calibration baselines. Each command writes
its JSON and figure, and its numbers are reproduced here by an independent computation: PCA by the eigenvectors of
the covariance of motions read afresh from the LeRobot data, hull areas by SciPy's Qhull, Spearman's ρ by SciPy on
the stored per-instance scores and the release's mismatch, Kendall's τ by SciPy on the reports' own suite scores, the
compression slope by `np.polyfit`, the T3 gap from the report's records, the IDM's ridge weights by an augmented
least-squares solve.
"""

from __future__ import annotations

import glob
import json
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.spatial import ConvexHull
from scipy.stats import kendalltau, spearmanr

from wsp_eval.baselines import write_baseline
from wsp_eval.cli import main
from wsp_eval.studies.ordering import SuiteScores
from wsp_eval.suites import SCORERS


def _reports(release, root, names) -> dict:
    out = {}
    for name in names:
        write_baseline(name, release, root / "subs" / name, seeds=(0,))
        assert main(["score", str(root / "subs" / name), "--release", str(release), "--out", str(root / name),
                     "--quiet"]) == 0
        out[name] = root / name
    return out


@pytest.fixture(scope="module")
def t1_reports(t1_release, tmp_path_factory):
    return _reports(t1_release, tmp_path_factory.mktemp("t1-reports"), ("oracle", "noise", "static"))


@pytest.fixture(scope="module")
def suites_reports(suites_release, tmp_path_factory):
    return _reports(suites_release, tmp_path_factory.mktemp("suites-reports"), ("oracle", "lag"))


def _rows(release, config) -> dict:
    return {r["instance_id"]: r for r in pq.read_table(release / config / "instances.parquet").to_pylist()}


def _records(report_dir, suite) -> list[dict]:
    return [r for r in json.loads((report_dir / "report.json").read_text())["instances"] if r["suite"] == suite]


def _figure_ok(path) -> None:
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000


def _motion(release, config, episode) -> np.ndarray:
    """The arm motion the coverage study defines, computed here from the LeRobot data without its helpers."""
    names = json.loads((release / config / "meta" / "info.json").read_text())["features"]["observation.state"]["names"]
    arm = [i for i, n in enumerate(names) if "finger" not in n and "gripper" not in n]
    frames = []
    for path in glob.glob(str(release / config / "data" / "*" / "*.parquet")):
        t = pq.read_table(path, columns=["episode_index", "frame_index", "observation.state"]).to_pandas()
        frames += [(f, s) for e, f, s in zip(t["episode_index"], t["frame_index"], t["observation.state"])
                   if e == episode]
    q = np.array([s for _, s in sorted(frames, key=lambda x: x[0])], float)[:, arm]
    q = q - q[0]
    grid = np.linspace(0, 1, 50)
    return np.concatenate([np.interp(grid, np.linspace(0, 1, len(q)), q[:, j])[:, None] for j in range(q.shape[1])],
                          axis=1).ravel()


@pytest.mark.parametrize("name", ["suites_release", "libero_release", "aloha_release"])
def test_coverage(name, request, tmp_path, capsys):
    release = request.getfixturevalue(name)
    assert main(["study", "coverage", "--release", str(release), "--out", str(tmp_path)]) == 0
    assert "beyond expert" in capsys.readouterr().out
    result = json.loads((tmp_path / "coverage.json").read_text())
    _figure_ok(tmp_path / "coverage.png")
    [(platform, p)] = result["platforms"].items()
    members = [(s, q) for s, d in p["sets"].items() for q in d["points"]]
    assert {s for s, _ in members} == {"expert", "counterfactual", "source-diverse"}
    x = np.stack([_motion(release, q["config"], q["episode_index"]) for _, q in members])
    x = x - x.mean(axis=0)
    values, vectors = np.linalg.eigh(np.cov(x.T))
    top = vectors[:, ::-1][:, :2]
    assert np.allclose(values[::-1][:2] / values.sum(), p["explained_variance"], atol=1e-6)
    ours = np.array([q["pc"] for _, q in members])
    for k in range(2):  # the same axes up to sign
        theirs = x @ top[:, k]
        assert np.allclose(np.abs(ours[:, k]), np.abs(theirs), atol=1e-6 * max(1.0, np.abs(theirs).max()))
    for s, d in p["sets"].items():
        pts = np.array([q["pc"] for q in d["points"]])
        if len(pts) >= 3:
            assert d["hull_area"] == pytest.approx(ConvexHull(pts).volume, rel=1e-9)
            assert d["generalised_variance"] == pytest.approx(np.linalg.det(np.cov(pts.T)), rel=1e-9)
        centroid = np.array([q["pc"] for q in p["sets"]["expert"]["points"]]).mean(axis=0)
        assert d["reach"] == pytest.approx(np.linalg.norm(pts - centroid, axis=1).max(), rel=1e-9)
    # measured, not assumed: the counterfactual rollouts lie farther from the expert centroid than any expert one
    assert p["sets"]["counterfactual"]["reaches_beyond_expert"] is (p["sets"]["counterfactual"]["reach"]
                                                                     > p["sets"]["expert"]["reach"])


def test_t1_response(t1_release, t1_reports, tmp_path, capsys):
    args = ["study", "t1-response", "--release", str(t1_release), "--reports", *map(str, t1_reports.values()),
            "--out", str(tmp_path)]
    assert main(args) == 0
    assert "compression slope" in capsys.readouterr().out
    _figure_ok(tmp_path / "t1_response.png")
    result = json.loads((tmp_path / "t1_response.json").read_text())["configs"]["t1_maniskill"]
    rows = _rows(t1_release, "t1_maniskill")
    for name, folder in t1_reports.items():
        a = result[f"baseline:{name}"]
        entries = []
        for rec in _records(folder, "t1"):
            row = rows[rec["instance_id"]]
            for key, magnitude in (("d_os", "magnitude_small"), ("d_ol", "magnitude_large")):
                entries.append((row["task"], row[magnitude], np.mean([s[key] for s in rec["seeds"]]), row[key]))
        model, sim = np.zeros(len(entries)), np.zeros(len(entries))
        for task in {e[0] for e in entries}:
            idx = [k for k, e in enumerate(entries) if e[0] == task]
            for out, col in ((model, 2), (sim, 3)):
                mean = np.mean([entries[k][col] for k in idx])
                out[idx] = [entries[k][col] / mean if mean > 0 else 0.0 for k in idx]
        expected = np.polyfit(sim, model, 1)[0]
        assert a["pooled"]["compression"]["slope"] == pytest.approx(expected, abs=1e-9)
        for point in a["pooled"]["curve"]:
            at = [k for k, e in enumerate(entries) if round(e[1], 9) == point["magnitude"]]
            assert point["model"]["mean"] == pytest.approx(model[at].mean()) and point["model"]["n"] == len(at)
            assert point["simulator"]["mean"] == pytest.approx(sim[at].mean())
        # each instance's side of r*, from the report's own per-seed r and the row's r*
        sides = a["pooled"]["sides"]
        recs = _records(folder, "t1")
        ratio = [np.mean([s["r"] for s in rec["seeds"] if s["r"] is not None]) / rows[rec["instance_id"]]["r_star"]
                 for rec in recs if any(s["r"] is not None for s in rec["seeds"])]
        assert sides["instances"] == len(recs)
        assert sides["under"] == pytest.approx(sum(x < 1 for x in ratio) / len(recs))
        assert sides["compressed"] == pytest.approx(sum(x > 1 for x in ratio) / len(recs))
        assert sides["no_response"] == pytest.approx(1 - len(ratio) / len(recs))
        assert sides["median_ratio"] == (pytest.approx(float(np.median(ratio))) if ratio else None)
    oracle, noise, static = (result[f"baseline:{n}"]["pooled"]["compression"] for n in ("oracle", "noise", "static"))
    assert oracle["slope"] == pytest.approx(1.0, abs=0.02)  # the references respond as the simulator does
    assert noise["slope"] < 0.5 and noise["ci"][1] < oracle["ci"][0]  # added noise compresses the response
    assert static["slope"] == 0.0  # no response at all
    sides = {n: result[f"baseline:{n}"]["pooled"]["sides"] for n in ("oracle", "noise", "static")}
    assert sides["oracle"]["median_ratio"] == pytest.approx(1.0, abs=0.05)  # T1 99.9: r is r* within codec noise
    assert sides["noise"]["compressed"] == 1.0  # the same added distance to both variants: r near 1, above r*
    assert sides["static"]["no_response"] == 1.0 and sides["static"]["median_ratio"] is None


def test_ordering(t1_release, t1_reports, tmp_path, capsys):
    """Known order static < noise < oracle on T1: τ by SciPy on the reports' own suite scores, the CI around it."""
    ordered = [t1_reports[n] for n in ("static", "noise", "oracle")]
    assert main(["study", "ordering", "--release", str(t1_release), "--reports", *map(str, ordered),
                 "--out", str(tmp_path)]) == 0
    assert "Kendall τ" in capsys.readouterr().out
    _figure_ok(tmp_path / "ordering.png")
    result = json.loads((tmp_path / "ordering.json").read_text())
    assert result["models"] == ["baseline:static", "baseline:noise", "baseline:oracle"]
    t1 = result["platforms"]["maniskill"]["suites"]["t1"]
    own = [json.loads((f / "report.json").read_text())["platforms"]["maniskill"]["suites"]["t1"]["score"]
           for f in ordered]
    assert t1["scores"] == pytest.approx(own)
    assert t1["kendall_tau"] == pytest.approx(kendalltau([0, 1, 2], own).statistic)
    assert t1["in_order"] == bool(own[0] < own[1] < own[2])
    lo, hi = t1["kendall_tau_ci"]
    assert -1 <= lo <= t1["kendall_tau"] <= hi <= 1
    assert result["platforms"]["maniskill"]["overall"]["scores"] == pytest.approx(own)  # one suite: Overall is T1
    reversed_ = [str(f) for f in reversed(ordered)]
    assert main(["study", "ordering", "--release", str(t1_release), "--reports", *reversed_,
                 "--out", str(tmp_path / "r")]) == 0
    back = json.loads((tmp_path / "r" / "ordering.json").read_text())["platforms"]["maniskill"]["suites"]["t1"]
    assert back["kendall_tau"] == pytest.approx(-t1["kendall_tau"])
    assert main(["study", "ordering", "--release", str(t1_release), "--reports", *reversed_[:2],
                 "--out", str(tmp_path / "two")]) == 2
    assert "at least three reports" in capsys.readouterr().err


def test_ordering_scores_t5_as_the_report_does(suites_release, suites_reports):
    """The study's suite score of a draw is the report's: within primitive first on T5, the plain mean elsewhere."""
    for suite in ("t2", "t5"):
        reports = [json.loads((f / "report.json").read_text()) for f in suites_reports.values()]
        recs = [sorted(_records(f, suite), key=lambda r: r["instance_id"]) for f in suites_reports.values()]
        ids = [r["instance_id"] for r in recs[0]]
        rows = _rows(suites_release, f"{suite}_maniskill")
        scores = SuiteScores(suite, np.array([[r["score"] for r in rs] for rs in recs]),
                             SCORERS[suite].groups([rows[i] for i in ids]))
        assert scores.score() == pytest.approx([r["platforms"]["maniskill"]["suites"][suite]["score"]
                                                for r in reports])
        draw = scores.draw(np.random.default_rng(0))
        if suite == "t5":  # resampled within primitive: every primitive keeps its count
            groups = SCORERS[suite].groups([rows[i] for i in ids])
            assert sorted(groups[k] for k in draw) == sorted(groups)


def test_t2_mismatch(suites_release, suites_reports, tmp_path):
    assert main(["study", "t2-mismatch", "--release", str(suites_release), "--reports",
                 *map(str, suites_reports.values()), "--out", str(tmp_path)]) == 0
    _figure_ok(tmp_path / "t2_mismatch.png")
    entry = json.loads((tmp_path / "t2_mismatch.json").read_text())["configs"]["t2_maniskill"]
    rows = _rows(suites_release, "t2_maniskill")
    rhos = []
    for name, folder in suites_reports.items():
        m = entry["models"][f"baseline:{name}"]
        recs = _records(folder, "t2")
        score = [r["score"] for r in recs]
        mismatch = [rows[r["instance_id"]]["mismatch"] for r in recs]
        expected = spearmanr(score, mismatch).statistic if np.ptp(score) > 0 else None
        if expected is None:
            assert m["spearman"] is None
        else:
            assert m["spearman"] == pytest.approx(expected, abs=1e-9)
            rhos.append(expected)
        by_decile = {}
        for r in recs:
            by_decile.setdefault(r["group"], []).append(r["score"])  # the report's own decile of each instance
        assert {str(d["decile"]): d["mean"] for d in m["deciles"]} == pytest.approx(
            {k: np.mean(v) for k, v in by_decile.items()})
    assert entry["mean_spearman"] == (pytest.approx(np.mean(rhos)) if rhos else None)


def test_t3_sources(suites_release, suites_reports, tmp_path):
    assert main(["study", "t3-sources", "--release", str(suites_release), "--reports",
                 *map(str, suites_reports.values()), "--out", str(tmp_path)]) == 0
    _figure_ok(tmp_path / "t3_sources.png")
    result = json.loads((tmp_path / "t3_sources.json").read_text())["configs"]["t3_maniskill"]
    rows = _rows(suites_release, "t3_maniskill")
    for name, folder in suites_reports.items():
        m = result[f"baseline:{name}"]
        by = {}
        for r in _records(folder, "t3"):
            by.setdefault(rows[r["instance_id"]]["source_group"], []).append(r["score"])
        means = {g: np.mean(v) for g, v in by.items()}
        assert m["policy_gap"]["value"] == pytest.approx(means["policy_late"] - means["policy_early"])
        ops = [means[f"H{k}"] for k in range(1, 6)]
        assert m["operator_range"]["value"] == pytest.approx(max(ops) - min(ops))
        assert m["operator_sd"]["value"] == pytest.approx(np.std(ops, ddof=1))
    assert result["baseline:oracle"]["policy_gap"]["value"] == pytest.approx(0.0, abs=1e-6)  # references: 100 each


def test_bad_input_is_one_line(t1_release, suites_release, suites_reports, tmp_path, capsys):
    args = ["--reports", str(suites_reports["oracle"]), "--out", str(tmp_path / "x")]
    assert main(["study", "t1-response", "--release", str(t1_release), *args]) == 2
    assert "scored against another release" in capsys.readouterr().err
    assert main(["study", "t2-mismatch", "--release", str(t1_release), "--reports", str(tmp_path),
                 "--out", str(tmp_path / "y")]) == 2
    assert "no T2 config" in capsys.readouterr().err
    assert main(["study", "t3-sources", "--release", str(suites_release), "--reports", str(tmp_path),
                 "--out", str(tmp_path / "z")]) == 2
    assert "not a `wsp score` report" in capsys.readouterr().err
    assert main(["study", "coverage", "--release", str(t1_release), "--out", str(tmp_path / "c")]) == 2
    assert "no T2 or T3 config" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{}")
    assert main(["study", "idm", "--release", str(suites_release), "--checkpoint", str(tmp_path / "bad.json"),
                 "--out", str(tmp_path / "i")]) == 2
    assert "not an IDM checkpoint" in capsys.readouterr().err
    assert main(["study", "idm-train", "--release", str(suites_release), "--platform", "maniskill",
                 "--out", str(tmp_path / "i.json")]) == 2
    assert "no train_maniskill split" in capsys.readouterr().err


def test_idm_trains_deterministically_and_reports_per_stream(libero_release, tmp_path, capsys):
    """The ridge IDM: two trainings give the same checkpoint, under the size limit, equal to the ridge solution of
    the augmented least-squares system; `wsp study idm` reports Micro-MSE per stream kind on the references and on
    a submission (the oracle's videos: the references re-encoded, so nearly the references' error)."""
    from wsp_eval.reference import reference_frames
    from wsp_eval.studies import idm

    for k in (1, 2):
        assert main(["study", "idm-train", "--release", str(libero_release), "--platform", "libero", "--out",
                     str(tmp_path / f"idm{k}.json")]) == 0
    one, two = ((tmp_path / f"idm{k}.json").read_bytes() for k in (1, 2))
    assert one == two and len(one) <= idm.MAX_CHECKPOINT_BYTES
    c = json.loads(one)
    config = libero_release / "train_libero"
    stream = idm.actions(config)
    xs, ys = zip(*(idm.pairs(reference_frames(config, e), stream[e]) for e in sorted(stream)))
    x, y = np.concatenate(xs), np.concatenate(ys)
    z = np.hstack([(x - x.mean(0)) / (x.std(0) + 1e-9), np.ones((len(x), 1))])
    penalty = np.sqrt(idm.RIDGE) * np.eye(z.shape[1])[:-1]
    expected = np.linalg.lstsq(np.vstack([z, penalty]), np.vstack([y, np.zeros((len(penalty), y.shape[1]))]),
                               rcond=None)[0]
    assert np.allclose(c["weights"], expected, atol=1e-8)

    write_baseline("oracle", libero_release, tmp_path / "oracle", seeds=(0,))
    assert main(["study", "idm", "--release", str(libero_release), "--checkpoint", str(tmp_path / "idm1.json"),
                 "--submission", str(tmp_path / "oracle"), "--out", str(tmp_path / "out")]) == 0
    assert "Micro-MSE" in capsys.readouterr().out
    _figure_ok(tmp_path / "out" / "idm.png")
    kinds = json.loads((tmp_path / "out" / "idm.json").read_text())["platforms"]["libero"]["kinds"]
    assert set(kinds) == {"expert", "policy_early", "cross_task"} and all(k["episodes"] for k in kinds.values())
    for k in kinds.values():
        assert k["generated_micro_mse"] == pytest.approx(k["reference_micro_mse"], rel=0.2)
    assert kinds["expert"]["reference_ratio_to_expert"] == 1.0
    manifest = tmp_path / "oracle" / "submission.json"  # a submission made for T3 only: the rest is not read
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "configs": ["t3_libero"]}))
    for other in ("t1_libero", "t2_libero"):
        shutil.rmtree(tmp_path / "oracle" / other)
    assert main(["study", "idm", "--release", str(libero_release), "--checkpoint", str(tmp_path / "idm1.json"),
                 "--submission", str(tmp_path / "oracle"), "--out", str(tmp_path / "t3only")]) == 0
    t3only = json.loads((tmp_path / "t3only" / "idm.json").read_text())["platforms"]["libero"]["kinds"]
    assert t3only["cross_task"]["generated_micro_mse"] is None and t3only["cross_task"]["generated_episodes"] == 0
    assert t3only["policy_early"]["generated_micro_mse"] == kinds["policy_early"]["generated_micro_mse"]
    assert 0 < t3only["expert"]["generated_episodes"] < t3only["expert"]["episodes"]
    for name in ("libero", "aloha", "maniskill"):  # the packaged checkpoints load and fit the limit
        path = idm.PACKAGED / f"idm_{name}.json"
        assert path.stat().st_size <= idm.MAX_CHECKPOINT_BYTES and idm.load(path)["platform"] == name
