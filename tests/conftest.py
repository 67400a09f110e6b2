"""Shared fixtures: the bundled robot, the vendor's model, random configurations."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import settings

from brachycal.model import Robot

# On CI, property-based tests draw the same examples every run (a failure found there can be
# replayed); locally they explore new ones each time.
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

ROOT = Path(__file__).parents[1]
#: Outside data (the vendor's SDA10F description, PLUS and SciKit-Surgery recordings) is not in the
#: repository: it is read from wherever ``BRACHYCAL_REFERENCE`` points (default: ``shared/reference``
#: beside the clone; CI has it). docs/reference_data.md says where each part
#: comes from.
REFERENCE = Path(os.environ.get("BRACHYCAL_REFERENCE") or ROOT.parent / "shared" / "reference")


def reference(*parts: str) -> Path:
    """Path of a file or folder of the outside data, or skip the test saying what it needs.

    On CI (``CI`` set) the data must be there: a missing file fails the test instead of skipping
    it, so that a broken checkout cannot pass by skipping.
    """
    path = REFERENCE.joinpath(*parts)
    if not path.exists():
        reason = (
            f"needs {path} (outside data: the PLUS toolkit's PlusLibData, SciKit-Surgery and ROS-Industrial "
            "motoman files: set BRACHYCAL_REFERENCE to a copy of them; docs/reference_data.md says where "
            "each comes from)"
        )
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    return path


@pytest.fixture(scope="session")
def robot() -> Robot:
    return Robot.load()


@pytest.fixture(scope="session")
def vendor_model() -> pin.Model:
    """The vendor URDF as Pinocchio reads it: 16 axes, ``torso_joint_b2`` independent."""
    return pin.buildModelFromUrdf(str(reference("motoman_sda10f", "sda10f_expanded.urdf")))


def random_configurations(robot: Robot, n: int, seed: int = 0) -> np.ndarray:
    """``(n, nq)`` configurations drawn uniformly inside the joint limits."""
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.lower, robot.upper, size=(n, robot.nq))


@pytest.fixture(scope="session")
def truth(robot):
    from brachycal.simulation import default_truth

    return default_truth(robot)


@pytest.fixture(scope="session")
def exact(robot, truth):
    """A noise-free 64-sample session hiding ``truth``."""
    from brachycal.simulation import exact_session

    return exact_session(robot, truth)


@pytest.fixture
def session_dir(tmp_path, exact):
    """The exact session written to a folder (a fresh copy per test)."""
    from brachycal.data.session import write_session

    return write_session(exact, tmp_path / "session")


# --- comparing numbers that two runs compute -------------------------------------------------------
# Regenerated files and results computed on another machine (another CPU, BLAS/LAPACK build or
# library version) agree with the committed ones only to the last few bits (~1e-16 relative), so
# tests compare them numerically. The bounds are far above round-off and far below anything the
# results resolve (encoder noise ~1e-5 rad, the calibration's ~0.1 mm, annotation ~1 px): a real
# change of the computation (another seed, sample, pose or formula) moves values by many orders more.
#: Joint values (rad), positions (m) and unitless numbers (rotation entries, ratios).
TOLERANCE_SI = 1e-9
#: Values in millimetres (1e-6 mm = 1e-9 m).
TOLERANCE_MM = 1e-6
#: Pixel values.
TOLERANCE_PX = 1e-6
#: Joint readings of simulated sessions. They come from damped IK on 7-axis arms, which stops
#: anywhere on the arm's self-motion within its 1e-12 m tolerance: round-off steers it along the
#: null space by ~1e-9 rad on another machine (measured 1.2e-9). 1e-7 rad moves a tool by < 0.2 µm
#: at the arms' 1.5 m reach: far below the twin's 2e-5 rad encoder noise.
TOLERANCE_JOINT_RAD = 1e-7


def tolerance_for(name: str) -> float:
    """Agreement demanded of a field, from the unit its name says (``*_px``, ``*_mm``, a joint
    name in radians, else SI)."""
    from brachycal.model.names import JOINT_NAMES

    if name in JOINT_NAMES or name.endswith("_q"):  # a joint column, or configurations (``true_samples_q``)
        return TOLERANCE_JOINT_RAD
    if name.endswith("_px"):
        return TOLERANCE_PX
    if name.endswith("_mm"):
        return TOLERANCE_MM
    return TOLERANCE_SI


def assert_same_numbers(got: object, want: object, where: str = "value") -> None:
    """Two JSON-like structures agree: same keys, lengths, strings, booleans and integers, and
    floats within :func:`tolerance_for` the innermost key naming them."""
    _compare(got, want, where, tolerance_for(where))


def _compare(got: object, want: object, where: str, tolerance: float) -> None:
    if isinstance(want, dict):
        assert isinstance(got, dict) and list(got) == list(want), f"{where}: keys {list(got)} != {list(want)}"
        for key in want:
            _compare(
                got[key], want[key], f"{where}[{key}]", tolerance_for(str(key)) if isinstance(key, str) else tolerance
            )
    elif isinstance(want, list | tuple):
        assert isinstance(got, list | tuple) and len(got) == len(want), f"{where}: length {len(got)} != {len(want)}"
        for k, (a, b) in enumerate(zip(got, want, strict=True)):
            _compare(a, b, f"{where}[{k}]", tolerance)
    elif isinstance(want, float) or isinstance(got, float):
        assert isinstance(got, int | float) and not isinstance(got, bool), f"{where}: {got!r} is not a number"
        assert abs(got - want) <= tolerance, f"{where}: {got!r} != {want!r} (tolerance {tolerance:g})"
    else:  # strings, booleans, integers (counts, seeds, trial numbers), None: copied, not computed
        assert got == want, f"{where}: {got!r} != {want!r}"


def _csv_cells(path: Path) -> list[dict[str, object]]:
    import csv

    def value(text: str) -> object:
        try:
            return int(text)
        except ValueError:
            pass
        try:
            return float(text)
        except ValueError:
            return text

    with path.open(newline="") as handle:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(handle)]


def _xml_tree(path: Path) -> list[object]:
    """An XML file as nested lists: tag, attributes (numbers parsed, file paths resolved), children."""
    import xml.etree.ElementTree as ET

    def node(element: ET.Element) -> list[object]:
        attributes: dict[str, object] = {}
        for key, text in element.attrib.items():
            if key in {"filename", "meshdir"} and "://" not in text:
                attributes[key] = str((path.parent / text).resolve())  # relative to where each file sits
                continue
            try:
                attributes[key] = [float(v) for v in text.split()]
            except ValueError:
                attributes[key] = text
        return [element.tag, attributes, (element.text or "").strip(), [node(child) for child in element]]

    return node(ET.parse(path).getroot())


def assert_same_files(
    got_folder: Path, want_folder: Path, names: list[str], *, joint_tolerance: float | None = None
) -> None:
    """The files ``names`` in two folders hold the same content, numbers compared as
    :func:`assert_same_numbers` does (CSV by column name, JSON by key, TOML by key, XML by
    attribute; mesh paths compared as the files they resolve to). ``joint_tolerance`` replaces
    :data:`TOLERANCE_JOINT_RAD` for joint columns (for joints that an iterative planner chose)."""
    global TOLERANCE_JOINT_RAD
    import json
    import tomllib

    readers = {
        ".csv": _csv_cells,
        ".json": lambda p: json.loads(p.read_text()),
        ".toml": lambda p: tomllib.loads(p.read_text()),
        ".urdf": _xml_tree,
        ".xml": _xml_tree,
    }
    default = TOLERANCE_JOINT_RAD
    TOLERANCE_JOINT_RAD = default if joint_tolerance is None else joint_tolerance
    try:
        for name in names:
            read = readers[Path(name).suffix]
            assert_same_numbers(read(got_folder / name), read(want_folder / name), name)
    finally:
        TOLERANCE_JOINT_RAD = default
