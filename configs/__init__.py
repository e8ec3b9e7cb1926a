"""The shipped default configs, installed as `diffsense._configs` (see pyproject.toml)."""
