"""Frame strips of the worst-scoring instances, for the report: what a failure looks like.

Per scored config, the `WORST` lowest-scoring instances (their lowest-scoring seed): `COLUMNS` frames spread over
the clip, the generated video above its reference, the evaluated object's frame-0 position ringed on both for
T4 and T5, written as `strips/<config>/<n>.png` beside the report, with the evidence that decided the score.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from wsp_eval.reference import reference_frames
from wsp_eval.submission import Expected
from wsp_eval.video import VideoError, read_video

WORST = 3
COLUMNS = 6
TILE = 112  # px per frame in the strip
STRIPS_DIR = "strips"


def evidence(suite: str, seed: dict, row: dict) -> str:
    """What decided one seed's score, in words."""
    s = seed["score"]
    if suite == "t4":
        return (f"S {s:.0f}: object moved d = {seed.get('displacement', 0):.1f} px (pass ≤ 10); arm gate "
                f"{'passed' if seed.get('gate_passed') else 'failed'} ({seed.get('gate', 0):.1f} px); object "
                f"{'tracked' if seed.get('tracked', True) else 'lost'} in {seed.get('visible_fraction', 0):.0%} of frames")
    if suite == "t5":
        ok = lambda b: "yes" if b else "no"  # noqa: E731
        return (f"S {s:.0f}: judged {seed.get('label') or 'unreadable'} (intended {row.get('primitive')}); robot acts: "
                f"{ok(seed.get('agent_ok'))}; object responds: {ok(seed.get('object_ok'))}")
    if suite in ("t2", "t3"):
        return f"RMFA {s:.1f} over the first {seed.get('common_seconds', 0):.1f} s"
    return f"S {s:.1f}"


def _tiles(frames: np.ndarray, mark: tuple[float, float] | None) -> np.ndarray:
    picks = np.linspace(0, len(frames) - 1, COLUMNS).round().astype(int)
    tiles = []
    for i in picks:
        tile = cv2.resize(frames[i], (TILE, TILE), interpolation=cv2.INTER_AREA)
        if mark is not None:
            center = (int(round(mark[0] * TILE / 256)), int(round(mark[1] * TILE / 256)))
            cv2.circle(tile, center, 7, (255, 40, 40), 1, cv2.LINE_AA)
        tiles.append(tile)
    return np.hstack(tiles)


def write_strips(records: list[dict], rows: dict[str, list[dict]], release: Path, submission: Path,
                 out: Path) -> list[dict]:
    """Write the strips (module docstring); their entries for the report (path relative to `out`)."""
    entries = []
    for config, config_rows in rows.items():
        by_id = {r["instance_id"]: r for r in config_rows}
        recs = [r for r in records if r["config"] == config and any(not s.get("missing") for s in r["seeds"])]
        for n, rec in enumerate(sorted(recs, key=lambda r: (r["score"], r["instance_id"]))[:WORST]):
            row = by_id[rec["instance_id"]]
            seed = min((s for s in rec["seeds"] if not s.get("missing")), key=lambda s: s["score"])
            k = len(row["roles"]) - 1  # the last role: T1's large perturbation, the reference elsewhere
            exp = Expected(config, row["episode_ids"][k], seed["seed"], row["num_frames"][k], row["fps"])
            try:
                generated, _ = read_video(submission / exp.relpath, max_frames=exp.num_frames)
            except VideoError:
                continue
            reference = reference_frames(release / config, row["episode_indices"][k])
            mark = row.get("object_pixel_256") if rec["suite"] in ("t4", "t5") else None
            image = np.vstack([_tiles(generated, mark), np.full((4, COLUMNS * TILE, 3), 255, np.uint8),
                               _tiles(reference, mark)])
            path = Path(STRIPS_DIR) / config / f"{n + 1}.png"
            (out / path).parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(out / path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
            entries.append({"config": config, "instance_id": rec["instance_id"], "task": rec["task"],
                            "seed": seed["seed"], "score": seed["score"], "role": row["roles"][k],
                            "evidence": evidence(rec["suite"], seed, row), "image": path.as_posix()})
    return entries
