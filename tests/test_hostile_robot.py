"""Hostile inputs to ``brachycal robot identify touches`` and ``robot identify session``: each refused in one
line, exit code 2, nothing written."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import pytest
from hostile import Case, check_refusal

from brachycal.model.description_file import example_robot_data_share

ROOT = Path(__file__).resolve().parents[1]
SESSION = ["robot", "identify", "session", str(ROOT / "examples" / "twin_session"), "--out", "{tmp}/out"]

URDF = example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf"
ROW = "0.1,0.2,0.3,-2.0,0.1,2.2,0.7\n"
BASE = ["robot", "identify", "touches", "{tmp}/a", "{tmp}/b", "--urdf", str(URDF), "--tool-frame", "panda_hand_tcp"]
RUN = [*BASE, "--train", "a", "--out", "{tmp}/out"]


def _places(a: dict[str, str], b: dict[str, str] | None = None) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        for name, tables in (("a", a), ("b", b if b is not None else {"hole_0.csv": ROW * 3, "hole_1.csv": ROW * 3})):
            (tmp / name).mkdir()
            for file, text in tables.items():
                (tmp / name / file).write_text(text)

    return setup


def _urdf_in_out(tmp: Path) -> None:
    _places(GOOD)(tmp)
    (tmp / "out").mkdir()
    (tmp / "out" / "robot.urdf").write_text(URDF.read_text())


GOOD = {"hole_0.csv": ROW * 3, "hole_1.csv": ROW * 3}


def _massless(tmp: Path) -> None:
    """The places, and the Panda's URDF with its masses stripped (every ``<inertial>`` element)."""
    _places(GOOD)(tmp)
    (tmp / "massless.urdf").write_text(re.sub(r"<inertial>.*?</inertial>", "", URDF.read_text(), flags=re.S))


CASES = [
    Case("missing-folder", RUN, ("a", "not a folder")),
    Case("no-tables", RUN, ("no touch table",), setup=_places({"notes.txt": "x"})),
    Case(
        "gap-in-numbering",
        RUN,
        ("hole_1.csv is missing",),
        setup=_places({"hole_0.csv": ROW * 3, "hole_2.csv": ROW * 3}),
    ),
    Case(
        "one-point-twice",
        RUN,
        ("hole_01.csv and hole_1.csv", "point 1"),
        setup=_places({"hole_0.csv": ROW * 3, "hole_1.csv": ROW * 3, "hole_01.csv": ROW * 3}),
    ),
    Case("short-row", RUN, ("hole_0.csv", "row 2", "expected 7"), setup=_places({"hole_0.csv": ROW + "0.1,0.2\n"})),
    Case(
        "text-field",
        RUN,
        ("hole_0.csv", "row 1", "panda_joint4", "not a number"),
        setup=_places({"hole_0.csv": "0.1,0.2,0.3,x,0.1,2.2,0.7\n" + ROW}),
    ),
    Case(
        "degrees",
        RUN,
        ("row 2", "panda_joint6", "radians"),
        setup=_places({"hole_0.csv": ROW + "0.1,0.2,0.3,-2.0,0.1,126,0.7\n"}),
    ),
    Case("one-touch", RUN, ("1 touch",), setup=_places({"hole_0.csv": ROW})),
    Case("truncated", RUN, ("truncated",), setup=_places({"hole_0.csv": ROW * 2 + ROW.strip()})),
    Case("binary", RUN, ("hole_0.csv",), setup=_places({"hole_0.csv": "\x00\xff" * 10})),
    Case("train-not-a-place", [*BASE, "--train", "c", "--out", "{tmp}/out"], ("'c'", "not among"), setup=_places(GOOD)),
    Case(
        "tool-frame-unknown",
        [*BASE[:-1], "tip", "--train", "a", "--out", "{tmp}/out"],
        ("tip",),
        setup=_places(GOOD),
    ),
    Case(
        "distance-not-positive",
        [*RUN, "--distance-mm", "-50"],
        ("--distance-mm",),
        setup=_places(GOOD),
    ),
    Case(
        "distance-with-one-point",
        [*RUN, "--distance-mm", "50"],
        ("distance", "points 0 and 1"),
        setup=_places({"hole_0.csv": ROW * 3}),
    ),
    Case("accuracy-zero", [*RUN, "--robot-accuracy-mm", "0"], ("--robot-accuracy-mm",), setup=_places(GOOD)),
    Case("identical-touches", RUN, ("do not determine",), setup=_places(GOOD)),
    Case(
        "out-replaces-the-urdf",
        [*BASE[:6], "{tmp}/out/robot.urdf", *BASE[7:], "--train", "a", "--out", "{tmp}/out", "--force"],
        ("input",),
        setup=_urdf_in_out,
    ),
    Case("unknown-protocol", ["robot", "identify", "laser", "{tmp}/a"], ("laser",)),
    Case("tracker-option", [*RUN, "--columns", "{tmp}/c.toml"], ("unrecognized", "--columns"), setup=_places(GOOD)),
    Case("no-train", [*BASE, "--out", "{tmp}/out"], ("--train", "required"), setup=_places(GOOD)),
    Case(
        "urdf-without-tool-frame",
        [*BASE[:-2], "--train", "a", "--out", "{tmp}/out"],
        ("--tool-frame", "required"),
        setup=_places(GOOD),
    ),
    Case("robot-and-urdf", [*RUN, "--robot", "panda"], ("--robot", "--urdf", "one"), setup=_places(GOOD)),
    Case(
        "unknown-robot-name",
        [*RUN[:5], "--robot", "no_such_arm", *RUN[7:]],
        ("no_such_arm",),
        setup=_places(GOOD),
    ),
    Case("session-on-a-single-arm", [*SESSION, "--robot", "panda"], ("panda", "arm")),
    Case(
        "session-on-a-plain-urdf",
        [*SESSION, "--urdf", str(URDF)],
        ("arm",),
    ),
    Case(
        "session-missing",
        ["robot", "identify", "session", "{tmp}/nothing", "--out", "{tmp}/out"],
        ("nothing",),
    ),
    Case("session-touches-option", [*SESSION, "--train", "a"], ("unrecognized", "--train")),
    Case("tilt-zero", [*RUN, "--robot-tilt-deg", "0"], ("--robot-tilt-deg",), setup=_places(GOOD)),
    Case("tilt-huge", [*RUN, "--robot-tilt-deg", "5"], ("--robot-tilt-deg", "1"), setup=_places(GOOD)),
    Case("tilt-nan", [*RUN, "--robot-tilt-deg", "nan"], ("--robot-tilt-deg",), setup=_places(GOOD)),
    Case(
        "dynamics-unknown-name",
        [*RUN, "--dynamics", "pandas"],
        ("--dynamics", "unknown robot 'pandas'", "panda"),
        setup=_places(GOOD),
    ),
    Case(
        "dynamics-of-another-arm",
        [*RUN, "--dynamics", "ur5"],
        ("--dynamics", "no joint panda_joint1", "same arm"),
        setup=_places(GOOD),
    ),
    Case(
        "dynamics-without-masses",
        [*RUN, "--dynamics", "{tmp}/massless.urdf"],
        ("--dynamics", "massless.urdf", "no mass", "<inertial>"),
        setup=_massless,
    ),
    Case("dynamics-a-folder", [*RUN, "--dynamics", "{tmp}/a"], ("--dynamics", "is a folder"), setup=_places(GOOD)),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_refused_in_one_line_with_nothing_written(case, tmp_path):
    check_refusal(case, tmp_path)
