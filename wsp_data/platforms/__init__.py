"""Simulator platforms. Simulators are imported only inside this package."""
