"""The scene's driver models and lane-change profile against their published formulas, by hand.

IDM (Treiber, Hennecke & Helbing 2000), MOBIL (Kesting, Treiber & Helbing 2007) and the quintic
(minimum-jerk) lateral profile: every number below is worked out from the formula in the test's
comment, with parameters that differ from the defaults and from each other, so that a swapped
field, a wrong constant or a flipped comparison changes a value.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene

# v0 30 m/s, T 1.2 s, s0 3 m, a 1.4 m/s2, b 2.0 m/s2, delta 3.5: no two alike, none the default
P = scene.IDMParams(desired_speed_mps=30.0, time_headway_s=1.2, min_gap_m=3.0, max_accel_mps2=1.4,
              comfort_decel_mps2=2.0, accel_exponent=3.5)


def test_desired_gap_by_hand():
    # s* = s0 + v T + v dv / (2 sqrt(a b)) = 3 + 25 * 1.2 + 25 * 5 / (2 sqrt(2.8))
    expected = 3.0 + 30.0 + 125.0 / (2.0 * math.sqrt(2.8))
    assert expected == pytest.approx(70.35089, abs=1e-5)
    np.testing.assert_allclose(float(scene.desired_gap_m(25.0, 20.0, P)), expected, rtol=1e-14)
    # a leader pulling away fast: v T + v dv / (2 sqrt(a b)) < 0, so s* is s0 alone
    assert 5.0 * 1.2 + 5.0 * (5.0 - 30.0) / (2.0 * math.sqrt(2.8)) < 0.0
    assert float(scene.desired_gap_m(5.0, 30.0, P)) == 3.0
    # the default parameters: 2 + 25 * 1.5 + 125 / (2 sqrt(1.5))
    np.testing.assert_allclose(float(scene.desired_gap_m(25.0, 20.0, scene.IDMParams())),
                               2.0 + 37.5 + 125.0 / (2.0 * math.sqrt(1.5)), rtol=1e-14)


def test_idm_acceleration_by_hand():
    # a = a_max (1 - (v / v0)^delta - (s* / s)^2) with s* from the test above
    s_star = 3.0 + 30.0 + 125.0 / (2.0 * math.sqrt(2.8))
    expected = 1.4 * (1.0 - (25.0 / 30.0) ** 3.5 - (s_star / 50.0) ** 2)
    assert expected == pytest.approx(-2.111174, abs=1e-6)
    np.testing.assert_allclose(float(scene.idm_acceleration(25.0, 50.0, 20.0, P)), expected, rtol=1e-13)
    # free road: the interaction term is (s0 / 1e4)^2-small; a = a_max (1 - (v / v0)^delta)
    free = float(scene.idm_acceleration(20.0, scene.FREE_ROAD_GAP_M, 20.0, P))
    np.testing.assert_allclose(free, 1.4 * (1.0 - (20.0 / 30.0) ** 3.5), atol=1e-4)
    assert scene.FREE_ROAD_GAP_M == 1e4


def test_idm_floors_speed_at_zero_and_gap_at_five_centimetres():
    # a reversing car is a standing one: free term 1, s* = s0 (no v T, no closing term)
    np.testing.assert_allclose(float(scene.idm_acceleration(-3.0, 6.0, 0.0, P)), 1.4 * (1.0 - (3.0 / 6.0) ** 2),
                               rtol=1e-14)
    # touching or overlapping: the gap is taken as 0.05 m, so braking is hard and finite
    touching = 1.4 * (1.0 - (10.0 / 30.0) ** 3.5 - ((3.0 + 12.0) / 0.05) ** 2)
    for gap in (0.0, -1.0, 0.05):
        np.testing.assert_allclose(float(scene.idm_acceleration(10.0, gap, 10.0, P)), touching, rtol=1e-13)
    assert float(scene.idm_acceleration(10.0, 0.06, 10.0, P)) > touching


def test_equilibrium_gap_by_hand_and_zero_acceleration_there():
    # s_e = (s0 + v T) / sqrt(1 - (v / v0)^delta)
    expected = (3.0 + 20.0 * 1.2) / math.sqrt(1.0 - (20.0 / 30.0) ** 3.5)
    assert expected == pytest.approx(31.01042, abs=1e-5)
    np.testing.assert_allclose(float(scene.equilibrium_gap_m(20.0, P)), expected, rtol=1e-14)
    np.testing.assert_allclose(float(scene.idm_acceleration(20.0, expected, 20.0, P)), 0.0, atol=1e-12)
    # at and above the desired speed no gap is enough: infinite, and its gradient finite
    assert np.isinf(float(scene.equilibrium_gap_m(30.0, P))) and np.isinf(float(scene.equilibrium_gap_m(35.0, P)))
    assert np.isfinite(float(jax.grad(lambda v: jnp.minimum(scene.equilibrium_gap_m(v, P), 1e3))(30.0)))


def test_mobil_safety_is_inclusive_at_minus_b_safe():
    p = scene.MOBILParams(safe_decel_mps2=3.0)
    got = np.asarray(scene.mobil_is_safe(jnp.array([-2.9, -3.0, -3.01, 1.0]), p))
    np.testing.assert_array_equal(got, [True, True, False, True])


def test_mobil_incentive_by_hand():
    # own +0.8; new follower 0.2 -> -0.6 (-0.8); old follower -0.3 -> 0.2 (+0.5)
    # incentive = 0.8 + p (-0.8 + 0.5) = 0.8 - 0.3 p
    for politeness in (0.0, 0.3, 1.0):
        got = scene.mobil_incentive_mps2(0.1, 0.9, 0.2, -0.6, -0.3, 0.2, scene.MOBILParams(politeness=politeness))
        np.testing.assert_allclose(float(got), 0.8 - 0.3 * politeness, rtol=1e-12, atol=1e-15)


def test_mobil_keep_right_bias_and_strict_threshold():
    p = scene.MOBILParams(threshold_mps2=0.5, safe_decel_mps2=4.0, keep_right_bias_mps2=0.25)  # binary fractions
    incentive = jnp.array([0.5, 0.5, 0.76, 0.26, 0.25, 0.75, 5.0])
    to_left = jnp.array([True, False, True, False, False, True, True])
    follower_after = jnp.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -4.5])  # the last: unsafe
    # left needs > 0.5 + 0.25 = 0.75, right needs > 0.5 - 0.25 = 0.25 (strictly)
    got = np.asarray(scene.mobil_wants_change(incentive, follower_after, to_left, p))
    np.testing.assert_array_equal(got, [False, True, True, True, False, False, False])


@pytest.mark.parametrize(("u", "progress"), [(0.0, 0.0), (0.25, 0.103515625), (0.5, 0.5),
                                             (0.75, 0.896484375), (1.0, 1.0)])
def test_quintic_progress_by_hand(u, progress):
    # 10 u^3 - 15 u^4 + 6 u^5, reached at t = start + u duration (start 2 s, duration 4 s)
    assert progress == pytest.approx(10 * u**3 - 15 * u**4 + 6 * u**5, abs=1e-15)
    np.testing.assert_allclose(float(scene.quintic_progress(2.0 + 4.0 * u, 2.0, 4.0)), progress, rtol=1e-15, atol=1e-15)


def test_lane_change_offset_and_speed_by_hand():
    t = jnp.array([0.0, 2.0, 3.0, 4.0, 6.0, 9.0])  # before, start, u = 1/4, u = 1/2, end, after
    d = np.asarray(scene.quintic_lateral_offset_m(t, 2.0, 4.0, 1.8, 5.4))
    np.testing.assert_allclose(d, [1.8, 1.8, 1.8 + 3.6 * 0.103515625, 3.6, 5.4, 5.4], rtol=1e-14)
    # dd/dt = (d1 - d0) 30 u^2 (1 - u)^2 / duration: 3.6 * 30 * 0.0625 / 4 = 1.6875 m/s at u = 1/2
    v = np.asarray(scene.quintic_lateral_speed_mps(t, 2.0, 4.0, 1.8, 5.4))
    np.testing.assert_allclose(v, [0.0, 0.0, 3.6 * 30 * (0.25**2) * (0.75**2) / 4.0, 1.6875, 0.0, 0.0],
                               rtol=1e-14, atol=1e-15)
    # the speed is the offset's derivative (central differences, float64), and a right change is negative
    for tc in (2.7, 3.9, 5.2):
        fd = (float(scene.quintic_lateral_offset_m(tc + 1e-6, 2.0, 4.0, 1.8, 5.4))
              - float(scene.quintic_lateral_offset_m(tc - 1e-6, 2.0, 4.0, 1.8, 5.4))) / 2e-6
        np.testing.assert_allclose(float(scene.quintic_lateral_speed_mps(tc, 2.0, 4.0, 1.8, 5.4)), fd, rtol=1e-7)
    assert float(scene.quintic_lateral_speed_mps(4.0, 2.0, 4.0, 5.4, 1.8)) == pytest.approx(-1.6875, rel=1e-14)
