"""Where the box solve looks (`diffsense/solve/_box_space.py`), at the edges, by hand.

- The sine transform never leaves the box, even where lo + (hi - lo) rounds past hi
  (-5 + 5.2 = 0.20000000000000018 > 0.2); a point outside the box maps to its bound's t (-pi/2,
  +pi/2), not to NaN.
- Snapping is inclusive: with bound_tol 1/4 on [0, 1], 0.25 goes to the lower bound and 0.75 to
  the upper; 0.26 and 0.74 stay.
- The Halton sample stays strictly inside the cube when the seed's shift lands a point on its
  edge: base 2's first point 1/2 shifted by 1/2 is 0 (moved to 1e-9), shifted by 1/2 - 1e-12 is
  1 - 1e-12 (moved to 1 - 1e-9).
"""

from __future__ import annotations

import numpy as np
import pytest

from diffsense.solve import _box_space
from diffsense.solve._box_space import _Box, halton


def test_x_never_rounds_past_the_upper_bound():
    box = _Box(np.array([-5.0]), np.array([0.2]), 1e-6)
    assert -5.0 + 5.2 * 0.5 * (1.0 + np.sin(np.pi / 2)) > 0.2  # the rounding the clip undoes
    assert box.x(np.array([np.pi / 2])).tolist() == [0.2]
    assert box.x(np.array([-np.pi / 2])).tolist() == [-5.0]


def test_t_of_a_point_outside_the_box_is_its_bounds():
    box = _Box(np.array([0.0, 0.0]), np.array([20.0, 20.0]), 1e-6)
    assert box.t(np.array([-5.0, 25.0])).tolist() == [-np.pi / 2, np.pi / 2]


def test_snap_is_inclusive_at_the_tolerance():
    box = _Box(np.zeros(4), np.ones(4), 0.25)
    x, flags = box.snap(np.array([0.25, 0.75, 0.26, 0.74]))
    assert x.tolist() == [0.0, 1.0, 0.26, 0.74] and flags == ["lower", "upper", "", ""]


class _Shift:
    def __init__(self, value):
        self.value = value

    def uniform(self, size):
        return np.full(size, self.value)


@pytest.mark.parametrize("shift, point", [(0.5, 1e-9), (0.5 - 1e-12, 1.0 - 1e-9)])
def test_halton_points_on_the_cubes_edge_are_moved_inside(monkeypatch, shift, point):
    monkeypatch.setattr(_box_space.np.random, "default_rng", lambda seed: _Shift(shift))
    assert halton(1, 1).tolist() == [[point]]
