"""The README's headline Table I and II say which figure is which: the means over seeds, and beside
them seed 0's, which are what ``brachycal demo`` prints (its session is ``examples/twin_session``)."""

from __future__ import annotations

import re

from conftest import ROOT

import brachycal


def test_the_headline_quotes_the_demos_seed_0_needle_then_probe(robot):
    row = next(line for line in (ROOT / "README.md").read_text().splitlines() if "Tables I and II reproduced" in line)
    assert "Table I needle / probe" in row and "means of seeds 0–5" in row
    quoted = re.search(r"`brachycal demo`, seed 0: ([\d.]+) / ([\d.]+), ([\d.]+)", row)
    assert quoted, row
    result = brachycal.calibrate(brachycal.read_session(ROOT / "examples" / "twin_session", robot), robot)
    demo = (result.needle.validation.mae_mm, result.probe.validation.mae_mm, result.loocv["kabsch"].mae_mm)
    assert quoted.groups() == tuple(f"{figure:.2f}" for figure in demo)
