"""Acceptance bands of the calibration checks of stated uncertainties (``tests/test_*.py``).

A stated uncertainty is tested over ``K`` Monte-Carlo draws with known noise. Its bands are derived
from ``K`` and the noise model alone, at the two-sided false-failure level :data:`ALPHA` (the test
fails by chance once in 10 000 seeds; each test's seed is fixed, so it is deterministic):

- a noise estimate ``σ̂²`` with ``ν`` residual degrees of freedom: ``ν σ̂²/σ² ~ χ²_ν``, so the mean
  of ``σ̂²/σ²`` over ``K`` draws is ``χ²_{Kν}/(Kν)`` (:func:`assert_unbiased_variance`);
- an error ``e`` of dimension ``k`` and its stated covariance ``C``: ``d² = eᵀC⁻¹e`` is ``χ²_k``
  (``C`` from the true noise) or ``k F(k, ν)`` (``C`` from an estimate ``σ̂²`` of ``ν`` degrees of
  freedom, independent of ``e``): the fraction of draws inside the 95 % region lies in a binomial
  band, and the mean of ``d²/k`` within the band of its sampling error (:func:`assert_calibrated`).

A wrong degree-of-freedom count, a dropped term or a missing factor moves these figures by more than
the bands allow for the ``K`` each test chooses (the mutation audit, ``benchmarks/mutants.py``,
checks that each one does).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import binom, chi2, f, norm

#: Two-sided probability that a band rejects a correct uncertainty by chance.
ALPHA = 1e-4
#: Level of the regions whose coverage is counted.
LEVEL = 0.95


def variance_band(draws: int, dof: float) -> tuple[float, float]:
    """Band of the mean of ``draws`` independent ``χ²_dof/dof`` (ratios ``σ̂²/σ²``)."""
    total = draws * dof
    return float(chi2.ppf(ALPHA / 2, total) / total), float(chi2.isf(ALPHA / 2, total) / total)


def assert_unbiased_variance(ratios: ArrayLike, dof: float) -> None:
    """``ratios (K,)`` of ``σ̂²/σ²`` over independent draws: their mean lies in :func:`variance_band`."""
    r = np.asarray(ratios, dtype=float)
    low, high = variance_band(r.size, dof)
    assert low <= r.mean() <= high, f"mean σ̂²/σ² {r.mean():.3f} over {r.size} draws outside [{low:.3f}, {high:.3f}]"


def coverage_band(draws: int, p: float) -> tuple[float, float]:
    """Band of the fraction of ``draws`` Bernoulli(``p``) trials that succeed."""
    return float(binom.ppf(ALPHA / 2, draws, p) / draws), float(binom.isf(ALPHA / 2, draws, p) / draws)


def assert_calibrated(d2: ArrayLike, k: int, dof: float = np.inf) -> None:
    """``d2 (K,)`` squared Mahalanobis distances ``eᵀC⁻¹e`` of independent errors of dimension ``k``
    under their stated covariances, ``C`` estimated with ``dof`` residual degrees of freedom
    (``inf``: the true noise): the coverage of the 95 % region and the mean of ``d²/k`` are within
    their bands (module docstring)."""
    d2 = np.asarray(d2, dtype=float)
    draws = d2.size
    if np.isinf(dof):
        p = LEVEL
        mean_low, mean_high = variance_band(draws, k)
    else:
        p = float(f.cdf(chi2.ppf(LEVEL, k) / k, k, dof))
        mean, var = f.stats(k, dof, moments="mv")  # dof > 4: finite variance
        half = float(norm.isf(ALPHA / 2)) * float(np.sqrt(var / draws))
        mean_low, mean_high = float(mean) - half, float(mean) + half
    inside = float(np.mean(d2 <= chi2.ppf(LEVEL, k)))
    low, high = coverage_band(draws, p)
    assert low <= inside <= high, (
        f"coverage {inside:.3f} of {draws} draws outside [{low:.3f}, {high:.3f}] (p = {p:.3f})"
    )
    m = float(np.mean(d2) / k)
    assert mean_low <= m <= mean_high, f"mean d²/k {m:.3f} of {draws} draws outside [{mean_low:.3f}, {mean_high:.3f}]"
