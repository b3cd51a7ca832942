"""wsp_data: builds WorldSimProbe releases from real simulators."""

__version__ = "0.1.0"
BENCHMARK_VERSION = "0.1.0"
