"""World models written here (torch; the `train` extra). `wsp generate --model reference` finds the reference world
model through this distribution's `worldsimprobe.models` entry point (pyproject.toml); importing this package needs
no torch, and a model imports torch when it is made."""
