"""The old name of diffsense.predictors, kept so that `python -m diffsense.predict` still works."""
