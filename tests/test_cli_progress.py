"""Long commands show their progress: ``calibrate --solve chain --identify-robot`` names each stage
as it starts, with its counts (one line per held-out fold), on a terminal's stderr; none with
--quiet or when stderr is not a terminal."""

from __future__ import annotations

import io

import pytest
from conftest import ROOT

from brachycal.calibration import calibrate_folder
from brachycal.cli.common import stage_lines
from brachycal.cli.main import main
from brachycal.model import Robot
from brachycal.reporting import chain_summary

TWIN = ROOT / "examples" / "twin_session"


class Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_the_identification_names_each_stage_with_its_counts():
    stages: list[str] = []
    calibrated = calibrate_folder(TWIN, Robot.load(), chain=True, identify_robot=True, stage=stages.append)
    assert stages[0] == "sequential calibration: 5 image methods, leave-one-out over 64 samples"
    assert stages[1].startswith("robot identification: ") and "64 samples" in stages[1]
    folds = [line for line in stages if line.startswith("held-out configurations: fold ")]
    assert [line.split()[3] for line in folds] == [str(k) for k in range(1, 9)]
    assert all(" of 8 " in line for line in folds)
    assert stages[-1].startswith("the chain's leave-one-out over 64 samples")
    # and the summary calibrate prints ends with the identification's verdict: the example's twin robot is
    # its URDF, so identification gains nothing beyond chance at held-out configurations
    summary = chain_summary(calibrated.chain, calibrated.session.sample_ids).splitlines()
    assert summary[-1].startswith("  verdict: keep the URDF: held-out image error ")
    assert summary[-1].endswith("; calibrate again without --identify-robot for a result on the URDF")


def test_stage_lines_are_shown_on_a_terminal_only_and_not_with_quiet():
    terminal = Terminal()
    say = stage_lines(False, terminal)
    assert say is not None
    say("held-out configurations: fold 1 of 8")
    assert terminal.getvalue().startswith("brachycal: [0 s] held-out configurations: fold 1 of 8")
    assert stage_lines(True, Terminal()) is None
    assert stage_lines(False, io.StringIO()) is None


@pytest.mark.parametrize("quiet", [False, True])
def test_calibrate_shows_its_stages_on_a_terminal(tmp_path, monkeypatch, capsys, quiet):
    terminal = Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    argv = ["calibrate", str(TWIN), "--solve", "chain", "--out", str(tmp_path / "r.json")]
    assert main(argv + (["--quiet"] if quiet else [])) == 0
    shown = terminal.getvalue()
    assert ("sequential calibration: 5 image methods" in shown) is not quiet
    assert ("the chain's leave-one-out over 64 samples" in shown) is not quiet
