"""diffsense.solve (being built)."""
