"""Is a release's T4 (and T5) evaluated object what the camera sees at its projected centre? (docs/validity.md, T4 tracker)

    .venv/bin/python benchmarks/centre_sight.py RELEASE [RELEASE ...] [--out FILE.json]

T4 seeds its query grid around the evaluated object's projected frame-0 centre; where another object stands in
front of that point, the grid follows the occluder, and a generation that moves the evaluated object could pass.
The builder drops such an instance (`object_hidden_at_centre`, `wsp_data.builders.t4.centre_hidden`). This script
checks a release's instances after the fact: for each T4 instance it rebuilds frame 0 in the
simulator (the seed's scene with the instance's placement: the distractor's pose, the moved target's pose, or
none for false contact; for T5, whose judge is given the same frame-0 point, the scene with its props),
confirms that the rebuilt frame is the stored one (the first reference frame, and the stored
`object_pixel_256`), and applies the build's check to the rendered object labels. Needs the simulators.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from tqdm import tqdm

from wsp_data.builders.t4 import CENTRE_SIGHT_MAX, centre_gap, centre_hidden
from wsp_data.platforms import kit
from wsp_eval.reference import iter_reference_frames
from wsp_eval.release_format import INSTANCES, RELEASE_JSON, split_config
from wsp_eval.suites.reference import InstanceReference
from wsp_eval.tracking import frame_size, project

FRAME_TOLERANCE = 1.0  # grey levels: mean |rebuilt − stored| frame 0 (the stored video is lossless: 0 measured)
OWN_PIXEL = 0.5 ** 0.5  # native px: a centre within this of a pixel centre may lie inside that pixel
PIXEL_TOLERANCE = 1e-3  # px: rebuilt projected centre against the stored `object_pixel_256`


def placements(row: dict, suite: str) -> dict[str, np.ndarray]:
    """The instance's frame-0 placement, from its stored intervention parameters: T4's distractor or moved target,
    T5's props."""
    params = json.loads(row["interventions"])["reference"]
    if suite == "t5":
        return {name: np.asarray(pose, dtype=np.float64) for name, pose in params["placements"].items()}
    key = {"distractor": "pose", "spatial_proximity": "to"}.get(row["kind"])
    return {row["evaluated_object"]: np.asarray(params[key], dtype=np.float64)} if key else {}


def frame_zero(platform, seed: int, objects: tuple[str, ...], placed: dict[str, np.ndarray]):
    """Frame 0 of a replay (its reset) recording `objects`: LIBERO and ALOHA re-index their objects with
    `track`, ManiSkill reads `object_names` (as the rigs' `replay` does)."""
    if hasattr(platform, "track"):
        platform.track(objects)
    else:
        platform.object_names = objects
    return platform.reset(seed, placed)


def check_config(cfg: Path, suite: str, platform: str) -> list[dict]:
    k_ = kit(platform)
    rows = pq.read_table(cfg / INSTANCES).to_pylist()
    groups = defaultdict(list)  # one rig per task (T4) or per task and scene addition (T5), as the builders keep
    for r in rows:
        groups[(r["task"], k_.t5_scene(r["primitive"]) if suite == "t5" else None)].append(r)
    out = []
    bar = tqdm(total=len(rows), desc=cfg.name, unit="inst")
    for (task, scene), group_rows in sorted(groups.items(), key=lambda g: str(g[0])):
        rig = k_.t5_rig(task, scene) if suite == "t5" else k_.t4_rig(task)
        intrinsic, extrinsic = rig.render.camera_params()
        try:
            for r in group_rows:
                ob = frame_zero(rig.render, int(r["seed"]), tuple(r["objects"]), placements(r, suite))
                k = int(r["evaluated_index" if suite == "t5" else "evaluated_object_index"])
                pixel = project(ob.object_poses[k, :3], intrinsic, extrinsic, frame_size(ob.rgb))
                stored = next(iter(iter_reference_frames(cfg, InstanceReference(cfg, r).episode("reference"))))
                frame_diff = float(np.abs(stored.astype(np.int16) - ob.rgb).mean())
                pixel_diff = float(np.abs(pixel - r["object_pixel_256"]).max())
                out.append({"instance_id": r["instance_id"], "task": task,
                            "kind": r["primitive" if suite == "t5" else "kind"],
                            "object": r["evaluated_object"], "rebuilt": frame_diff <= FRAME_TOLERANCE
                            and pixel_diff <= PIXEL_TOLERANCE, "frame_diff": frame_diff, "pixel_diff": pixel_diff,
                            "object_pixels": int((ob.objects == k + 1).sum()),
                            "centre_gap": centre_gap(ob.objects, k, pixel),
                            "hidden": centre_hidden(ob.objects, k, pixel)})
                bar.update()
        finally:
            rig.close()
    bar.close()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("releases", nargs="+", type=Path)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    results = {}
    for rel in args.releases:
        for name in json.loads((rel / RELEASE_JSON).read_text())["configs"]:
            suite, platform = split_config(name)
            if suite in ("t4", "t5"):
                results[f"{rel.name}/{name}"] = check_config(rel / name, suite, platform)
    for name, rs in results.items():
        hidden = [r for r in rs if r["hidden"]]
        gaps = np.array([r["centre_gap"] if r["centre_gap"] is not None else np.inf for r in rs])
        print(f"{name}: {len(rs)} instances, rebuilt as stored {sum(r['rebuilt'] for r in rs)}; the evaluated "
              f"object's centre on its own pixel (gap <= {OWN_PIXEL:.2f} px) {int((gaps <= OWN_PIXEL).sum())}, at a "
              f"neighbouring pixel {int(((gaps > OWN_PIXEL) & (gaps <= CENTRE_SIGHT_MAX)).sum())}, hidden "
              f"{len(hidden)} ({dict(Counter(r['kind'] for r in hidden))})")
        for r in hidden:
            print(f"  {r['instance_id']} {r['kind']} {r['object']}: {r['hidden']}")
    if args.out:
        args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
