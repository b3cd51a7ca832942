"""`wsp export-inputs`: an inputs-only release — what a model needs to generate a submission and nothing a model
could copy (issue: private test sets).

Per scored config: `instances.parquet` reduced to `KEEP` (ids, task and instruction, roles, episode ids and
indices, horizons, fps), `inputs/first_frames/<episode_id>.png` (frame 0 of each scored episode, lossless) and
`inputs/actions.parquet` (each scored episode's native action streams). No reference video, robot mask, state,
contact, object pose, camera or intervention is copied. `release.json` says `inputs_only` and names the full
release only by the SHA-256 of its `release.json` (never a seed). `wsp generate --release INPUTS` runs a model on
it; the submission is scored against the full release, which the maintainer keeps private.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import pyarrow as pa
import pyarrow.parquet as pq

from wsp_eval.episode import episode_actions
from wsp_eval.reference import reference_frames
from wsp_eval.release_format import FIRST_FRAME, INPUT_ACTIONS, INPUTS_ONLY, INSTANCES, RELEASE_JSON, load_release
from wsp_eval.submission import test_configs

KEEP = ("instance_id", "suite", "platform", "task", "instruction", "roles", "episode_ids", "episode_indices",
        "num_frames", "fps")
ACTION_KEYS = ("action", "action.ee", "action.joint")
README = """# WorldSimProbe inputs-only release

What a world model needs to generate a submission, and nothing more: per scored config, `instances.parquet`
(ids, task, instruction, episode ids, horizons, fps), `inputs/first_frames/<episode_id>.png` and
`inputs/actions.parquet`. Generate with `wsp generate --model MODULE:CALLABLE --release <this folder> --out SUB`
and send the submission to the maintainers, who score it against the private release whose `release.json`
has SHA-256 {sha}.
"""


class ExportError(RuntimeError):
    """A release that cannot be exported (already inputs-only, unreadable)."""


def is_inputs_only(release: Path) -> bool:
    return bool(load_release(release).get(INPUTS_ONLY))


def export_inputs(release: Path, out: Path, progress: bool = True) -> dict:
    """Write the inputs-only release of `release` to `out` (overwriting files there); its release.json."""
    from tqdm import tqdm

    release, out = Path(release), Path(out)
    meta = load_release(release)
    if meta.get(INPUTS_ONLY):
        raise ExportError(f"{release}: already an inputs-only release")
    if out.resolve() == release.resolve():
        raise ExportError(f"{out}: the inputs-only release must go to another folder than the release")
    configs = test_configs(release)
    sha = hashlib.sha256((release / RELEASE_JSON).read_bytes()).hexdigest()
    rows_of = {c: pq.read_table(release / c / INSTANCES).to_pylist() for c in configs}
    total = sum(len(r["episode_ids"]) for rows in rows_of.values() for r in rows)
    summary = {}
    with tqdm(total=total, desc="export inputs", unit="episode", disable=not progress) as bar:
        for config in configs:
            rows = rows_of[config]
            (out / config / FIRST_FRAME).parent.mkdir(parents=True, exist_ok=True)
            episodes = []
            for row in rows:
                for episode_id, index in zip(row["episode_ids"], row["episode_indices"]):
                    frame0 = reference_frames(release / config, int(index))[0]
                    path = out / config / FIRST_FRAME.format(episode_id=episode_id)
                    if not cv2.imwrite(str(path), cv2.cvtColor(frame0, cv2.COLOR_RGB2BGR)):
                        raise ExportError(f"{path}: cannot write")
                    ep = {"episode_index": int(index), "episode_id": episode_id}
                    for key in ACTION_KEYS:
                        try:
                            ep[key] = episode_actions(release / config, int(index), key).tolist()
                        except ValueError:  # this platform stores no such stream
                            pass
                    episodes.append(ep)
                    bar.update()
            kept = [{k: r[k] for k in KEEP if k in r} for r in rows]
            pq.write_table(pa.Table.from_pylist(kept), out / config / INSTANCES)
            pq.write_table(pa.Table.from_pylist(episodes), out / config / INPUT_ACTIONS)
            summary[config] = {"instances": len(rows), "episodes": len(episodes)}
    manifest = {"version": meta["version"], INPUTS_ONLY: True, "source_release_json_sha256": sha,
                "configs": summary}
    (out / RELEASE_JSON).write_text(json.dumps(manifest, indent=1, sort_keys=True))
    (out / "README.md").write_text(README.format(sha=sha))
    return manifest
