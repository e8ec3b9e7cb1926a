"""Fill policies for missed detections: the hard fills against plain-loop definitions, the soft
fills as expectations over detection patterns and by hand, continuity and gradients in p."""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.tracks import FILL_POLICIES, fill_window


def _hard_fill(z, seen, policy):
    """A missed point's value for one detection pattern, by scanning outwards from it."""
    out = z.copy()
    for k in np.flatnonzero(~seen):
        before = [i for i in range(k - 1, -1, -1) if seen[i]][:1]
        after = [i for i in range(k + 1, len(z)) if seen[i]][:1]
        if policy == "zero" or not (before or after):
            out[k] = 0.0
        elif policy == "hold":
            out[k] = z[before[0]] if before else 0.0
        elif before and after:
            a, b = before[0], after[0]
            out[k] = ((b - k) * z[a] + (k - a) * z[b]) / (b - a)
        else:
            out[k] = z[(before or after)[0]]
    return out


def _expectation(z, p, policy):
    """E[filled window] over all 2^W independent detection patterns with probabilities p."""
    total = np.zeros_like(z)
    for pattern in itertools.product((False, True), repeat=len(p)):
        seen = np.array(pattern)
        total += np.prod(np.where(seen, p, 1 - p)) * _hard_fill(z, seen, policy)
    return total


def test_the_policies_are_zero_hold_and_interp():
    assert FILL_POLICIES == ("zero", "hold", "interp")
    with pytest.raises(ValueError, match="nearest"):
        fill_window(jnp.zeros((3, 2)), jnp.ones(3), "nearest")


@pytest.mark.parametrize("policy", FILL_POLICIES)
def test_hard_fill_matches_definition(policy):
    rng = np.random.default_rng(0)
    z = rng.normal(size=(64, 31, 2)) * 10
    mask = rng.random((64, 31)) < 0.5
    mask[0] = False  # a window with no detection at all
    mask[1] = True
    mask[2, :5] = False
    got = jax.jit(fill_window, static_argnums=2)(jnp.asarray(z), jnp.asarray(mask, z.dtype), policy)
    want = np.stack([_hard_fill(z[i], mask[i], policy) for i in range(64)])
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-10)


@pytest.mark.parametrize("policy", ["zero", "hold"])
def test_soft_zero_and_hold_are_exact_expectations(policy):
    rng = np.random.default_rng(3)
    z, p = rng.normal(size=(7, 2)) * 10, rng.uniform(0.05, 0.95, 7)
    np.testing.assert_allclose(np.asarray(fill_window(z, p, policy)), _expectation(z, p, policy), atol=1e-12)


def test_soft_hold_by_hand():
    # z = 1, 2, 3 with p = 1, 1/2, 1/2: the last point is 3 (p 1/2), else 2 (1/4), else 1 (1/4).
    got = np.asarray(fill_window(np.array([[1.0, 0], [2, 0], [3, 0]]), np.array([1, 0.5, 0.5]), "hold"))
    np.testing.assert_allclose(got[:, 0], [1.0, 1.5, 2.25])


def test_soft_interp_weights_below_one_by_hand():
    # The soft interp's recurrences on z = 2, 6 m with p = 1/2, 1/2. Forward holds F, any-detection
    # h, steps-since a: F0 = 1, h0 = 1/2, a0 = 1/2; backward (from the right) B0 = 1/2 * 2 + 1/2 *
    # (1/2 * 6) = 5/2, h'0 = 3/4, b0 = 3/4. At k = 0 the weights b0 h0 + a0 h'0 = 3/8 + 3/8 = 3/4
    # (below 1, as no hard pattern gives), the fill (b0 F0 + a0 B0) / (3/4) = (3/4 + 5/4) / (3/4)
    # = 8/3, and the point 1/2 * 2 + 1/2 * 8/3 = 7/3 m.
    got = np.asarray(fill_window(np.array([[2.0, 0.0], [6.0, 0.0]]), np.array([0.5, 0.5]), "interp"))
    np.testing.assert_allclose(got[0], [7.0 / 3.0, 0.0], rtol=1e-12)


@pytest.mark.xfail(strict=True, reason=(
    "soft interp blends the uncertain point's own measurement into its fill (the forward and "
    "backward holds at k include p_k z_k): 4.25 instead of 0.5 * 4 + 0.5 * 5 = 4.5"))
def test_soft_interp_single_uncertain_point():
    # Detections at 0 and 10 m for sure, the middle one (measured 4 m) with p = 1/2: missed, it
    # is interpolated to 5 m, so its expectation is 0.5 * 4 + 0.5 * 5 = 4.5 m.
    z = np.array([[0.0, 0.0], [4.0, 0.0], [10.0, 0.0]])
    got = np.asarray(fill_window(z, np.array([1.0, 0.5, 1.0]), "interp"))
    np.testing.assert_allclose(got[1, 0], 4.5)


@pytest.mark.parametrize("policy", FILL_POLICIES)
def test_soft_fill_is_continuous_in_p_with_finite_gradient(policy):
    rng = np.random.default_rng(1)
    z = jnp.asarray(rng.normal(size=(31, 2)))
    mask = jnp.asarray(rng.random(31) < 0.4, jnp.float64)
    hard = fill_window(z, mask, policy)
    for eps in (1e-3, 1e-6):
        # p within eps of the 0/1 pattern: the soft fill is within O(eps) of the hard one.
        near = mask * (1 - eps) + (1 - mask) * eps
        gap = float(jnp.max(jnp.abs(fill_window(z, near, policy) - hard)))
        assert gap < 100 * eps * float(jnp.max(jnp.abs(z)))
    for p_value in (0.0, 0.3, 1.0):
        g = jax.grad(lambda p: jnp.sum(fill_window(z, p, policy)))(jnp.full(31, p_value))
        assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.parametrize("policy", FILL_POLICIES)
def test_fill_gradient_matches_finite_differences(policy):
    rng = np.random.default_rng(2)
    z = jnp.asarray(rng.normal(size=(31, 2)))
    p0 = jnp.asarray(rng.uniform(0.05, 0.95, 31))
    w = jnp.asarray(rng.normal(size=(31, 2)))

    def loss(p):
        return jnp.sum(w * fill_window(z, p, policy))

    direction = jnp.asarray(rng.normal(size=31))
    h = 1e-6
    fd = (loss(p0 + h * direction) - loss(p0 - h * direction)) / (2 * h)
    np.testing.assert_allclose(float(jax.grad(loss)(p0) @ direction), float(fd), rtol=1e-6)
