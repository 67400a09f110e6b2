"""The identification's verdict: use the identified robot only when it predicts held-out
configurations better by more than twice the standard error of the gain over the folds."""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.robot.identification import (
    IDENTIFICATION_FOLDS,
    identification_folds,
    identification_verdict,
)


def _held_out(gain_mm: float, spread_mm: float, n: int = 64, seed: int = 1) -> tuple[ErrorStats, ErrorStats]:
    """Per-sample held-out errors without identification (~0.33 mm) and with it, the latter smaller
    by ``gain_mm`` in each sample, give or take ``spread_mm`` (metres in the stats)."""
    rng = np.random.default_rng(seed)
    alone = 0.33e-3 + 0.05e-3 * rng.random(n)
    identified = alone - gain_mm * 1e-3 + spread_mm * 1e-3 * rng.standard_normal(n)
    return ErrorStats(alone), ErrorStats(np.abs(identified))


def test_the_folds_cover_every_sample_once():
    parts = identification_folds(64)
    assert len(parts) == IDENTIFICATION_FOLDS
    assert sorted(np.concatenate(parts).tolist()) == list(range(64))


def test_a_clear_held_out_gain_says_use_the_identified_robot():
    verdict = identification_verdict(_held_out(gain_mm=0.03, spread_mm=0.005))
    assert verdict.use and verdict.gain_mm > 2 * verdict.se_mm
    assert verdict.gain_mm == pytest.approx(0.03, abs=0.005)
    sentence = verdict.sentence()
    assert sentence.startswith("use the identified robot: held-out image error ")
    assert "more than 2 x its standard error" in sentence


def test_a_gain_within_chance_says_keep_the_urdf():
    verdict = identification_verdict(_held_out(gain_mm=0.001, spread_mm=0.05))
    assert not verdict.use and verdict.gain_mm < 2 * verdict.se_mm
    assert verdict.sentence().startswith("keep the URDF: held-out image error ")


def test_an_identification_that_predicts_worse_says_keep_the_urdf():
    verdict = identification_verdict(_held_out(gain_mm=-0.03, spread_mm=0.005))
    assert not verdict.use and verdict.gain_mm < 0
    assert "identification predicts no better (worse by" in verdict.sentence()


def test_the_verdict_reads_the_folds_not_the_pooled_samples():
    """A gain carried by one fold alone (one lucky split) is not consistent across folds: its SE is
    large, and the verdict keeps the URDF although the pooled RMSE is lower."""
    n = 64
    alone = np.full(n, 0.33e-3)
    identified = alone.copy()
    identified[identification_folds(n)[0]] = 0.10e-3  # one fold much better, the others the same
    held = (ErrorStats(alone), ErrorStats(identified))
    assert held[1].rmse_mm < held[0].rmse_mm
    assert not identification_verdict(held).use
