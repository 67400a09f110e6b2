"""Hostile input to the excitation poses: ``brachycal plan excitation`` and ``brachycal design
--robot-error`` refuse each with one line naming the option or file, exit code 2, nothing written."""

from __future__ import annotations

import pytest
from conftest import ROOT
from hostile import Case, check_refusal

SESSION = ROOT / "examples" / "twin_session"
EXCITE = ["plan", "excitation", str(SESSION), "--out", "{tmp}/excitation.csv", "--quiet"]
DESIGN = ["design", "--out", "{tmp}/design", "--robot-error", "real-arm", "--quiet"]

CASES = [
    Case("missing-session", ["plan", "excitation", "{tmp}/nowhere", "--out", "{tmp}/x.csv"], ("nowhere",)),
    Case("zero-budget", [*EXCITE, "--excitation-minutes", "0"], ("--excitation-minutes",)),
    Case("negative-budget", [*EXCITE, "--excitation-minutes", "-5"], ("--excitation-minutes",)),
    Case("absurd-budget", [*EXCITE, "--excitation-minutes", "1e6"], ("--excitation-minutes",)),
    Case("nan-budget", [*EXCITE, "--excitation-minutes", "nan"], ("--excitation-minutes",)),
    Case("other-robot", [*EXCITE, "--robot", "baxter"], ("touches.csv",)),
    Case("robot-without-self-motion", [*EXCITE, "--robot", "ur5_pair"], ("ur5_pair", "one way")),
    Case("with-result", [*EXCITE, "--result", "{tmp}/r.json"], ("--result",)),
    Case("design-with-designs", [*DESIGN, "--designs", "grid 3x3x3"], ("--designs",)),
    Case("design-zero-budget", [*DESIGN, "--excitation-minutes", "0"], ("--excitation-minutes",)),
    Case("design-unknown-level", [*DESIGN[:3], "--robot-error", "rusty"], ("--robot-error",)),
    Case("design-robot-without-torso", [*DESIGN, "--robot", "baxter"], ("baxter", "shared", "held-out")),
    Case(
        "accuracy-without-excitation",
        ["plan", "--out", "{tmp}/p.csv", "--robot-accuracy-mm", "0.1"],
        ("--robot-accuracy-mm",),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_refusals(case, tmp_path):
    check_refusal(case, tmp_path)
