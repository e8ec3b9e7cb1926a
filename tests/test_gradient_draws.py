"""The relaxed estimators on a mini-batch of the reference's draws (`EstimatorConfig.gradient_draws`):
relaxed-reference on the first K_g of K draws is relaxed-reference on K_g draws; straight-through
keeps E_ref on all K as its value and takes its gradient from the K_g relaxed draws; K_g >= K is
every draw; and a K_g below one is refused. On the toy pipeline's Swerling I radar."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import pytest

from diffsense.metrics import EstimatorConfig
from diffsense.runtime import InputError
from tests._toy_pipeline import radar_objective

HFOV = {"hfov_deg": jnp.asarray(10.0)}  # a narrow beam: the toy car is seen in some draws only


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def _value_and_grad(E):
    return jax.value_and_grad(lambda h: E.e2({"hfov_deg": h}, 1.0))(HFOV["hfov_deg"])


def test_relaxed_reference_on_the_first_draws_is_that_many_draws():
    few = radar_objective(kind="relaxed-reference", draws=8, gradient_draws=3)
    three = radar_objective(kind="relaxed-reference", draws=3, gradient_draws=3)
    v_few, g_few = _value_and_grad(few)
    v_three, g_three = _value_and_grad(three)
    assert float(v_few) == pytest.approx(float(v_three), rel=1e-12)
    assert float(g_few) == pytest.approx(float(g_three), rel=1e-10)
    every = radar_objective(kind="relaxed-reference", draws=8, gradient_draws=8)
    assert float(_value_and_grad(every)[0]) != pytest.approx(float(v_few), rel=1e-6)  # the other 5 draws count


def test_straight_through_keeps_e_ref_on_all_draws_and_the_mini_batchs_gradient():
    st = radar_objective(kind="straight-through", draws=8, gradient_draws=3)
    relaxed = radar_objective(kind="relaxed-reference", draws=8, gradient_draws=3)
    v, g = _value_and_grad(st)
    assert float(v) == pytest.approx(float(st.reference(HFOV).e2), rel=1e-12)  # E_ref over K = 8
    assert float(g) == pytest.approx(float(_value_and_grad(relaxed)[1]), rel=1e-10)


def test_a_mini_batch_larger_than_k_is_every_draw():
    big = radar_objective(kind="relaxed-reference", draws=4, gradient_draws=100)
    four = radar_objective(kind="relaxed-reference", draws=4, gradient_draws=4)
    assert float(_value_and_grad(big)[0]) == float(_value_and_grad(four)[0])


def test_a_mini_batch_below_one_is_refused():
    with pytest.raises(InputError, match="gradient_draws"):
        EstimatorConfig(gradient_draws=0)
