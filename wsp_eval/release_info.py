"""`wsp info`: a release summarised from its `release.json`, dataset card and config metadata."""

from __future__ import annotations

import json
import re
from pathlib import Path

from wsp_eval.release_format import CARD, RELEASE_JSON, STAGING_DIR, load_release


def describe(root: Path) -> str:
    """A human-readable summary of a release for `wsp info`."""
    root = Path(root)
    rel = load_release(root)
    card = (root / CARD).read_text() if (root / CARD).exists() else ""
    licence = next((line.split(":", 1)[1].strip() for line in card.splitlines() if line.startswith("license:")), "?")
    lines = [f"{root}: WorldSimProbe {rel['version']} built by {rel['code_version']}; licence {licence} (dataset card)",
             f"{'config':<16} {'split':>5} {'instances':>9} {'episodes':>9} {'tasks':>6}  build"]
    for name, c in sorted(rel["configs"].items()):
        n = c.get("counts", {})
        b = c["build_config"]
        info = root / name / "meta" / "info.json"
        split = ",".join(json.loads(info.read_text()).get("splits", {})) if info.exists() else "?"
        lines.append(f"{name:<16} {split:>5} {n.get('instances', '?'):>9} {n.get('episodes', '?'):>9} "
                     f"{n.get('tasks', '?'):>6}  count={b['count']} seed={b['seed']} tasks={','.join(b['tasks'])}")
    in_card = set(re.findall(r"config_name: (\S+)", card))
    if card and in_card != set(rel["configs"]):
        lines.append(f"the dataset card lists configs {sorted(in_card)}, the release holds {sorted(rel['configs'])}: "
                     "rebuild the card (any `wsp build` re-writes it)")
    staged = root / STAGING_DIR
    if staged.exists() and any(staged.iterdir()):
        lines.append(f"unfinished builds staged under {staged}: re-run the same `wsp build` to resume")
    lines.append(f"{len(rel.get('files', {}))} files with sha256 in {RELEASE_JSON}")
    return "\n".join(lines)
