"""diffsense.tracks (being built)."""
