"""Hostile robot descriptions: every command that takes ``--urdf`` refuses a file that is not a
loadable URDF with one line naming it, exit code 2, nothing written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli

URDF = ROOT / "urdf" / "sda10f.urdf"


def write(name: str, text: str):
    def setup(tmp: Path) -> None:
        (tmp / name).write_text(text)

    return setup


def bundled_with(old: str, new: str):
    """The bundled SDA10F description with one edit (mesh paths made absolute so it loads from tmp)."""

    def setup(tmp: Path) -> None:
        text = URDF.read_text().replace('filename="meshes/', f'filename="{URDF.parent}/meshes/')
        assert old in text
        (tmp / "robot.urdf").write_text(text.replace(old, new, 1))

    return setup


CASES = [
    Case("model-urdf-missing", ["model", "--urdf", "{tmp}/none.urdf"], ["none.urdf"]),
    Case("model-urdf-is-a-folder", ["model", "--urdf", "{tmp}"], []),
    Case("model-urdf-empty", ["model", "--urdf", "{tmp}/robot.urdf"], ["robot.urdf"], write("robot.urdf", "")),
    Case(
        "model-urdf-malformed-xml",
        ["model", "--urdf", "{tmp}/robot.urdf"],
        ["robot.urdf"],
        write("robot.urdf", "<robot name='x'><link name='a'></robot>"),
    ),
    Case(
        "model-urdf-not-a-robot",
        ["model", "--urdf", "{tmp}/robot.urdf"],
        ["robot.urdf"],
        write("robot.urdf", "<html><body>not a robot</body></html>"),
    ),
    Case(
        "model-urdf-without-tool-frames",
        ["fk", "{log}", "--frames", "needle_tip", "--urdf", "{tmp}/robot.urdf", "--out", "{tmp}/p.csv"],
        ["needle_tip"],
        write(
            "robot.urdf",
            "<robot name='r'><link name='base_link'/><link name='l1'/>"
            "<joint name='j1' type='revolute'><parent link='base_link'/><child link='l1'/>"
            "<axis xyz='0 0 1'/><limit lower='-1' upper='1' effort='1' velocity='1'/></joint></robot>",
        ),
    ),
    Case(
        "fk-urdf-with-a-joint-renamed",
        ["fk", "{log}", "--frames", "needle_tip", "--urdf", "{tmp}/robot.urdf", "--out", "{tmp}/p.csv"],
        ["missing joint", "arm_left_joint_1_x"],
        bundled_with('joint name="arm_left_joint_1_s"', 'joint name="arm_left_joint_1_x"'),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_a_bad_robot_description_is_refused_in_one_line(case, tmp_path):
    check_refusal(case, tmp_path, log=ROOT / "examples" / "joint_log.csv")


def test_the_bundled_description_is_described():
    outcome = run_cli(["model"])
    assert outcome.code == 0 and "15 controlled axes" in outcome.out and "needle_tip" in outcome.out


# urdfdom (Pinocchio's C++ URDF parser) prints its errors on the process's standard error, where
# the in-process harness does not look: these run the command in a process of its own.
URDFDOM_REFUSALS = {
    "revolute-joint-without-limits": (
        "<robot name='x'><link name='a'/><link name='b'/>"
        "<joint name='j' type='revolute'><parent link='a'/><child link='b'/></joint></robot>",
        "Joint [j] is of type REVOLUTE but it does not specify limits",
    ),
    # urdfdom drops the inertial it cannot read and returns a model all the same: refused, not used
    "mass-not-a-number": (
        "<robot name='x'><link name='a'><inertial><mass value='abc'/>"
        "<inertia ixx='1' ixy='0' ixz='0' iyy='1' iyz='0' izz='1'/></inertial></link></robot>",
        "Inertial: mass [abc] is not a float",
    ),
}


@pytest.mark.parametrize("name", URDFDOM_REFUSALS)
def test_urdfdom_errors_are_one_line_naming_the_file_not_its_own_printout(tmp_path, name):
    text, said = URDFDOM_REFUSALS[name]
    (tmp_path / "robot.urdf").write_text(text)
    done = subprocess.run(
        [sys.executable, "-m", "brachycal.cli.main", "model", "--urdf", "robot.urdf"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert done.stderr == f"brachycal: error: robot.urdf: Pinocchio cannot load this URDF (urdfdom: {said})\n"


def test_other_text_on_standard_error_while_urdfdom_parses_is_kept(capfd):
    """The capture is scoped to urdfdom's lines: anything else written meanwhile is written back."""
    from brachycal.model.robot import urdfdom_errors

    with urdfdom_errors() as errors:
        os.write(2, b"Error:   from urdfdom\n         at line 1 in x.cpp\nsomeone else's line\n")
    assert errors == ["from urdfdom"]
    assert capfd.readouterr().err == "someone else's line\n"
