"""The threshold detection law, named where a test is about it.

The physical profile's default laws are the probabilistic ones (Swerling I radar, the
confidence camera); the threshold gates and their temperatures are the paper profile's law and a
sensor config of the physical one. A test of the gates says so by loading these files.
"""

from __future__ import annotations

from pathlib import Path

from diffsense import sensors

LAWS = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"
THRESHOLD = {"radar": str(LAWS / "radar_threshold.toml"), "camera": str(LAWS / "camera_threshold.toml")}


def threshold_config(name: str, profile: str = "physical"):
    """The sensor's constants of `profile` with the threshold law."""
    return sensors.load_config(name, THRESHOLD[name], profile)
