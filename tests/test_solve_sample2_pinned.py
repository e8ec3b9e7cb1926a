"""Kills the survivors of a fresh solve sample (seed 2 at da3a7db; docs/mutation.md): the
evaluator's progress for E_ref, its float pair for the solver and its detections program, and the
size of the box solve's coarse sample."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import Evaluator
from diffsense.solve._box import BoxConfig, box_solve
from diffsense.solve._box_fns import BoxFunctions
from tests.test_evaluator_pinned import Bowl


class BowlWithDetections(Bowl):
    """The bowl, with detections that tell the mode and the temperature apart: 10 x + tau when
    soft, x when hard."""

    def detections(self, x, mode, tau):
        return 10.0 * x + tau if mode == "soft" else x


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def test_reference_progress_reports_e_ref_in_metres():
    seen = []
    ev = Evaluator(Bowl(), progress=lambda kind, value, tau: seen.append((kind, value, tau)))
    # E_ref(3) = sqrt(0 + 1/4) + 1 = 1.5 m (the bowl's reference is E_hard plus 1 m)
    assert ev.e_reference(3.0) == pytest.approx(1.5, abs=1e-12)
    assert seen == [("reference", pytest.approx(1.5, abs=1e-12), 0.0)]


def test_host_value_and_grad_is_a_pair_of_floats():
    v, g = Evaluator(Bowl()).host_value_and_grad(4.0, 2.0)
    assert (v, g) == (1.5, 2.0)  # (4 - 3)^2 + 2/4 and 2 (4 - 3)
    assert type(v) is float and type(g) is float


def test_detections_pass_the_mode_and_the_temperature():
    ev = Evaluator(BowlWithDetections())
    assert float(ev.detections(4.0, "soft", 2.0)) == 42.0
    assert float(ev.detections(4.0)) == 4.0  # hard by default


def test_the_coarse_sample_has_two_d_plus_two_points_by_default():
    # No BFGS start: the box solve evaluates only its coarse sample on E_hard (and the answer).
    def e_hard(x):  # x = (a, b), a float64 vector
        return jnp.hypot(x[0] - 0.3, x[1] - 0.6)

    def e2_soft(x, tau):
        return (x[0] - 0.3) ** 2 + (x[1] - 0.6) ** 2

    fns = BoxFunctions.from_jax(["a", "b"], e2_soft, e_hard)
    box_solve(fns, {"a": (0.0, 1.0), "b": (0.0, 1.0)}, BoxConfig(starts=0))
    assert fns.counts["hard"] == 2 * 2 + 2
    fns = BoxFunctions.from_jax(["a", "b"], e2_soft, e_hard)
    box_solve(fns, {"a": (0.0, 1.0), "b": (0.0, 1.0)}, BoxConfig(starts=0, samples=9))
    assert fns.counts["hard"] == 9
