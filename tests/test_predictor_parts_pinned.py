"""The predictor's small parts pinned to values worked out by hand and to numpy loops: the SI /
model frame boundary (international foot, lateral axis to the right), the input spec's derived
quantities, the float-precision wrapper, and the layers in PyTorch's parameterisation (Linear,
LSTM with both biases and gates i, f, g, o, a convolution spanning the whole width, uniform
initialisation in +-1/sqrt(fan_in))."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx

from diffsense.predictors._cast import CastPredictor, with_compute_dtype
from diffsense.predictors._frame import M_PER_FT, model_to_si, si_to_model
from diffsense.predictors._layers import LSTM, FullWidthConv, Linear
from diffsense.predictors._protocol import CSLSTM_SPEC, InputSpec, PredictorInputs


def test_the_frame_boundary_is_feet_with_lateral_to_the_right():
    assert M_PER_FT == 0.3048  # the international foot, exactly
    # 30.48 m ahead and 3.048 m to the left is (lateral 10 ft to the LEFT = -10, 100 ft forward).
    xy = jnp.array([[30.48, 3.048], [-6.096, -1.524]])
    np.testing.assert_allclose(si_to_model(xy), [[-10.0, 100.0], [5.0, -20.0]], rtol=1e-15)
    np.testing.assert_allclose(model_to_si(jnp.array([[-10.0, 100.0], [5.0, -20.0]])), xy, rtol=1e-15)
    batch = jax.random.normal(jax.random.key(0), (3, 4, 2), jnp.float64) * 50.0
    assert si_to_model(batch).shape == (3, 4, 2)
    np.testing.assert_allclose(model_to_si(si_to_model(batch)), batch, rtol=1e-14)


def test_the_cslstm_spec_and_what_follows_from_it():
    s = CSLSTM_SPEC
    assert (s.history_points, s.future_points, s.rate_hz, s.grid_cells, s.grid_lanes) == (16, 25, 5.0, 13, 3)
    assert s.grid_cell_m == pytest.approx(4.572, abs=1e-12)  # 15 ft
    assert s.history_s == 3.0 and s.future_s == 5.0 and s.grid_size == 39
    assert s.grid_half_length_m == pytest.approx(29.718, abs=1e-12)  # 6.5 cells of 15 ft
    assert s.frames_per_point(0.1) == 2 and s.frames_per_point(0.2) == 1 and s.frames_per_point(0.04) == 5
    horizon = s.horizon_s()
    assert len(horizon) == 25 and horizon[0] == 0.2 and horizon[4] == 1.0 and horizon[-1] == 5.0


@pytest.mark.parametrize("scene_dt_s", [0.3, 0.15, 0.5])
def test_a_scene_rate_that_is_not_a_multiple_of_the_predictors_is_refused(scene_dt_s):
    with pytest.raises(ValueError, match="cannot feed a 5 Hz predictor"):
        CSLSTM_SPEC.frames_per_point(scene_dt_s)


@pytest.mark.parametrize("field, value", [("history_points", 0), ("future_points", 0), ("grid_cells", 0),
                                          ("grid_lanes", 0), ("rate_hz", 0.0), ("rate_hz", float("inf")),
                                          ("rate_hz", -5.0), ("grid_cell_m", 0.0)])
def test_a_spec_with_an_empty_or_non_positive_field_is_refused(field, value):
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(CSLSTM_SPEC, **{field: value})
    ok = dataclasses.replace(CSLSTM_SPEC, history_points=1, future_points=1, grid_cells=1, grid_lanes=1)
    assert ok.history_s == 0.0 and ok.grid_size == 1
    slow = dataclasses.replace(CSLSTM_SPEC, rate_hz=0.5, grid_cell_m=0.5)  # below 1 but positive: fine
    assert slow.future_s == 50.0 and slow.grid_half_length_m == 3.25


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Probe:
    """A predictor with float32 parameters (as the CS-LSTM's are): its output is hist's last point
    times `scale`, plus 1e-9, which float32 cannot hold next to 1."""

    scale: jax.Array
    spec = CSLSTM_SPEC
    validation_rmse_m = (0.5, 1.0)

    def __call__(self, inputs: PredictorInputs):
        assert inputs.nbr_slot.dtype == jnp.int32  # integers pass through untouched
        last = inputs.hist[:, -1:, :] * self.scale
        return jnp.broadcast_to(last + jnp.asarray(1e-9, inputs.hist.dtype), (last.shape[0], 25, 2))


def _inputs(dtype):
    hist = jnp.full((2, 16, 2), 1.0, dtype)
    return PredictorInputs(hist=hist, nbr_hist=jnp.zeros((2, 3, 16, 2), dtype),
                           nbr_slot=jnp.zeros((2, 3), jnp.int32), nbr_weight=jnp.zeros((2, 3), dtype))


def test_the_cast_runs_the_inner_predictor_in_its_dtype_and_hands_back_the_callers():
    probe = _Probe(scale=jnp.asarray(1.0, jnp.float32))
    inside32 = with_compute_dtype(probe, "float32")
    out = inside32(_inputs(jnp.float64))
    assert out.dtype == jnp.float64 and out.shape == (2, 25, 2)
    assert np.all(np.asarray(out) == 1.0)  # 1 + 1e-9 rounded in float32, then widened
    out64 = with_compute_dtype(probe, "float64")(_inputs(jnp.float64))
    assert np.all(np.asarray(out64) == 1.0 + 1e-9)
    down = with_compute_dtype(probe, "float64")(_inputs(jnp.float32))
    assert down.dtype == jnp.float32
    assert inside32.spec is CSLSTM_SPEC and inside32.validation_rmse_m == (0.5, 1.0)
    assert CastPredictor(inner=object(), dtype="float32").validation_rmse_m is None
    # the derivative of a cast is the identity: d out / d hist = scale at the last point, 0 before
    g = jax.grad(lambda h: inside32(dataclasses.replace(_inputs(jnp.float64), hist=h)).sum())(
        jnp.full((2, 16, 2), 1.0))
    assert g.dtype == jnp.float64
    assert np.all(np.asarray(g[:, -1]) == 25.0) and np.all(np.asarray(g[:, :-1]) == 0.0)


def test_with_compute_dtype_never_nests_and_refuses_other_types():
    probe = _Probe(scale=jnp.asarray(1.0, jnp.float32))
    assert with_compute_dtype(probe, None) is probe
    once = with_compute_dtype(probe, "float32")
    twice = with_compute_dtype(once, "float64")
    assert isinstance(twice, CastPredictor) and twice.inner is probe and twice.dtype == "float64"
    with pytest.raises(ValueError, match="float32, float64, got 'bfloat16'"):
        with_compute_dtype(probe, "bfloat16")
    leaves = jax.tree.leaves(once)
    assert len(leaves) == 1 and leaves[0] is probe.scale  # the dtype is static, the weights leaves


def _sigmoid(z):
    return 1.0 / (1.0 + np.exp(-z))


def _lstm_by_hand(xs, w_ih, w_hh, b_ih, b_hh):
    """PyTorch's LSTM written out: gates (i, f, g, o), h_0 = c_0 = 0; every hidden state."""
    hidden = w_hh.shape[0]
    h = np.zeros((xs.shape[1], hidden))
    c = np.zeros_like(h)
    out = []
    for x in xs:
        z = x @ w_ih + b_ih + h @ w_hh + b_hh
        i, f, g, o = (z[:, k * hidden:(k + 1) * hidden] for k in range(4))
        c = _sigmoid(f) * c + _sigmoid(i) * np.tanh(g)
        h = _sigmoid(o) * np.tanh(c)
        out.append(h)
    return np.stack(out)


def _f64(p):
    return np.asarray(p[...], np.float64)


def test_linear_lstm_and_conv_are_pytorchs_formulas():
    rngs = nnx.Rngs(params=1)
    lin, lstm, emb = Linear(3, 5, rngs=rngs), LSTM(4, 6, rngs=rngs), Linear(2, 4, rngs=rngs)
    conv = FullWidthConv(3, 2, 5, 7, rngs=rngs)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(8, 3)).astype(np.float32)
    np.testing.assert_allclose(lin(jnp.asarray(x)), x @ _f64(lin.weight) + _f64(lin.bias), rtol=1e-5, atol=1e-6)
    seq = rng.normal(size=(7, 5, 2)).astype(np.float32)  # T 7, N 5, d 2
    pre = seq @ _f64(emb.weight) + _f64(emb.bias)
    embedded = np.where(pre >= 0, pre, 0.1 * pre)
    weights = (_f64(lstm.w_ih), _f64(lstm.w_hh), _f64(lstm.b_ih), _f64(lstm.b_hh))
    np.testing.assert_allclose(lstm.final(jnp.asarray(seq), emb), _lstm_by_hand(embedded, *weights)[-1],
                               rtol=1e-4, atol=1e-5)
    x4 = rng.normal(size=(7, 5, 4)).astype(np.float32)
    np.testing.assert_allclose(lstm.final(jnp.asarray(x4)), _lstm_by_hand(x4, *weights)[-1], rtol=1e-4, atol=1e-5)
    one = rng.normal(size=(5, 4)).astype(np.float32)
    repeated = lstm.repeated(jnp.asarray(one), 9)
    assert repeated.shape == (9, 5, 6)
    np.testing.assert_allclose(repeated, _lstm_by_hand(np.broadcast_to(one, (9, 5, 4)), *weights), rtol=1e-4, atol=1e-5)
    img = rng.normal(size=(2, 6, 2, 5)).astype(np.float32)  # B 2, H 6, W 2 (= kernel width), C 5
    k, bias = _f64(conv.kernel), _f64(conv.bias)
    want = np.array([[[np.sum(img[n, r:r + 3] * k[..., o]) + bias[o] for o in range(7)] for r in range(4)]
                     for n in range(2)])
    np.testing.assert_allclose(conv(jnp.asarray(img)), want, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="kernel width 2 must span the input width 3"):
        conv(jnp.zeros((2, 6, 3, 5)))


def test_initialisation_is_uniform_in_one_over_root_fan_in():
    rngs = nnx.Rngs(params=0)
    lin, lstm, conv = Linear(16, 400, rngs=rngs), LSTM(3, 100, rngs=rngs), FullWidthConv(3, 3, 64, 16, rngs=rngs)
    for values, fan_in in [(lin.weight, 16), (lin.bias, 16), (lstm.w_ih, 100), (lstm.w_hh, 100), (lstm.b_ih, 100),
                           (lstm.b_hh, 100), (conv.kernel, 3 * 3 * 64), (conv.bias, 3 * 3 * 64)]:
        w = np.asarray(values[...])
        bound = 1.0 / np.sqrt(fan_in)
        assert w.dtype == np.float32
        assert np.abs(w).max() <= bound
        if w.size >= 400:  # a uniform fills its interval: the extremes and the variance bound^2 / 3
            assert w.min() < -0.98 * bound and w.max() > 0.98 * bound
            assert abs(w.var() / (bound**2 / 3) - 1.0) < 0.15
    assert lin.weight.shape == (16, 400) and lstm.w_ih.shape == (3, 400) and lstm.w_hh.shape == (100, 400)
    assert conv.kernel.shape == (3, 3, 64, 16) and conv.bias.shape == (16,) and lstm.hidden == 100
    b = np.asarray(lstm.b_ih[...])
    assert not np.array_equal(b, np.asarray(lstm.b_hh[...]))  # two biases, each its own draw


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Bits:
    """A predictor whose every output is the bit width of the floats it was handed."""

    spec = CSLSTM_SPEC

    def __call__(self, inputs: PredictorInputs):
        assert inputs.nbr_slot.dtype == jnp.int32
        bits = jnp.finfo(inputs.hist.dtype).bits
        assert jnp.finfo(inputs.nbr_hist.dtype).bits == jnp.finfo(inputs.nbr_weight.dtype).bits == bits
        return jnp.full((inputs.hist.shape[0], 25, 2), bits, inputs.hist.dtype)


@pytest.mark.parametrize("given, inside", [(jnp.float32, "float64"), (jnp.float64, "float32"),
                                           (jnp.float32, "float32"), (jnp.float64, "float64")])
def test_every_float_input_is_cast_to_the_compute_dtype_whatever_it_was(given, inside):
    out = with_compute_dtype(_Bits(), inside)(_inputs(given))
    assert out.dtype == given and np.all(np.asarray(out) == {"float32": 32, "float64": 64}[inside])
