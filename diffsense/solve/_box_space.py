"""Where the box solve looks: the Halton sample of the box and the sine transform.

Each parameter is searched as x = lo + (hi - lo) (1 + sin t) / 2 with t unconstrained (MINUIT's
transform), so every point a solver asks for lies in [lo, hi] and a minimum on a bound is an
ordinary stationary point in t.
"""

from __future__ import annotations

import numpy as np


def halton(n: int, d: int, seed: int = 0) -> np.ndarray:
    """n points of the d-dimensional Halton sequence in (0, 1)^d, shifted modulo 1 by a uniform
    draw from `seed` (Cranley-Patterson rotation), [n, d]."""
    primes = [p for p in range(2, 1000) if all(p % q for q in range(2, int(p**0.5) + 1))][:d]
    out = np.empty((n, d))
    for j, base in enumerate(primes):
        for i in range(n):
            f, k, x = 1.0, i + 1, 0.0
            while k > 0:
                f /= base
                x += f * (k % base)
                k //= base
            out[i, j] = x
    shift = np.random.default_rng(seed).uniform(size=d)
    return np.clip((out + shift) % 1.0, 1e-9, 1.0 - 1e-9)


class _Box:
    """The sine transform between t and x, and the snap to bounds."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, bound_tol: float):
        self.lo, self.hi, self.width, self.tol = lo, hi, hi - lo, bound_tol

    def x(self, t) -> np.ndarray:
        return np.clip(self.lo + self.width * 0.5 * (1.0 + np.sin(t)), self.lo, self.hi)

    def t(self, x) -> np.ndarray:
        return np.arcsin(np.clip(2.0 * (np.asarray(x) - self.lo) / self.width - 1.0, -1.0, 1.0))

    def snap(self, x) -> tuple[np.ndarray, list[str]]:
        u = (np.asarray(x) - self.lo) / self.width
        flags = ["lower" if v <= self.tol else "upper" if v >= 1.0 - self.tol else "" for v in u]
        x = np.where(u <= self.tol, self.lo, np.where(u >= 1.0 - self.tol, self.hi, x))
        return x, flags
