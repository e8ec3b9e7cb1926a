"""Test-wide settings: float64 available (gradient checks need it), paths to shared test data."""

from __future__ import annotations

from pathlib import Path

import jax
import pytest

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
NGSIM_WEIGHTS = SHARED / "weights" / "ngsim"


@pytest.fixture
def ngsim_checkpoint():
    """Path factory for a published NGSIM checkpoint; skips when ../shared is absent."""

    def get(name: str) -> Path:
        path = NGSIM_WEIGHTS / name
        if not path.is_file():
            pytest.skip(f"published checkpoint {path} not present (../shared/weights/ngsim)")
        return path

    return get
