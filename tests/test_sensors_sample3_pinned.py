"""Kills of the survivors of the fourth sensors mutation sample (seed 3, docs/mutation.md): a
one-sensor list is that sensor, the unknown-parameter error lists the known names, and integer
inputs to the rain model come in at the default float precision. The domain
check's batch test pins what its `ndim` guard is for; under numpy >= 2.4 a batch never reaches the
guard (no array of ndim > 0 converts to a float), so its mutant is equivalent there."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.sensors import make_sensor
from diffsense.sensors._config import load_config
from diffsense.sensors._params import check_params
from diffsense.sensors._suite import Camera, Radar
from diffsense.sensors._weather import rain_coefficients, rain_two_way_loss_db


def test_a_one_sensor_list_is_that_sensor_not_a_suite():
    camera = make_sensor(["camera"])
    assert isinstance(camera, Camera) and camera.config == make_sensor("camera").config
    paper = make_sensor(("radar",), profile="paper")
    assert isinstance(paper, Radar) and paper.config == make_sensor("radar", profile="paper").config
    assert paper.config != make_sensor("radar").config  # the profile reached the member


def test_an_unknown_parameter_names_the_known_ones():
    known = "hfov_deg, vfov_deg, range_m, tx_power_dbm, noise_figure_db, yaw_deg, mount_x_m, mount_y_m"
    with pytest.raises(InputError) as caught:
        make_sensor("radar").spec("fov")
    assert str(caught.value) == f"unknown radar parameter 'fov' (known: {known})"


def test_the_domain_check_leaves_a_batch_of_values_to_its_caller():
    # A solver may hold r as a batch (one value per vmapped lane): its values are checked where
    # they are scalars. Out of the domain, a scalar is refused and a batch of one is not.
    params = load_config("radar").params
    batch = dataclasses.replace(params, hfov_deg=np.array([400.0]))
    assert check_params(batch) is batch
    with pytest.raises(InputError, match="hfov_deg = 400 is outside its domain"):
        check_params(dataclasses.replace(params, hfov_deg=np.float64(400.0)))


def test_an_integer_frequency_is_computed_at_the_default_float_precision():
    # The suite runs with x64 (tests/conftest.py): an int32 frequency is promoted to float64, as a
    # Python float is, not computed at float32 (which log10 of an int32 would give).
    k, alpha = rain_coefficients(np.int32(77))
    k_ref, alpha_ref = rain_coefficients(77.0)
    assert k.dtype == alpha.dtype == jnp.float64
    assert float(k) == float(k_ref) and float(alpha) == float(alpha_ref)
    loss = rain_two_way_loss_db(np.array([100], np.int64), np.float32(5.0))
    assert loss.dtype == jnp.float64  # the integer range, too, comes in at the default float
