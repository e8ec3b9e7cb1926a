"""diffsense.predict (being built)."""
