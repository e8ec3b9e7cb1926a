"""diffsense.objective (being built)."""
