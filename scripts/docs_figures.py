"""The documentation's pictures, made from real outputs of the benchmark (written under docs/img/).

    .venv/bin/python scripts/docs_figures.py suites --release worldsimprobe [--platforms maniskill libero aloha]
    .venv/bin/python scripts/docs_figures.py leaderboard --leaderboard calibration/leaderboard
    .venv/bin/python scripts/docs_figures.py report --report calibration/reports/oracle [--screenshot]

- `suites`: one frame strip per suite (T1–T5) and platform, `--frames` frames spread evenly over one reference
  episode of the config (the instance `--instance` in instance-id order; its last scored role: T1's large
  perturbation, the reference elsewhere), the evaluated object ringed on T4 and T5; ManiSkill first. Written to
  docs/img/suites.png (the README's figure). Reads the release only: `instances.parquet` and the reference
  videos (`wsp_eval.reference.reference_frames`).
- `leaderboard`: a screenshot of the page `wsp leaderboard` writes (`leaderboard.html`), taken by headless
  Chromium (`chromium --headless --screenshot=... --window-size=W,H`), to docs/img/leaderboard.png.
- `report`: a `wsp score` report's pictures into docs/img/report/: its plots (inline SVG in `report.html`, written
  out as .svg files named after their captions), the frame strips of its worst-scoring instances (the PNGs under
  `strips/`, as listed in `report.json`), and with `--screenshot` the page itself (report.png) by headless Chromium.

Nothing here changes a release or a report. Needs the scoring install (numpy, pyarrow, OpenCV, PyAV,
matplotlib) and, for the screenshots, Chromium (`scripts/setup.sh` installs it).
"""

from __future__ import annotations

import argparse
import html as html_lib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
SUITE_NAMES = {
    "t1": "T1 Local action calibration",
    "t2": "T2 Global trajectory coverage",
    "t3": "T3 Action-source behaviour preservation",
    "t4": "T4 Interaction grounding",
    "t5": "T5 Interaction dynamics",
}
PLATFORM_NAMES = {"maniskill": "ManiSkill", "libero": "LIBERO", "aloha": "ALOHA"}
PLATFORMS = ("maniskill", "libero", "aloha")  # the figure's order: ManiSkill first
FRAMES = 6
TILE_HEIGHT = 128  # px of every frame in a strip (ALOHA's 320×240 frames keep their aspect: 171 px wide)
GAP = 4  # px of white between frames
RING = (255, 40, 40)  # RGB of the ring around the evaluated object (as the report's strips draw it)
CHROMIUM = ("chromium", "chromium-browser", "google-chrome", "chrome")
WINDOW = (1280, 1000)  # default screenshot size, px
SCREENSHOT_TIMEOUT = 120  # s


# ---------------------------------------------------------------------------------------------- pure helpers
def frame_indices(n: int, k: int = FRAMES) -> list[int]:
    """`k` frame indices spread evenly over `n` frames, the first and the last included (fewer when n < k)."""
    if n <= 0 or k <= 0:
        return []
    if n <= k:
        return list(range(n))
    return [int(i) for i in np.linspace(0, n - 1, k).round().astype(int)]


def ring(frame: np.ndarray, xy_256: Sequence[float] | None, radius: int = 7) -> np.ndarray:
    """A copy of the RGB frame with a ring at `xy_256`, a point of the 256×256 scoring frame (stretched to the
    frame's own width and height, as the scorers resize); the frame itself when there is no point."""
    if xy_256 is None:
        return frame
    import cv2

    h, w = frame.shape[:2]
    out = np.ascontiguousarray(frame.copy())
    centre = (int(round(float(xy_256[0]) * w / 256)), int(round(float(xy_256[1]) * h / 256)))
    cv2.circle(out, centre, radius, RING, 1, cv2.LINE_AA)
    return out


def strip(frames: Sequence[np.ndarray], height: int = TILE_HEIGHT, gap: int = GAP, fill: int = 255) -> np.ndarray:
    """RGB uint8 frames side by side, each resized to `height` keeping its aspect ratio, `gap` px of `fill`
    between them: one (height, W, 3) uint8 image."""
    import cv2

    if not len(frames):
        raise ValueError("no frames to put in a strip")
    tiles = []
    for f in frames:
        f = np.asarray(f)
        if f.ndim != 3 or f.shape[2] != 3:
            raise ValueError(f"expected (H, W, 3) frames, got {f.shape}")
        width = max(1, int(round(f.shape[1] * height / f.shape[0])))
        interp = cv2.INTER_AREA if f.shape[0] > height else cv2.INTER_NEAREST
        tiles.append(cv2.resize(np.ascontiguousarray(f.astype(np.uint8)), (width, height), interpolation=interp))
    spacer = np.full((height, gap, 3), fill, np.uint8)
    parts = [tiles[0]]
    for t in tiles[1:]:
        parts += [spacer, t]
    return np.hstack(parts)


def scored_episode(row: dict) -> tuple[str, int]:
    """The role and episode index of an instance row's last scored rollout (T1's large perturbation, the
    reference elsewhere), as the report's strips choose it."""
    roles, episodes = list(row["roles"]), list(row["episode_indices"])
    if not roles or len(roles) != len(episodes):
        raise ValueError(f"instance {row.get('instance_id')!r}: roles {roles} do not match episodes {episodes}")
    return roles[-1], int(episodes[-1])


def slug(text: str) -> str:
    """A file-name stem for a caption: lower case, runs of other characters as one hyphen."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "plot"


FIGURE = re.compile(r"<figure>\s*(<svg\b.*?</svg>)\s*<figcaption>(.*?)</figcaption>\s*</figure>", re.S)


def svg_figures(page: str) -> list[tuple[str, str]]:
    """The inline SVG plots of a report page, as (caption, standalone SVG document) in page order."""
    found = []
    for svg, caption in FIGURE.findall(page):
        if "xmlns=" not in svg[:300]:
            svg = svg.replace("<svg", '<svg xmlns="http://www.w3.org/2000/svg"', 1)
        found.append((html_lib.unescape(caption).strip(), '<?xml version="1.0" encoding="utf-8"?>\n' + svg + "\n"))
    return found


def window_size(text: str) -> tuple[int, int]:
    """`W,H` (or `WxH`) in pixels, for argparse."""
    try:
        w, h = (int(v) for v in re.split(r"[,x]", text.strip()))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected W,H in pixels (e.g. 1280,1000), got {text!r}") from None
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"expected positive sides, got {text!r}")
    return w, h


def chromium_command(binary: str, page: Path, out: Path, size: tuple[int, int], profile: Path,
                     no_sandbox: bool) -> list[str]:
    """The headless-Chromium command line that screenshots `page` (a local file) into `out` at `size`."""
    cmd = [binary, "--headless", "--disable-gpu", "--hide-scrollbars", "--no-first-run", "--no-default-browser-check",
           f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}", f"--screenshot={out}"]
    if no_sandbox:  # Chromium refuses to run as root with its sandbox
        cmd.append("--no-sandbox")
    return [*cmd, Path(page).resolve().as_uri()]


# ---------------------------------------------------------------------------------------------- suites
def config_strips(release: Path, suite: str, platform: str, instance: int, frames: int) -> tuple[np.ndarray, str]:
    """One config's strip and its label, from the release."""
    import pyarrow.parquet as pq

    from wsp_eval.reference import reference_frames
    from wsp_eval.release_format import INSTANCES

    config_dir = release / f"{suite}_{platform}"
    rows = sorted(pq.read_table(config_dir / INSTANCES).to_pylist(), key=lambda r: str(r["instance_id"]))
    if not rows:
        raise SystemExit(f"{config_dir}: no instances")
    row = rows[min(instance, len(rows) - 1)]
    role, episode = scored_episode(row)
    video = reference_frames(config_dir, episode)
    mark = row.get("object_pixel_256") if suite in ("t4", "t5") else None
    tiles = [ring(video[i], mark) for i in frame_indices(len(video), frames)]
    what = {"t4": row.get("kind"), "t5": row.get("primitive"), "t3": row.get("source_kind")}.get(suite)
    label = f"{SUITE_NAMES[suite]}\n{PLATFORM_NAMES.get(platform, platform)} · {row.get('task', '')}"
    if what:
        label += f" · {str(what).replace('_', ' ')}"
    return strip(tiles), label


def suites_figure(release: Path, platforms: Sequence[str], out: Path, instance: int = 0, frames: int = FRAMES,
                  dpi: int = 150) -> Path:
    """The suites figure (module docstring): rows T1…T5, each with one strip per platform present."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = []
    for suite in SUITE_NAMES:
        for platform in platforms:
            if not (release / f"{suite}_{platform}").is_dir():
                print(f"{suite}_{platform}: not in {release}; left out", file=sys.stderr)
                continue
            rows.append(config_strips(release, suite, platform, instance, frames))
    if not rows:
        raise SystemExit(f"{release}: none of the configs t1–t5 of {', '.join(platforms)}")
    width = max(img.shape[1] for img, _ in rows)
    fig_w = 11.0
    heights = [fig_w * 0.72 * img.shape[0] / width + 0.35 for img, _ in rows]
    fig, axes = plt.subplots(len(rows), 1, figsize=(fig_w, sum(heights)), gridspec_kw={"height_ratios": heights},
                             squeeze=False)
    for ax, (img, label) in zip(axes[:, 0], rows):
        ax.imshow(img, interpolation="nearest")
        ax.set_xlim(-0.5, width - 0.5)
        ax.set_axis_off()
        ax.text(-0.01 * width, img.shape[0] / 2, label, ha="right", va="center", fontsize=8)
    fig.subplots_adjust(left=0.27, right=0.99, top=0.99, bottom=0.01, hspace=0.15)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, facecolor="white", metadata={"Software": None})
    plt.close(fig)
    return out


# ---------------------------------------------------------------------------------------------- screenshots
def find_chromium(given: str | None) -> str:
    for name in ([given] if given else CHROMIUM):
        path = shutil.which(name) if name else None
        if path:
            return path
    raise SystemExit("headless Chromium not found (the Debian package `chromium`, installed by scripts/setup.sh); "
                     "or pass --chromium PATH")


def screenshot(page: Path, out: Path, size: tuple[int, int], binary: str | None = None) -> Path:
    """Screenshot a local HTML page with headless Chromium."""
    if not page.is_file():
        raise SystemExit(f"{page}: no such page")
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="wsp-chromium-") as profile:
        cmd = chromium_command(find_chromium(binary), page, out.resolve(), size, Path(profile),
                               no_sandbox=hasattr(os, "geteuid") and os.geteuid() == 0)
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=SCREENSHOT_TIMEOUT)
    if done.returncode != 0 or not out.is_file():
        raise SystemExit(f"chromium failed ({done.returncode}) on {page}:\n{done.stderr[-2000:]}")
    return out


def leaderboard_page(path: Path) -> Path:
    """The leaderboard page: `path` itself, or the `leaderboard.html` in the folder `wsp leaderboard --out` wrote."""
    return path / "leaderboard.html" if path.is_dir() else path


def report_pictures(report: Path, out_dir: Path, shot: bool, size: tuple[int, int],
                    binary: str | None = None) -> list[Path]:
    """Copy a report's plots and strips into `out_dir` (module docstring); the files written."""
    page = report / "report.html"
    if not page.is_file():
        raise SystemExit(f"{report}: no report.html (a folder `wsp score --out` wrote)")
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for caption, svg in svg_figures(page.read_text(encoding="utf-8")):
        target = out_dir / f"{slug(caption)}.svg"
        n = 2
        while target in written:
            target, n = out_dir / f"{slug(caption)}-{n}.svg", n + 1
        target.write_text(svg, encoding="utf-8")
        written.append(target)
    listed = report / "report.json"
    strips = [e["image"] for e in json.loads(listed.read_text()).get("strips") or []] if listed.is_file() else []
    for rel in strips or sorted(p.relative_to(report).as_posix() for p in (report / "strips").glob("*/*.png")):
        source = report / rel
        if source.is_file():
            parts = Path(rel).parts  # strips/<config>/<n>.png
            target = out_dir / ("strip-" + "-".join(parts[1:]) if parts[0] == "strips" else Path(rel).name)
            shutil.copyfile(source, target)
            written.append(target)
    if shot:
        written.append(screenshot(page, out_dir / "report.png", size, binary))
    return written


# ---------------------------------------------------------------------------------------------- command line
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="docs_figures.py", description="Make the documentation's pictures.")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("suites", help="one frame strip per suite and platform from a release → docs/img/suites.png")
    s.add_argument("--release", type=Path, default=Path("worldsimprobe"), help="release folder (default ./worldsimprobe)")
    s.add_argument("--platforms", nargs="+", default=["maniskill"], choices=PLATFORMS,
                   help="platforms to show, in this order (default: maniskill)")
    s.add_argument("--instance", type=int, default=0, help="which instance of each config, in instance-id order")
    s.add_argument("--frames", type=int, default=FRAMES, help=f"frames per strip (default {FRAMES})")
    s.add_argument("--out", type=Path, default=IMG / "suites.png")
    lb = sub.add_parser("leaderboard", help="screenshot a `wsp leaderboard` page → docs/img/leaderboard.png")
    lb.add_argument("--leaderboard", type=Path, default=Path("calibration/leaderboard"),
                    help="the folder `wsp leaderboard --out` wrote, or its leaderboard.html")
    lb.add_argument("--out", type=Path, default=IMG / "leaderboard.png")
    lb.add_argument("--window-size", type=window_size, default=WINDOW, metavar="W,H")
    lb.add_argument("--chromium", help="the Chromium binary (default: found on PATH)")
    r = sub.add_parser("report", help="a `wsp score` report's plots and strips → docs/img/report/")
    r.add_argument("--report", type=Path, required=True, help="the folder `wsp score --out` wrote")
    r.add_argument("--out-dir", type=Path, default=IMG / "report")
    r.add_argument("--screenshot", action="store_true", help="also screenshot report.html (report.png)")
    r.add_argument("--window-size", type=window_size, default=WINDOW, metavar="W,H")
    r.add_argument("--chromium", help="the Chromium binary (default: found on PATH)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.command == "suites":
        if args.frames < 2:
            raise SystemExit("--frames: at least 2")
        print(suites_figure(args.release, args.platforms, args.out, args.instance, args.frames))
    elif args.command == "leaderboard":
        print(screenshot(leaderboard_page(args.leaderboard), args.out, args.window_size, args.chromium))
    else:
        for path in report_pictures(args.report, args.out_dir, args.screenshot, args.window_size, args.chromium):
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
