"""The old name of diffsense.sensors, kept so that `python -m diffsense.sensor` still works."""
