"""Hostile inputs to ``brachycal robot identify tracker``: each refused in one line, exit code 2, nothing written."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from hostile import Case, check_refusal

from brachycal.model.description_file import example_robot_data_share

URDF = example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf"
JOINTS = [f"panda_joint{k}" for k in range(1, 8)]
SPEC = (
    f'format = "brachycal-tracker-columns/1"\njoints = {JOINTS!r}\n'.replace("'", '"')
    + '[position]\ncolumns = ["x", "y", "z"]\nunit = "{unit}"\n'
)
HEADER = ",".join([*JOINTS, "x", "y", "z"]) + "\n"


def _row(k: int, x: str | None = None, scale: float = 1.0) -> str:
    joints = [0.1 * k, 0.2, 0.3, -2.0, 0.1, 2.2, 0.7]
    position = [x or f"{(0.5 + 0.05 * k) * scale:g}", f"{0.2 * scale:g}", f"{(0.3 + 0.02 * k) * scale:g}"]
    return ",".join([*map(str, joints), *position]) + "\n"


GOOD = HEADER + "".join(_row(k) for k in range(6))


def _files(table: str = GOOD, unit: str = "m") -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        (tmp / "table.csv").write_text(table)
        (tmp / "columns.toml").write_text(SPEC.format(unit=unit))

    return setup


#: A 6-D marker: the position's spec with a rotation vector in degrees, and a table whose angles are
#: radians (within ±π) while the first joint turns by 1.5 rad.
SPEC_6D = (
    SPEC.format(unit="m") + '[orientation]\ncolumns = ["rx", "ry", "rz"]\nkind = "rotation_vector"\nunit = "deg"\n'
)
TABLE_6D = (
    ",".join([*JOINTS, "x", "y", "z", "rx", "ry", "rz"])
    + "\n"
    + "".join(
        ",".join(map(str, [0.3 * k, 0.2, 0.3, -2.0, 0.1, 2.2, 0.7, 0.5 + 0.05 * k, 0.2, 0.3, 0.1 * k, 1.2, -0.4]))
        + "\n"
        for k in range(6)
    )
)


def _six_d(tmp: Path) -> None:
    (tmp / "table.csv").write_text(TABLE_6D)
    (tmp / "columns.toml").write_text(SPEC_6D)


def _urdf_in_out(tmp: Path) -> None:
    _files()(tmp)
    (tmp / "out").mkdir()
    (tmp / "out" / "robot.urdf").write_text(URDF.read_text())


BASE = ["robot", "identify", "tracker", "{tmp}/table.csv", "--urdf", str(URDF)]
RUN = [*BASE, "--columns", "{tmp}/columns.toml", "--flange", "panda_link8", "--out", "{tmp}/out"]

CASES = [
    Case("no-columns-spec", [*BASE, "--out", "{tmp}/out"], ("--columns", "required"), setup=_files()),
    Case("two-tables", [*RUN[:4], "{tmp}/table.csv", *RUN[4:]], ("unrecognized", "table.csv"), setup=_files()),
    Case(
        "missing-table", RUN, ("table.csv",), setup=lambda tmp: (tmp / "columns.toml").write_text(SPEC.format(unit="m"))
    ),
    Case("missing-column", RUN, ("'z'",), setup=_files(GOOD.replace(",z\n", ",zz\n"))),
    Case(
        "nan",
        RUN,
        ("row 3", "'x'"),
        setup=_files(HEADER + _row(0) + _row(1, "nan") + "".join(_row(k) for k in range(2, 6))),
    ),
    Case(
        "millimetres-as-metres",
        RUN,
        ("row 2", "'x'", "unit"),
        setup=_files(HEADER + "".join(_row(k, scale=1e3) for k in range(6))),
    ),
    Case("metres-as-millimetres", RUN, ("'x'", "metres"), setup=_files(unit="mm")),
    Case("radians-stated-as-degrees", RUN, ("'ry'", "within ±π", "radians", "unit = 'rad'"), setup=_six_d),
    Case("too-few-rows", RUN, ("posture", "at least"), setup=_files(HEADER + _row(0) + _row(1))),
    Case("bad-unit-in-spec", RUN, ("position.unit",), setup=_files(unit="cm")),
    Case("unknown-flange", [*RUN[:-4], "--flange", "hand", "--out", "{tmp}/out"], ("hand",), setup=_files()),
    Case("touches-option", [*RUN, "--train", "a"], ("unrecognized", "--train"), setup=_files()),
    Case("unknown-prior", [*RUN, "--prior", "flat"], ("--prior", "flat"), setup=_files()),
    Case("robot-and-urdf", [*RUN, "--robot", "panda"], ("--robot", "--urdf", "one"), setup=_files()),
    Case(
        "bundled-arm-without-the-table-joints",
        [*RUN[:4], "--robot", "ur5", *RUN[6:]],
        ("panda_joint1",),
        setup=_files(),
    ),
    Case(
        "out-replaces-the-urdf",
        [*RUN[:3], "{tmp}/table.csv", "--urdf", "{tmp}/out/robot.urdf", *RUN[6:], "--force"],
        ("input",),
        setup=_urdf_in_out,
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_refused_in_one_line_with_nothing_written(case, tmp_path):
    check_refusal(case, tmp_path)
