"""World models written here (torch; the `train` extra). The scoring-only install never imports this package."""
