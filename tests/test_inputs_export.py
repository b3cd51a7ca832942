"""Private test sets: `wsp export-inputs` on the shared tiny T1 release holds first frames and actions only; a model
run on it with `wsp generate` gives exactly the submission it gives on the full release, which scores against
the full release; and the scorer flags a submission that copies the references (the oracle) but not a model."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq

from test_generate import CONFIG, shift_model
from wsp_eval.cli import main
from wsp_eval.baselines import write_baseline
from wsp_eval.generate import generate
from wsp_eval.reference import reference_frames, reference_size
from wsp_eval.video import read_video


def test_inputs_only_release_holds_no_reference(t1_release, tmp_path, capsys):
    inputs = tmp_path / "inputs"
    assert main(["export-inputs", "--release", str(t1_release), "--out", str(inputs), "--quiet"]) == 0
    assert "first frames and actions only" in capsys.readouterr().out
    meta = json.loads((inputs / "release.json").read_text())
    assert meta["inputs_only"] is True and "seed" not in json.dumps(meta)  # the private release only by hash
    names = {p.relative_to(inputs).as_posix() for p in inputs.rglob("*") if p.is_file()}
    assert not any(n.endswith(".mp4") or "/videos/" in n or "/data/" in n or "/meta/" in n for n in names)
    rows = pq.read_table(inputs / CONFIG / "instances.parquet").to_pylist()
    assert rows and not {"seed", "interventions", "camera_intrinsic", "r_star"} & set(rows[0])
    ep = rows[0]["episode_ids"][0]
    full = reference_frames(t1_release / CONFIG, rows[0]["episode_indices"][0])[0]
    import cv2

    first = cv2.cvtColor(cv2.imread(str(inputs / CONFIG / "inputs" / "first_frames" / f"{ep}.png")), cv2.COLOR_BGR2RGB)
    assert np.array_equal(first, full)
    assert reference_size(inputs / CONFIG) == reference_size(t1_release / CONFIG) == full.shape[:2]  # PNG, info.json
    assert main(["baseline", "oracle", "--release", str(inputs), "--out", str(tmp_path / "o")]) == 2
    assert "inputs-only release holds no reference frames" in capsys.readouterr().err


def test_a_model_on_the_inputs_scores_against_the_release(t1_release, tmp_path, capsys):
    inputs = tmp_path / "inputs"
    assert main(["export-inputs", "--release", str(t1_release), "--out", str(inputs), "--quiet"]) == 0
    generate(shift_model, inputs, tmp_path / "from-inputs", seeds=(0,), name="shift", progress=False)
    generate(shift_model, t1_release, tmp_path / "from-release", seeds=(0,), name="shift", progress=False)
    for path in sorted((tmp_path / "from-release" / CONFIG).rglob("*.mp4")):
        twin = tmp_path / "from-inputs" / path.relative_to(tmp_path / "from-release")
        assert np.array_equal(read_video(path)[0], read_video(twin)[0])
    assert main(["score", str(tmp_path / "from-inputs"), "--release", str(t1_release), "--out",
                 str(tmp_path / "report"), "--quiet"]) == 0
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["copy_check"]["probable_copy"] is False and report["copy_check"]["videos"] > 0
    assert report["strips"] and all("against the simulator's r*" in s["evidence"] or "r undefined" in s["evidence"]
                                    for s in report["strips"])  # T1 evidence (this toy model moves the whole frame)
    write_baseline("oracle", t1_release, tmp_path / "oracle", seeds=(0,))
    assert main(["score", str(tmp_path / "oracle"), "--release", str(t1_release), "--out",
                 str(tmp_path / "oracle-report"), "--quiet"]) == 0
    oracle = json.loads((tmp_path / "oracle-report" / "report.json").read_text())["copy_check"]
    assert oracle["probable_copy"] is True and oracle["equal_to_reference"] == oracle["videos"]
    assert "PROBABLE COPY" in (tmp_path / "oracle-report" / "report.md").read_text()
