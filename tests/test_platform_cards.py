"""The platform cards of the docs site (docs/platforms/<name>.md) are generated from the platform kits by
`scripts/platform_cards.py`; the committed cards must equal what it generates now, and it must never import a
simulator (it runs in a fresh process with the simulator packages blocked)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "platform_cards.py"


def test_committed_cards_equal_the_generated_ones():
    run = subprocess.run([sys.executable, str(SCRIPT), "--check"], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_every_built_in_platform_has_a_card_with_notes():
    listed = subprocess.run([sys.executable, "-c", "from wsp_data.platforms import KITS; print(' '.join(KITS))"],
                            cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    assert listed, "no platform registered"
    for name in listed:
        card = (ROOT / "docs" / "platforms" / f"{name}.md").read_text()
        notes = card.split("<!-- platform_cards: end of the generated part -->", 1)[1]
        assert "## " in notes, f"{name}: the card has no hand-written notes after its generated part"
