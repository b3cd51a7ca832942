"""`scripts/docs_figures.py` without a release (seconds): its arguments and its pure helpers on synthetic arrays.
The figures themselves are made from a real release by the command in the script's docstring."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "docs_figures.py"


@pytest.fixture(scope="module")
def figures():
    spec = importlib.util.spec_from_file_location("docs_figures", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_three_commands_parse_with_their_defaults(figures):
    p = figures.parser()
    a = p.parse_args(["suites", "--release", "worldsimprobe", "--platforms", "maniskill", "libero", "aloha"])
    assert (a.command, a.release, a.platforms, a.frames, a.instance) == (
        "suites", Path("worldsimprobe"), ["maniskill", "libero", "aloha"], figures.FRAMES, 0)
    assert a.out == figures.IMG / "suites.png"
    a = p.parse_args(["leaderboard", "--window-size", "1400,900"])
    assert (a.leaderboard, a.window_size, a.out) == (Path("calibration/leaderboard"), (1400, 900),
                                                      figures.IMG / "leaderboard.png")
    a = p.parse_args(["report", "--report", "reports/oracle", "--screenshot"])
    assert (a.report, a.screenshot, a.out_dir) == (Path("reports/oracle"), True, figures.IMG / "report")
    for bad in (["suites", "--platforms", "robotwin"], ["leaderboard", "--window-size", "wide"], ["report"]):
        with pytest.raises(SystemExit):
            p.parse_args(bad)


def test_frame_indices_spread_over_the_clip_ends_included(figures):
    assert figures.frame_indices(100, 6) == [0, 20, 40, 59, 79, 99]
    assert figures.frame_indices(4, 6) == [0, 1, 2, 3]
    assert figures.frame_indices(0, 6) == []


def test_a_strip_keeps_each_frames_aspect_at_one_height(figures):
    square = np.zeros((128, 128, 3), np.uint8)
    wide = np.full((240, 320, 3), 200, np.uint8)
    out = figures.strip([square, wide, square], height=64, gap=4)
    assert out.shape == (64, 64 + 4 + 85 + 4 + 64, 3) and out.dtype == np.uint8
    assert (out[:, 64:68] == 255).all()  # the gap
    assert (out[:, 68:153] == 200).all()  # the wide frame, resized, values kept
    with pytest.raises(ValueError):
        figures.strip([])
    with pytest.raises(ValueError):
        figures.strip([np.zeros((8, 8), np.uint8)])


def test_the_ring_sits_at_the_scoring_frame_point_on_any_frame_size(figures):
    frame = np.zeros((240, 320, 3), np.uint8)
    ringed = figures.ring(frame, (128.0, 128.0), radius=7)
    ys, xs = np.nonzero(ringed[..., 0])
    assert abs(xs.mean() - 160) < 1 and abs(ys.mean() - 120) < 1  # the centre of 256² is the centre of the frame
    assert not frame.any()  # the input is left alone
    assert figures.ring(frame, None) is frame


def test_the_scored_episode_is_the_last_role(figures):
    row = {"instance_id": "x", "roles": ["original", "small", "large"], "episode_indices": [3, 4, 5]}
    assert figures.scored_episode(row) == ("large", 5)
    with pytest.raises(ValueError):
        figures.scored_episode({"instance_id": "y", "roles": ["reference"], "episode_indices": []})


def test_a_reports_inline_plots_come_out_as_standalone_svg(figures):
    page = ('<h2>Scores</h2><figure><svg width="10" height="10"><rect/></svg><figcaption>Per-suite scores with '
            '95% CIs</figcaption></figure><p>x</p><figure><img src="strips/t1_maniskill/1.png" alt="a">'
            "<figcaption>not a plot</figcaption></figure>")
    (caption, svg), = figures.svg_figures(page)
    assert caption == "Per-suite scores with 95% CIs"
    assert svg.startswith("<?xml") and 'xmlns="http://www.w3.org/2000/svg"' in svg and svg.rstrip().endswith("</svg>")
    assert figures.slug(caption) == "per-suite-scores-with-95-cis"


def test_the_chromium_command_screenshots_a_local_file(figures, tmp_path):
    page = tmp_path / "leaderboard.html"
    cmd = figures.chromium_command("/usr/bin/chromium", page, tmp_path / "out.png", (1280, 1000), tmp_path / "p",
                                   no_sandbox=True)
    assert cmd[0] == "/usr/bin/chromium" and "--headless" in cmd and "--no-sandbox" in cmd
    assert f"--screenshot={tmp_path / 'out.png'}" in cmd and "--window-size=1280,1000" in cmd
    assert cmd[-1] == page.resolve().as_uri()
    assert figures.leaderboard_page(tmp_path) == tmp_path / "leaderboard.html"
    assert figures.leaderboard_page(page) == page


def test_the_suites_figure_is_laid_out_from_whatever_configs_the_release_holds(figures, tmp_path, monkeypatch):
    for config in ("t1_maniskill", "t5_maniskill", "t5_aloha"):
        (tmp_path / "rel" / config).mkdir(parents=True)
    made = []

    def fake(release, suite, platform, instance, frames):
        made.append(f"{suite}_{platform}")
        h, w = (240, 320) if platform == "aloha" else (128, 128)
        return figures.strip([np.full((h, w, 3), 90, np.uint8)] * frames), f"{suite} {platform}"

    monkeypatch.setattr(figures, "config_strips", fake)
    out = figures.suites_figure(tmp_path / "rel", ["maniskill", "aloha"], tmp_path / "img" / "suites.png", dpi=40)
    assert made == ["t1_maniskill", "t5_maniskill", "t5_aloha"]  # suite order, ManiSkill before ALOHA
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(SystemExit):
        figures.suites_figure(tmp_path / "rel", ["libero"], tmp_path / "none.png")
