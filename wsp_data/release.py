"""Release-level files: `release.json` (semver, code version, build configs, per-file sha256, counts),
the dataset card `README.md` rendered from `cards/`, and `croissant.json`.

A folder is a WorldSimProbe release when it holds `release.json` (`wsp info` summarises one:
`wsp_eval.release_info`).
"""

from __future__ import annotations

from collections import Counter
import json
import subprocess
from pathlib import Path

import jinja2
import pyarrow.parquet as pq

import wsp_data
from wsp_data.platforms import kit
from wsp_data.schema import (
    CARD, CODEBASE_VERSION, CROISSANT, INSTANCES, LOG_DIR, MAX_OBJECTS, PRIVATE_BASE, PRIVATE_PRIME, PRIVATE_RANGE,
    RELEASE_JSON, SEED_BASE, SEED_SPAN, STAGING_DIR,
)
from wsp_eval.integrity import sha256
from wsp_eval.release_format import BENCHMARK_VERSION, ReleaseError, load_release

CARDS_DIR = Path(__file__).resolve().parent.parent / "cards"


def code_version() -> str:
    """Package version plus the git commit of the checkout that built it, when there is one."""
    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                                text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return f"worldsimprobe {wsp_data.__version__} ({commit}{'-dirty' if dirty else ''})"
    except (OSError, subprocess.SubprocessError):
        return f"worldsimprobe {wsp_data.__version__}"


def write_release(root: Path, suites: dict) -> dict:
    """(Re)write release.json, README.md and croissant.json from the configs present under `root`.

    `suites` maps suite name → the suite's builder class (for titles and descriptions)."""
    root = Path(root)
    previous = load_release(root) if (root / RELEASE_JSON).exists() else {"configs": {}}
    configs = {}
    for cfg_dir in sorted(p for p in root.iterdir() if (p / INSTANCES).exists() and p.is_dir()):
        name = cfg_dir.name
        entry = previous["configs"].get(name)
        if entry is None:
            raise ReleaseError(f"{cfg_dir}: config folder without a build record in {RELEASE_JSON}")
        configs[name] = entry
    card_configs = []
    for name, entry in configs.items():
        table = pq.read_table(root / name / INSTANCES, columns=["task", "episode_indices", "source"])
        tasks = sorted(set(table.column("task").to_pylist()))
        sources = dict(sorted(Counter(s.split(":")[0].split(" (")[0] for s in table.column("source").to_pylist()).items()))
        episodes = sum(len(x) for x in table.column("episode_indices").to_pylist())
        entry["counts"] = {"instances": table.num_rows, "episodes": episodes, "tasks": len(tasks)}
        builder = suites[entry["build_config"]["suite"]]
        card_configs.append(dict(name=name, suite=entry["build_config"]["suite"], suite_title=builder.title,
                                 suite_description=builder.description, platform=entry["build_config"]["platform"],
                                 instances=table.num_rows, episodes=episodes, tasks=tasks, sources=sources))
    if not card_configs:
        raise ReleaseError(f"{root}: no assembled config to describe")
    release = {
        "name": root.name, "version": BENCHMARK_VERSION, "code_version": code_version(),
        "codebase_version": CODEBASE_VERSION, "configs": configs,
        "seed_ranges": {**{k: [v, v + SEED_SPAN - 1] for k, v in SEED_BASE.items()},
                        PRIVATE_RANGE: [PRIVATE_BASE, PRIVATE_BASE + PRIVATE_PRIME - 1]},
    }
    _render_card(root, release, card_configs)
    _write_croissant(root, release, card_configs)
    release["files"] = {str(p.relative_to(root)): sha256(p) for p in sorted(root.rglob("*"))
                        if p.is_file() and p.name != RELEASE_JSON and not _ignored(p.relative_to(root))}
    (root / RELEASE_JSON).write_text(json.dumps(release, indent=1, sort_keys=True) + "\n")
    return release


def record_build(root: Path, config: str, build_config: dict) -> None:
    """Note in release.json that `config` was assembled from `build_config` (before write_release)."""
    root = Path(root)
    release = load_release(root) if (root / RELEASE_JSON).exists() else {"configs": {}}
    release.setdefault("configs", {})[config] = {"build_config": build_config}
    (root / RELEASE_JSON).write_text(json.dumps(release, indent=1, sort_keys=True) + "\n")


def _ignored(rel: Path) -> bool:
    return rel.parts[0] in (STAGING_DIR, LOG_DIR, ".cache") or rel.parts[0].endswith(".writing")


def _render_card(root: Path, release: dict, card_configs: list[dict]) -> None:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(CARDS_DIR), undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True)
    platforms = [kit(p).info for p in dict.fromkeys(c["platform"] for c in card_configs)]
    text = env.get_template("dataset_card.md.j2").render(
        name=root.name, version=release["version"], code_version=release["code_version"],
        codebase_version=CODEBASE_VERSION, configs=card_configs, fps=platforms[0].fps, max_objects=MAX_OBJECTS,
        platforms=platforms,
    )
    (root / CARD).write_text(text)


def _write_croissant(root: Path, release: dict, card_configs: list[dict]) -> None:
    """Croissant 1.0 metadata with the core fields and the responsible-AI (RAI) fields."""
    infos = [kit(p).info for p in dict.fromkeys(c["platform"] for c in card_configs)]
    sizes = ", ".join(dict.fromkeys(f"{p.width}x{p.height}" for p in infos))
    doc = {
        "@context": {"@vocab": "https://schema.org/", "cr": "http://mlcommons.org/croissant/",
                     "rai": "http://mlcommons.org/croissant/RAI/", "sc": "https://schema.org/"},
        "@type": "sc:Dataset", "conformsTo": "http://mlcommons.org/croissant/1.0",
        "name": root.name, "version": release["version"], "license": "https://www.apache.org/licenses/LICENSE-2.0",
        "description": "WorldSimProbe: simulator-validated diagnostic instances for action-conditioned world models.",
        "keywords": ["world models", "robotics", "benchmark", "LeRobot"],
        "distribution": [{"@type": "cr:FileObject", "@id": f"{c['name']}/instances.parquet",
                          "contentUrl": f"{c['name']}/instances.parquet", "encodingFormat": "application/x-parquet",
                          "sha256": sha256(root / c["name"] / INSTANCES)} for c in card_configs],
        "recordSet": [{"@type": "cr:RecordSet", "@id": c["name"], "name": c["name"],
                       "description": c["suite_description"]} for c in card_configs],
        "rai:dataCollection": f"Generated in simulation ({'; '.join(p.simulator for p in infos)}; CPU) from scripted "
                              "expert trajectories and controlled interventions; validated from simulator state.",
        "rai:dataCollectionType": "Simulation",
        "rai:personalSensitiveInformation": "None: no people, no personal data.",
        "rai:dataBiases": "Scripted experts move in straight end-effector lines at fixed speeds; tasks cover "
                          f"tabletop manipulation by {', '.join(dict.fromkeys(p.robot_type for p in infos))} only.",
        "rai:dataLimitations": f"Simulator rendering at {sizes}; references are simulator ground truth, not real "
                               "robot footage.",
        "rai:dataUseCases": "Evaluating and diagnosing action-conditioned video world models; training them.",
        "rai:dataSocialImpact": "Diagnostic benchmark; no foreseeable direct harm.",
    }
    (root / CROISSANT).write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
