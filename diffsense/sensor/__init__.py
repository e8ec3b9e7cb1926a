"""diffsense.sensor (being built)."""
