"""Hostile inputs to ``brachycal export``'s hand-off options (``--ros-package``, the package's files).

Each row is refused as every refusal must be (:func:`hostile.check_refusal`): exit code 2, one line
naming the option or the file, nothing written.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli

SESSION = ROOT / "examples" / "twin_session"


def existing(*names: str) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        for name in names:
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text("kept\n")

    return setup


def urdf_without_meshes(tmp: Path) -> None:
    """The bundled SDA10F's URDF copied alone: its meshes are not beside it."""
    (tmp / "alone.urdf").write_text((ROOT / "urdf" / "sda10f.urdf").read_text())


CASES = [
    *(
        Case(
            f"ros-package-{label}",
            ["export", "{result}", "--out", "{tmp}/x", "--ros-package", name],
            ("--ros-package",),
        )
        for label, name in (
            ("uppercase", "Sda10f"),
            ("starts-with-a-digit", "1cal"),
            ("hyphen", "sda10f-cal"),
            ("double-underscore", "sda10f__cal"),
            ("trailing-underscore", "sda10f_"),
            ("a-path", "../cal"),
            ("empty", ""),
        )
    ),
    Case(
        "ros-package-file-exists",
        ["export", "{result}", "--out", "{tmp}/x", "--ros-package", "cal"],
        ("package.xml", "already exists", "--force"),
        existing("x/cal/package.xml"),
    ),
    Case(
        "ros-package-folder-is-a-file",
        ["export", "{result}", "--out", "{tmp}/x", "--ros-package", "cal"],
        ("cal", "not a folder"),
        existing("x/cal"),
    ),
    # The export copies the URDF's meshes: one it cannot find is named, nothing is written.
    Case(
        "urdf-whose-meshes-are-missing",
        ["export", "{result}", "--out", "{tmp}/x", "--urdf", "{tmp}/alone.urdf"],
        ("alone.urdf", "mesh", "not a file"),
        urdf_without_meshes,
    ),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A valid result file, outside the cases' folders."""
    result = tmp_path_factory.mktemp("inputs") / "result.json"
    assert run_cli(["calibrate", str(SESSION), "--out", str(result), "--quiet"]).code == 0
    return {"result": result}


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_export_handoff_refusals(case, tmp_path, inputs):
    check_refusal(case, tmp_path, **inputs)
