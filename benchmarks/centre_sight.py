"""Is a release's T4 evaluated object what the camera sees at its projected centre? (docs/validity.md §2)

    .venv/bin/python benchmarks/centre_sight.py RELEASE [RELEASE ...] [--out FILE.json]

T4 seeds its query grid around the evaluated object's projected frame-0 centre; where another object stands in
front of that point, the grid follows the occluder, and a generation that moves the evaluated object could pass.
Builds since 2026-11-26 drop such an instance (`object_hidden_at_centre`, `wsp_data.builders.t4.centre_hidden`).
This script checks the instances of releases built before: for each T4 instance it rebuilds frame 0 in the
simulator (the seed's scene with the instance's placement: the distractor's pose, the moved target's pose, or
none for false contact), confirms that the rebuilt frame is the stored one (the first reference frame, and the
stored `object_pixel_256`), and applies the build's check to the rendered object labels. Needs the simulators.
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
PIXEL_TOLERANCE = 1e-3  # px: rebuilt projected centre against the stored `object_pixel_256`


def placements(row: dict) -> dict[str, np.ndarray]:
    """The instance's frame-0 placement, from its stored intervention parameters."""
    params = json.loads(row["interventions"])["reference"]
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


def check_config(cfg: Path, platform: str) -> list[dict]:
    rows = pq.read_table(cfg / INSTANCES).to_pylist()
    by_task = defaultdict(list)
    for r in rows:
        by_task[r["task"]].append(r)
    out = []
    bar = tqdm(total=len(rows), desc=cfg.name, unit="inst")
    for task, task_rows in sorted(by_task.items()):
        rig = kit(platform).t4_rig(task)
        try:
            for r in task_rows:
                ob = frame_zero(rig.render, int(r["seed"]), tuple(r["objects"]), placements(r))
                k = int(r["evaluated_object_index"])
                pixel = project(ob.object_poses[k, :3], rig.intrinsic, rig.extrinsic, frame_size(ob.rgb))
                stored = next(iter(iter_reference_frames(cfg, InstanceReference(cfg, r).episode("reference"))))
                frame_diff = float(np.abs(stored.astype(np.int16) - ob.rgb).mean())
                pixel_diff = float(np.abs(pixel - r["object_pixel_256"]).max())
                out.append({"instance_id": r["instance_id"], "task": task, "kind": r["kind"],
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
            if suite == "t4":
                results[f"{rel.name}/{name}"] = check_config(rel / name, platform)
    for name, rs in results.items():
        hidden = [r for r in rs if r["hidden"]]
        gaps = np.array([r["centre_gap"] if r["centre_gap"] is not None else np.inf for r in rs])
        print(f"{name}: {len(rs)} instances, rebuilt exactly {sum(r['rebuilt'] for r in rs)}, evaluated object "
              f"hidden at its centre {len(hidden)} ({dict(Counter(r['kind'] for r in hidden))}); centre gap 0 in "
              f"{int((gaps == 0).sum())}, largest of the others {gaps[gaps <= CENTRE_SIGHT_MAX].max():.2f} px")
        for r in hidden:
            print(f"  {r['instance_id']} {r['kind']} {r['object']}: {r['hidden']}")
    if args.out:
        args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
