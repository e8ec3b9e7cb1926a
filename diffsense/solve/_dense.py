"""The brute-force baseline: the hard objective on a dense grid, and the basin cross-check.

The reference used for the main job is a 0.5-deg grid over 30..180 deg HFOV (301 evaluations). The basin of
the best dense point is the run of grid points around it over which E_hard does not decrease
moving away from it (plateaus included); the continuous answer should lie in it.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from diffsense.runtime import InputError
from diffsense.solve._steps import check_interval


@dataclasses.dataclass(frozen=True)
class DenseGrid:
    """E_hard on a dense grid.

    Attributes:
        r: grid points, float64 [n], both interval ends included.
        E_hard: E_hard at each point [m], float64 [n].
        evaluations: hard objective evaluations spent (n).
        wall_s: wall time of the search [s].
    """

    r: np.ndarray
    E_hard: np.ndarray
    evaluations: int
    wall_s: float

    @property
    def best_index(self) -> int:
        """Index of the smallest E_hard (the first, on ties)."""
        return int(np.argmin(self.E_hard))

    def basin(self) -> tuple[float, float]:
        """(lo, hi): the best point's basin: E_hard never decreases walking outwards from it."""
        e, i = self.E_hard, self.best_index
        left = i
        while left > 0 and e[left - 1] >= e[left]:
            left -= 1
        right = i
        while right + 1 < e.size and e[right + 1] >= e[right]:
            right += 1
        return float(self.r[left]), float(self.r[right])


def dense_grid_search(
    e_hard: Callable[[float], float], interval: tuple[float, float], step: float
) -> DenseGrid:
    """Evaluate `e_hard` every `step` over the interval (the last spacing may be shorter).

    Args:
        e_hard: `e_hard(r) -> E [m]`.
        interval: (lo, hi), the objective's units.
        step: grid spacing in the same units (e.g. 0.5 deg, converted).
    """
    lo, hi = check_interval(*interval)
    if not (math.isfinite(step) and step > 0):
        raise InputError(f"dense grid step {step} must be positive")
    n = int(math.ceil((hi - lo) / step - 1e-9)) + 1
    r = np.minimum(lo + step * np.arange(n), hi)
    r[-1] = hi
    t0 = time.perf_counter()
    e = np.array([float(e_hard(float(x))) for x in r], dtype=np.float64)
    return DenseGrid(r=r, E_hard=e, evaluations=int(n), wall_s=time.perf_counter() - t0)


def basin_check(
    dense: DenseGrid,
    r_star: float,
    E_hard_star: float | None = None,
    bracket: tuple[float, float] | None = None,
) -> str | None:
    """None if r* lies in the basin of the best dense point; otherwise the reason, one line.

    Args:
        dense: the dense grid search.
        r_star: the continuous answer.
        E_hard_star: E_hard(r_star) [m], to say whether r* is in an equally good basin.
        bracket: the bracket the continuous solve searched, to say where the miss comes from.
    """
    a, b = dense.basin()
    spacing = float(np.max(np.diff(dense.r))) if dense.r.size > 1 else 0.0
    # r* is continuous: within half a grid spacing of the basin it is still in it.
    if a - 0.5 * spacing <= r_star <= b + 0.5 * spacing:
        return None
    i = dense.best_index
    best_r, best_e = float(dense.r[i]), float(dense.E_hard[i])
    where = (
        f"r*={r_star:.6g} lies outside the basin [{a:.6g}, {b:.6g}] of the best dense point "
        f"r={best_r:.6g} (E_hard={best_e:.6g} m)"
    )
    if E_hard_star is None:
        return where
    if E_hard_star <= best_e:
        return (
            f"{where}, in another basin at least as deep (E_hard={E_hard_star:.6g} m): the hard "
            "objective has several equally good minima"
        )
    worse = f"{where}; E_hard(r*)={E_hard_star:.6g} m is worse by {E_hard_star - best_e:.3g} m"
    if bracket is not None and bracket[0] <= best_r <= bracket[1]:
        return f"{worse}: inside the bracket the soft objective's minimum misses the hard basin"
    return (
        f"{worse}: the stepped sweep's best step does not bracket the dense optimum (the steps "
        "are coarser than the basin)"
    )
