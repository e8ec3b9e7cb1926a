"""Intervals on E from the scene sample: a stratified percentile bootstrap that reweights sums
already computed, so it costs no new evaluation of the pipeline.

The scenarios are the design and their variants the sample. A bootstrap resample draws, within
each stratum (a scenario), as many variants as it holds, with replacement; variant n then
counts c_n times. Every E the job reports is a ratio of sums over variants of per-instant
pieces, so E at a resample is those per-variant sums (`SceneSums`) weighted by c:

    eq12:     E^2(c) = sum_n c_n S_n / sum_n c_n I_n                                    [m^2]
    tracked:  J(c)   = mean_k [ sum_n c_n A_kn / (1 + sum_n c_n Q_kn)
                                + miss_penalty (1 - sum_n c_n Q_kn / sum_n c_n I_n) ]   [m^2]

(S_n: the variant's squared distances summed over its instants, mean over horizon steps and
detection draws; I_n its instants; A_kn, Q_kn its tracked error and tracked count in draw k), and
c = 1 gives the reported value itself. The interval at level L is the (1 - L)/2 and (1 + L)/2
quantiles of E over B resamples (`RESAMPLES`, default 2000; level 0.9 by default).

Detection draws. A variant's uniforms and measurement noise come from its own key, so the K
draws of one variant are independent of every other variant's: its draw-averaged sum carries its
draws' error, and resampling the variants resamples that error with them. The bootstrap's
variance is then Var(scene)/N + Var(draw)/(N K), the estimator's whole variance; no draw term is
added on top.

Pairing. The resamples are a function of the seed and the strata alone, so every r of a run is
reweighted by the same resamples: a difference E(a) - E(b) is resampled scene by scene (paired:
the scenes every r shares cancel). An unpaired interval, which resamples a and b independently,
is given beside it for comparison.

An interval needs at least two variants in every stratum; with one, the sample says nothing about
how E would move with other traffic, and the functions return None rather than an interval.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Float, Int

LEVEL = 0.9
RESAMPLES = 2000
# Mixed into the seed so that the resamples are their own stream, apart from anything else the
# seed fixes; the unpaired comparison's second sample takes the next stream.
_STREAM = 0x5EED_B007


@dataclasses.dataclass(frozen=True)
class SceneSums:
    """The per-variant sums E^2 at one r is a ratio of (module docstring); K draws (1 for a
    hard evaluation), N variants, padding rows (weight 0) all zero.

    Attributes:
        sq: [N] squared distance summed over the variant's instants, mean over horizon steps
            and draws, times the variant's weight [m^2].
        instants: [N] the variant's instants times its weight.
        tracked_sq: [K, N] per draw, the squared distance summed over tracked instants [m^2].
        tracked: [K, N] per draw, the tracked instants.
        question: "eq12" or "tracked".
        miss_penalty_m2: the tracked question's price of an instant without a track [m^2].
    """

    sq: Float[np.ndarray, " N"]
    instants: Float[np.ndarray, " N"]
    tracked_sq: Float[np.ndarray, "K N"]
    tracked: Float[np.ndarray, "K N"]
    question: str = "eq12"
    miss_penalty_m2: float = 100.0

    def e2(self, counts: Float[np.ndarray, "B N"]) -> Float[np.ndarray, " B"]:
        """E^2 (or J) [m^2] of each resample's counts."""
        counts = np.asarray(counts, np.float64)
        total = counts @ self.instants
        if self.question == "eq12":
            return (counts @ self.sq) / total
        seen = counts @ self.tracked.T  # [B, K]
        error = (counts @ self.tracked_sq.T) / (1.0 + seen)
        return np.mean(error + self.miss_penalty_m2 * (1.0 - seen / total[:, None]), axis=1)

    def e(self, counts: Float[np.ndarray, "B N"]) -> Float[np.ndarray, " B"]:
        """E [m] of each resample's counts (the square root of `e2`)."""
        return np.sqrt(np.maximum(self.e2(counts), 0.0))


def scene_sums(sq_instant: Float[np.ndarray, "*K N I"], coverage: Float[np.ndarray, "*K N I 3"],
               weight: Float[np.ndarray, " N"], question: str = "eq12", miss_penalty_m2: float = 100.0) -> SceneSums:
    """The `SceneSums` of one evaluation: a hard one's `sq_instant` [N, I] and `coverage`
    [N, I, 3] (`HardEvaluation`), or the reference draws' [K, N, I] and [K, N, I, 3]
    (`DrawnParts`); `weight` [N] the variants' weights (0 for padding)."""
    sq = np.asarray(sq_instant, np.float64)
    cov = np.asarray(coverage, np.float64)
    if sq.ndim == 2:
        sq, cov = sq[None], cov[None]
    w = np.asarray(weight, np.float64)
    tracked = cov[..., 1]
    return SceneSums(sq=w * np.mean(np.sum(sq, axis=2), axis=0), instants=w * sq.shape[2],
                     tracked_sq=w * np.sum(tracked * sq, axis=2), tracked=w * np.sum(tracked, axis=2),
                     question=question, miss_penalty_m2=float(miss_penalty_m2))


def estimable(strata: Int[np.ndarray, " N"], weight: Float[np.ndarray, " N"] | None = None) -> bool:
    """Whether an interval can be estimated: every stratum holds at least two real variants."""
    real = _real(strata, weight)
    _, sizes = np.unique(np.asarray(strata)[real], return_counts=True)
    return sizes.size > 0 and bool(np.all(sizes >= 2))


def _real(strata, weight) -> np.ndarray:
    return np.ones(np.shape(strata), bool) if weight is None else np.asarray(weight) > 0


def bootstrap_counts(strata: Int[np.ndarray, " N"], *, weight: Float[np.ndarray, " N"] | None = None,
                     resamples: int = RESAMPLES, seed: int = 0, stream: int = 0) -> Int[np.ndarray, "B N"] | None:
    """How often each variant is drawn in each of `resamples` stratified resamples: [B, N].

    Each stratum's real variants (`weight` > 0) are drawn as many times as it holds them, with
    replacement; padding is never drawn. The same (strata, weight, resamples, seed, stream) give
    the same counts, bit for bit. None where `estimable` is False."""
    strata = np.asarray(strata)
    if not estimable(strata, weight):
        return None
    real = _real(strata, weight)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), _STREAM, int(stream)]))
    counts = np.zeros((int(resamples), strata.size), np.int64)
    for s in np.unique(strata[real]):
        members = np.flatnonzero(real & (strata == s))
        picks = rng.integers(0, members.size, size=(int(resamples), members.size))
        counts[:, members] = np.sum(picks[..., None] == np.arange(members.size), axis=1)
    return counts


def _quantiles(values: Float[np.ndarray, " B"], level: float, tail: float | None = None) -> tuple[float, float]:
    """The `tail` and 1 - `tail` quantiles of `values` (None: (1 - level)/2, the plain percentile)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    tail = (1.0 - level) / 2.0 if tail is None else tail
    lo, hi = np.quantile(values, [tail, 1.0 - tail])
    return float(lo), float(hi)


def expanded_tail(strata: Int[np.ndarray, " N"], weight: Float[np.ndarray, " N"] | None = None,
                  level: float = LEVEL) -> float:
    """The tail probability the expanded percentile interval (Hesterberg 2015, "What teachers
    should know about the bootstrap", sec. 4) reads its quantiles at, in place of (1 - level)/2:

        Phi(-sqrt(n / (n - 1)) t_{df, (1 + level)/2}),   df = N - H

    A stratum of n variants resampled with replacement has (n - 1)/n of the sample's variance
    (n: the smallest stratum; exact where all hold as many), and a variance estimated from N
    variants in H strata has N - H degrees of freedom: with few variants the plain percentile
    interval, in effect a normal interval with the variance plugged in, is narrow on both counts.
    Requires `estimable(strata, weight)`."""
    from scipy import stats

    _, sizes = np.unique(np.asarray(strata)[_real(strata, weight)], return_counts=True)
    n, df = int(np.min(sizes)), int(np.sum(sizes) - sizes.size)
    return float(stats.norm.cdf(-np.sqrt(n / (n - 1.0)) * stats.t.ppf((1.0 + level) / 2.0, df)))


def bootstrap_ci(sums: SceneSums, strata: Int[np.ndarray, " N"], *, level: float = LEVEL,
                 resamples: int = RESAMPLES, seed: int = 0) -> tuple[float, float] | None:
    """The percentile bootstrap interval [lo, hi] [m] on E at level `level` from the scene
    sample: `resamples` stratified resamples of the variants (`bootstrap_counts`, `strata` [N]
    the scenario of each variant) reweighting `sums` (module docstring). Same seed, same
    interval. None where it cannot be estimated (a stratum with one variant)."""
    counts = bootstrap_counts(strata, weight=_weight(sums), resamples=resamples, seed=seed)
    if counts is None:
        return None
    return _quantiles(sums.e(counts), level, expanded_tail(strata, _weight(sums), level))


def difference_ci(a: SceneSums, b: SceneSums, strata: Int[np.ndarray, " N"], *, paired: bool = True,
                  level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0) -> tuple[float, float] | None:
    """The percentile bootstrap interval [lo, hi] [m] on E(a) - E(b), two evaluations over the
    same variants. Paired (the default): both reweighted by the same resamples, scene by scene.
    Unpaired: b by an independent set of resamples, as if the two had seen other scenes. None
    where it cannot be estimated."""
    counts = bootstrap_counts(strata, weight=_weight(a), resamples=resamples, seed=seed)
    if counts is None:
        return None
    other = counts if paired else bootstrap_counts(strata, weight=_weight(a), resamples=resamples, seed=seed, stream=1)
    return _quantiles(a.e(counts) - b.e(other), level, expanded_tail(strata, _weight(a), level))


def argmin_ci(points: Float[np.ndarray, " P"], sums: list[SceneSums], strata: Int[np.ndarray, " N"], *,
              level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0,
              offset_m: Float[np.ndarray, " P"] | None = None) -> tuple[float, float] | None:
    """The bootstrap interval [lo, hi] on the minimiser r* of E over evaluated `points` [P]
    (`sums` [P] their `SceneSums`, over the same variants): each resample (the resamples of
    `bootstrap_ci`, same seed) reweights every point alike and picks the point of least E, a
    re-solve over the points on that resample's scenes; the interval is the picks' quantiles at
    `bootstrap_ci`'s expanded tails. Resolved to the points: r* between two of them is read as
    one of the two. `offset_m` [P], where given, is added to each point's E before the pick (a
    suite's lambda x cost, so that the pick is J's: the scenes do not move the cost). None where
    it cannot be estimated."""
    if len(points) != len(sums) or not sums:
        raise ValueError(f"{len(points)} points and {len(sums)} sums: one SceneSums per point")
    if offset_m is not None and np.shape(offset_m) != (len(points),):
        raise ValueError(f"offset_m has shape {np.shape(offset_m)}, want ({len(points)},): one per point")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    counts = bootstrap_counts(strata, weight=_weight(sums[0]), resamples=resamples, seed=seed)
    if counts is None:
        return None
    e = np.stack([s.e2(counts) for s in sums])  # [P, B]; E^2 picks as E does, where nothing is added
    if offset_m is not None:
        e = np.sqrt(np.maximum(e, 0.0)) + np.asarray(offset_m, np.float64)[:, None]
    picks = np.asarray(points, np.float64)[np.argmin(e, axis=0)]
    tail = expanded_tail(strata, _weight(sums[0]), level)
    # the quantiles read outward to evaluated points: no r* between two points is claimed
    return (float(np.quantile(picks, tail, method="lower")), float(np.quantile(picks, 1.0 - tail, method="higher")))


def _weight(sums: SceneSums) -> np.ndarray:
    # a real variant has instants; a padding row none
    return (np.asarray(sums.instants) > 0).astype(np.float64)


__all__ = ["LEVEL", "RESAMPLES", "SceneSums", "argmin_ci", "bootstrap_ci", "bootstrap_counts", "difference_ci",
           "estimable", "expanded_tail", "scene_sums"]
