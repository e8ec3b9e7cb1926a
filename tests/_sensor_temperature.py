"""The documented property of a sensor's `temperature`: it acts as every soft-gate temperature
of the config (occlusion's included) multiplied by it. Shared by the sensors' pinned tests."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diffsense import config as cfg
from diffsense.sensors._geometry import Tracks


def scaled(config, factor):
    """`config` with every soft-gate temperature multiplied by `factor`."""
    t = config.temperature
    return cfg.replace(config, temperature=dataclasses.replace(
        t, **{f.name: getattr(t, f.name) * factor for f in dataclasses.fields(t)}))


def assert_temperature_scales_the_config(terms, config, scene, temperature, gate, vehicle, least):
    """The soft gates of `terms` at `temperature` equal those of the scaled config at 1; and the
    margin of gate `gate` of `vehicle` (frame 0) moves by more than `least` between the config
    scaled by 2 and by 1/2 (the scene is sensitive: the comparison can fail)."""
    tracks = Tracks.of(scene)
    got = terms(tracks, config.params, config, "soft", temperature)[0]
    want = terms(tracks, config.params, scaled(config, temperature), "soft", 1.0)[0]
    for (m_got, t_got), (m_want, t_want) in zip(got, want):
        np.testing.assert_allclose(np.asarray(m_got), np.asarray(m_want), rtol=1e-12, atol=1e-12)
        assert float(t_got) == pytest.approx(float(t_want), rel=1e-12)
    margin = {f: float(terms(tracks, config.params, scaled(config, f), "soft", 1.0)[0][gate][0][vehicle, 0])
              for f in (2.0, 0.5)}
    assert abs(margin[2.0] - margin[0.5]) > least, margin
