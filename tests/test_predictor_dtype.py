"""A predictor computing at its own float precision (`with_compute_dtype`) and the objective's
choice of it (`Problem.predictor_dtype`).

The cast hands every float input to the predictor in its dtype and its output back in the
caller's, with the identity as its derivative; it must not change what E means: E and dE/dr with a
float32 CS-LSTM agree with the all-float64 objective's value and with central finite differences
of it, to float32's rounding; the output and E stay float64; the choice is checked at the door.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.predictors import (
    CSLSTM_SPEC,
    CastPredictor,
    PredictorInputs,
    init_predictor,
    with_compute_dtype,
)
from diffsense.runtime import InputError
from tests._laws import THRESHOLD


def _inputs(dtype, b=6, m=3, seed=0):
    rng = np.random.default_rng(seed)
    hist = np.stack([25 * 0.2 * np.arange(-15, 1)[None].repeat(b, 0), rng.normal(0, 0.3, (b, 16))], -1)
    nbr = hist[:, None] + rng.normal(0, 10, (b, m, 1, 2))
    slot = np.stack([rng.choice(39, m, replace=False) for _ in range(b)]).astype(np.int32)
    return PredictorInputs(hist=jnp.asarray(hist, dtype), nbr_hist=jnp.asarray(nbr, dtype),
                           nbr_slot=jnp.asarray(slot), nbr_weight=jnp.asarray(rng.uniform(0.2, 1, (b, m)), dtype))


def test_cast_runs_the_inner_predictor_in_float32_and_returns_float64():
    inner = init_predictor(seed=1)
    cast = with_compute_dtype(inner, "float32")
    x64_in = _inputs(jnp.float64)
    out = jax.jit(lambda p, x: p(x))(cast, x64_in)  # the predictor is an argument: a pytree
    assert out.dtype == jnp.float64
    # Computed in float32: every output is a float32 number, and it is the float32 prediction.
    np.testing.assert_array_equal(np.asarray(out), np.asarray(out).astype(np.float32).astype(np.float64))
    x32_in = jax.tree.map(lambda a: a.astype(jnp.float32) if a.dtype == jnp.float64 else a, x64_in)
    want = jax.jit(lambda p, x: p(x))(inner, x32_in)
    np.testing.assert_allclose(np.asarray(out), np.asarray(want, np.float64), rtol=2e-6, atol=1e-7)
    # ... while float64 inside gives float64 numbers, near them.
    full = np.asarray(jax.jit(lambda p, x: p(x))(inner, x64_in))
    assert np.any(full != full.astype(np.float32).astype(np.float64))
    assert np.max(np.abs(full - np.asarray(out))) < 1e-5


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Probe:
    """A predictor with float32 parameters (as the CS-LSTM's are): its output is hist's last point
    times `scale` plus the machine epsilon of the dtype it computes in; it checks that every
    float input comes in that one dtype, the integers untouched."""

    scale: jax.Array
    spec = CSLSTM_SPEC
    validation_rmse_m = (0.5, 1.0)

    def __call__(self, inputs: PredictorInputs):
        assert inputs.nbr_slot.dtype == jnp.int32
        assert inputs.hist.dtype == inputs.nbr_hist.dtype == inputs.nbr_weight.dtype
        last = inputs.hist[:, -1:, :] * self.scale
        return jnp.broadcast_to(last + jnp.finfo(inputs.hist.dtype).eps, (last.shape[0], 25, 2))


def _ones(dtype):
    return PredictorInputs(hist=jnp.full((2, 16, 2), 1.0, dtype), nbr_hist=jnp.zeros((2, 3, 16, 2), dtype),
                           nbr_slot=jnp.zeros((2, 3), jnp.int32), nbr_weight=jnp.zeros((2, 3), dtype))


@pytest.mark.parametrize("given", [np.float32, np.float64])
@pytest.mark.parametrize("inside", ["float32", "float64"])
def test_the_cast_computes_in_its_dtype_and_hands_back_the_callers(given, inside):
    out = with_compute_dtype(_Probe(scale=jnp.asarray(1.0, jnp.float32)), inside)(_ones(given))
    assert out.dtype == given and out.shape == (2, 25, 2)
    assert np.all(np.asarray(out) == np.asarray(1.0 + np.finfo(inside).eps, given))


def test_the_cast_is_differentiable_as_the_identity_and_keeps_the_inner_predictors_face():
    probe = _Probe(scale=jnp.asarray(1.0, jnp.float32))
    inside32 = with_compute_dtype(probe, "float32")
    # d out / d hist = 25 outputs x scale at the last point, 0 before
    g = jax.grad(lambda h: inside32(dataclasses.replace(_ones(jnp.float64), hist=h)).sum())(jnp.full((2, 16, 2), 1.0))
    assert g.dtype == jnp.float64
    assert np.all(np.asarray(g[:, -1]) == 25.0) and np.all(np.asarray(g[:, :-1]) == 0.0)
    assert inside32.spec is CSLSTM_SPEC and inside32.validation_rmse_m == (0.5, 1.0)
    assert CastPredictor(inner=object(), dtype="float32").validation_rmse_m is None
    leaves = jax.tree.leaves(inside32)
    assert len(leaves) == 1 and leaves[0] is probe.scale  # the dtype is static, the weights leaves


def test_the_cast_is_one_level_deep_and_refuses_other_dtypes():
    inner = init_predictor(seed=1)
    twice = with_compute_dtype(with_compute_dtype(inner, "bfloat16"), "float64")
    assert isinstance(twice, CastPredictor) and twice.inner == inner and twice.dtype == "float64"
    assert twice.spec == inner.spec and with_compute_dtype(inner, None) is inner
    for dtype in ("float16", "int8"):
        with pytest.raises(ValueError, match=dtype):
            with_compute_dtype(inner, dtype)
    with pytest.raises(ValueError, match="bfloat16"):  # a predictor without LSTM products
        with_compute_dtype(_Probe(scale=jnp.asarray(1.0, jnp.float32)), "bfloat16")


_predict = jax.jit(lambda p, x: p(x))


@pytest.mark.parametrize("maneuvers", [False, True])
def test_bfloat16_products_move_the_float32_prediction_by_their_rounding_alone(maneuvers):
    """float32 arithmetic, the LSTM products on bfloat16 operands (8 significant bits, a relative
    rounding of 2^-9 each): the prediction is the float32 one to within that rounding of the
    motion it predicts (0.2 % of the displacement, rms), yet not equal to it (the products did
    change), the same bit for bit on every call, in the caller's dtype."""
    # A random single-mode network predicts near-constant futures: the shipped weights for it.
    inner = init_predictor(maneuvers=True, seed=1) if maneuvers else ds.predictors.load_predictor()
    x = _inputs(jnp.float64, b=64)
    want = np.asarray(_predict(with_compute_dtype(inner, "float32"), x))
    fast = with_compute_dtype(inner, "bfloat16")
    got = np.asarray(_predict(fast, x))
    assert got.dtype == np.float64 and np.all(np.isfinite(got))
    np.testing.assert_array_equal(got, np.asarray(_predict(fast, x)))
    moved = np.sqrt(np.mean((want - np.asarray(x.hist[:, -1:, :])) ** 2))
    err = np.sqrt(np.mean((got - want) ** 2))
    assert 0.0 < err < 2.0**-9 * moved


def test_bfloat16_products_give_finite_gradients_near_the_float32_ones():
    """Both differentiation modes run on the bfloat16 products: the input gradient of the summed
    prediction is finite and within a few bfloat16 roundings (5 %) of float32's, in reverse
    mode and in forward mode."""
    inner = ds.predictors.load_predictor()
    x = _inputs(jnp.float64, b=16)

    def total(p, h):
        return p(dataclasses.replace(x, hist=h)).sum()

    f32, b16 = with_compute_dtype(inner, "float32"), with_compute_dtype(inner, "bfloat16")
    g32, g16 = (np.asarray(jax.jit(jax.grad(total, argnums=1))(p, x.hist)) for p in (f32, b16))
    assert np.all(np.isfinite(g16)) and np.linalg.norm(g16 - g32) < 0.05 * np.linalg.norm(g32)
    tangent = jnp.zeros_like(x.hist).at[:, -1, 1].set(1.0)  # move each target's last point forward
    with ds.predictors.forward_mode():  # float32's forward mode is reverse mode's (tests/test_forward_mode.py)
        t16 = float(jax.jvp(lambda h: total(b16, h), (x.hist,), (tangent,))[1])
    want = float(np.sum(g32 * np.asarray(tangent)))
    assert np.isfinite(t16) and abs(t16 - want) < 0.05 * abs(want)


@pytest.fixture(scope="module")
def objectives():
    # The shipped weights: a random network predicts near-constant futures, and E would be flat.
    predictor = ds.predictors.load_predictor()
    # The threshold law's mean-field E: smooth, so a finite difference checks its gradient.
    kw = dict(sensor="radar", params={"hfov_deg": (30.0, 180.0)}, scenarios=["sc03"], variants=2, seed=0,
              predictor=predictor, prediction_stride_frames=20, sensor_config=THRESHOLD["radar"])
    return (ds.objective(ds.Problem(**kw)), ds.objective(ds.Problem(**kw, predictor_dtype="float64")),
            ds.objective(ds.Problem(**kw, predictor_dtype="bfloat16")))


def test_problem_default_computes_the_predictor_in_float32(objectives):
    e32, e64, _ = objectives
    assert isinstance(e32.predictor, CastPredictor) and e32.predictor.dtype == "float32"
    assert not isinstance(e64.predictor, CastPredictor)
    assert e32.dtype == e64.dtype == jnp.float64


# At module level: compiled once for every case (a lambda made in the test is a new program each time).
_vg = eqx.filter_jit(lambda E, r: jax.value_and_grad(lambda x: E({"hfov_deg": x}))(r))
_value = eqx.filter_jit(lambda E, r: E({"hfov_deg": r}))


@pytest.mark.parametrize("hfov", [32.0, 50.0, 120.0])
def test_float32_predictor_value_and_gradient_match_float64_finite_differences(objectives, hfov):
    e32, e64, _ = objectives
    v32, g32 = _vg(e32, jnp.asarray(hfov))
    v64, g64 = _vg(e64, jnp.asarray(hfov))
    assert v32.dtype == jnp.float64 and g32.dtype == jnp.float64
    h = 1e-3
    fd = (float(_value(e64, jnp.asarray(hfov + h))) - float(_value(e64, jnp.asarray(hfov - h)))) / (2 * h)
    assert float(v32) == pytest.approx(float(v64), rel=1e-6)
    assert abs(float(g64)) > 0.1  # a slope worth comparing
    assert float(g64) == pytest.approx(fd, rel=1e-5)
    assert float(g32) == pytest.approx(fd, rel=1e-4)


def test_predictor_dtype_is_checked_at_the_door():
    with pytest.raises(InputError, match="predictor_dtype"):
        ds.Problem(predictor_dtype="float16")
    with pytest.raises(InputError, match="float64"):
        ds.Problem(float64=False, predictor_dtype="float64")


def test_bfloat16_e_is_the_float32_e_to_the_products_rounding(objectives):
    """The objective with "bfloat16" products: float64 E within 0.1 % of the float32 CS-LSTM's
    (predictions centimetres off, E a mean over many of them), its gradient finite."""
    e32, _, e16 = objectives
    v32, _ = _vg(e32, jnp.asarray(50.0))
    v16, g16 = _vg(e16, jnp.asarray(50.0))
    assert v16.dtype == jnp.float64 and np.isfinite(float(g16))
    assert float(v16) == pytest.approx(float(v32), rel=1e-3) and float(v16) != float(v32)


def test_auto_casts_the_cslstm_only():
    """A user's predictor keeps E's precision under "auto" (it may not be a float32 network);
    "float32" asked for casts it too."""

    class Persistence(eqx.Module):  # the target stays where it is
        spec = ds.predictors.CSLSTM_SPEC

        def __call__(self, inputs):
            return jnp.repeat(inputs.hist[:, -1:], self.spec.future_points, axis=1)

    kw = dict(sensor="radar", params={"hfov_deg": (30.0, 180.0)}, scenarios=["sc03"], variants=1,
              prediction_stride_frames=40)
    assert isinstance(ds.objective(ds.Problem(**kw, predictor=Persistence())).predictor, Persistence)
    cast = ds.objective(ds.Problem(**kw, predictor=Persistence(), predictor_dtype="float32")).predictor
    assert isinstance(cast, CastPredictor) and isinstance(cast.inner, Persistence)
    single = ds.objective(ds.Problem(**kw, float64=False)).predictor  # float32 E: nothing to cast
    assert not isinstance(single, CastPredictor)
    with pytest.raises(InputError, match="bfloat16"):  # no LSTM products to make faster
        ds.objective(ds.Problem(**kw, predictor=Persistence(), predictor_dtype="bfloat16"))
