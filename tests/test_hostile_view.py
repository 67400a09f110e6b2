"""Hostile inputs to ``brachycal view``: each is refused before anything is served, as every refusal
must be (:func:`hostile.check_refusal`): exit code 2, one line naming the option or the file,
nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli

SESSION = str(ROOT / "examples" / "twin_session")

CASES = [
    Case("result-without-session", ["view", "{result}"], ("--session",)),
    Case("method-without-result", ["view", "--session", SESSION, "--method", "kabsch"], ("--method", "RESULT")),
    Case("unknown-method", ["view", "{result}", "--session", SESSION, "--method", "magic"], ("--method",)),
    Case("method-not-in-result", ["view", "{result}", "--session", SESSION, "--method", "icp"], ("icp",)),
    Case("port-out-of-range", ["view", "--port", "70000"], ("--port",)),
    Case("port-not-a-number", ["view", "--port", "nan"], ("--port",)),
    Case("targets-zero", ["view", "{result}", "--session", SESSION, "--targets", "0"], ("--targets",)),
    Case("missing-session", ["view", "--session", "{tmp}/nowhere"], ("nowhere",)),
    Case("missing-plan", ["view", "--plan", "{tmp}/nowhere.csv"], ("nowhere.csv",)),
    Case("plan-and-session", ["view", "--plan", "{tmp}/p.csv", "--session", SESSION], ("--session", "--plan")),
    Case("result-of-another-robot", ["view", "{result}", "--session", SESSION, "--robot", "baxter"], ("baxter",)),
    Case("unknown-robot", ["view", "--robot", "kuka"], ("kuka",)),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A result file with the Kabsch calibration only, outside the cases' folders."""
    result = tmp_path_factory.mktemp("inputs") / "result.json"
    assert run_cli(["calibrate", SESSION, "--out", str(result), "--methods", "kabsch", "--quiet"]).code == 0
    return {"result": result}


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_view_refusals(case, tmp_path, inputs):
    check_refusal(case, tmp_path, **inputs)
