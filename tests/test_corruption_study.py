"""`wsp study corruption` (docs/validity.md, T2 and T3) on the shared tiny ManiSkill T2 references.

Tolerances: the clean reference scored against itself is RMFA 100 up to nothing (same frames, same flows), so we
ask ≥ 99.9. Corrupting the robot must cost more than corrupting an equal-area background region on every
reference (measured on 50 references: robot 20–45 points, background under 2), and
stronger blur inside the robot mask must never score higher than weaker blur by more than flow noise (0.5).
"""

from __future__ import annotations

import json

import numpy as np

from wsp_eval.cli import main
from wsp_eval.studies.corruption import MARGIN_PX, background_regions, corrupt


def test_background_region_has_the_robot_area_and_keeps_clear_of_it():
    masks = np.zeros((3, 64, 64), np.uint8)
    masks[0, 10:20, 10:20] = 1
    masks[1, 12:30, 10:20] = 2
    masks[2, 40:50, 40:45] = 1
    region = background_regions(masks, np.random.default_rng(0))
    assert [int(r.sum()) for r in region] == [int((m > 0).sum()) for m in masks]
    import cv2

    ever = (masks > 0).any(axis=0).astype(np.uint8)
    dist = cv2.distanceTransform(1 - ever, cv2.DIST_L2, 3)
    assert (dist[region.any(axis=0)] >= MARGIN_PX).all()
    frames = np.random.default_rng(1).integers(0, 256, (3, 64, 64, 3), dtype=np.uint8)
    flat = corrupt(frames, masks > 0, "texture", 3)
    assert (flat[~(masks > 0)] == frames[~(masks > 0)]).all()  # nothing outside the region changes
    assert all(len(np.unique(flat[t][masks[t] > 0], axis=0)) == 1 for t in range(3))  # α = 1: flat silhouette


def test_study_runs_resumes_and_separates_robot_from_background(suites_release, tmp_path, capsys):
    out = tmp_path / "corruption"
    assert main(["study", "corruption", "--release", str(suites_release), "--out", str(out), "--count", "2",
                 "--quiet"]) == 0
    assert "Paired excess drop" in capsys.readouterr().out
    summary = json.loads((out / "corruption.json").read_text())
    cached = [json.loads(line) for line in (out / "trajectories.jsonl").read_text().splitlines()]
    assert summary["trajectories"] == len(cached) == 2 and (out / "example.png").stat().st_size > 0
    for t in cached:
        assert t["clean"] >= 99.9
        robot = np.mean([t["scores"]["robot"][c] for c in ("blur", "texture")])
        background = np.mean([t["scores"]["background"][c] for c in ("blur", "texture")])
        assert robot < background
        blur = t["scores"]["robot"]["blur"]
        assert all(b <= a + 0.5 for a, b in zip(blur, blur[1:]))
    assert summary["rows"]["excess"]["drop"] > 0
    assert main(["study", "corruption", "--release", str(suites_release), "--out", str(out), "--count", "2",
                 "--quiet"]) == 0  # resumed: nothing recomputed
    assert len((out / "trajectories.jsonl").read_text().splitlines()) == 2


def test_study_refuses_a_release_without_t2(t1_release, tmp_path, capsys):
    assert main(["study", "corruption", "--release", str(t1_release), "--out", str(tmp_path / "c")]) == 2
    assert "no T2 config" in capsys.readouterr().err
