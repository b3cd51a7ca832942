"""wsp_data: builds WorldSimProbe releases from real simulators."""

__version__ = "0.1.0"
