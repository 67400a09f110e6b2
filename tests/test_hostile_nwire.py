"""Hostile inputs to ``brachycal nwire``: device-set layouts it cannot use, models it does not know,
frames that cannot determine a fit — each refused in one line, nothing written.

The inputs are PLUS's fCal 2.0 device set and segmented frames (outside data, ``conftest.reference``),
edited in the case's folder.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import reference
from hostile import Case, check_refusal

CONFIG = "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
FRAMES = "fCal_3NWires_segmented_frames.xml"
NWIRE = ["nwire", "{tmp}/config.xml", "{tmp}/frames.xml", "--out", "{tmp}/nwire.json"]
REGISTRATION = "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='Reference']"


def files(edit_config: Callable[[ET.Element], None] | None = None, edit_frames=None):
    """PLUS's fCal 2.0 files as ``config.xml`` and ``frames.xml``, each optionally edited."""

    def setup(tmp: Path) -> None:
        for name, target, edit in ((CONFIG, "config.xml", edit_config), (FRAMES, "frames.xml", edit_frames)):
            source = reference("plus_fcal_nwire", name)
            if edit is None:
                shutil.copyfile(source, tmp / target)
                continue
            tree = ET.parse(source)
            edit(tree.getroot())
            tree.write(tmp / target)

    return setup


def as_1x_without_registration(root: ET.Element) -> None:
    """A 1.x-style device set (the data collection names its transforms) whose phantom was never registered."""
    names = ET.SubElement(root.find("DataCollection"), "TransformNames")
    for name in ("ProbeToTracker", "ReferenceToTracker"):
        ET.SubElement(names, "Transform", Name=name)
    definitions = root.find("CoordinateDefinitions")
    for element in list(definitions):
        if element.get("From") == "Phantom":
            definitions.remove(element)


def drop_phantom(root: ET.Element) -> None:
    root.remove(root.find("PhantomDefinition"))


def drop_a_wire(root: ET.Element) -> None:
    pattern = root.find("PhantomDefinition/Geometry/Pattern")
    pattern.remove(pattern.findall("Wire")[2])


def no_segmented_calibration_frame(root: ET.Element) -> None:
    for frame in root.iter("Frame"):
        if frame in list(root.find(".//CalibrationData")):
            frame.set("SegmentationStatus", "Failed")


CASES = [
    Case(
        "nwire-1x-device-set-without-registration",
        NWIRE,
        ("config.xml", "no phantom registration", REGISTRATION),
        files(edit_config=as_1x_without_registration),
    ),
    Case(
        "nwire-device-set-without-phantom",
        NWIRE,
        ("config.xml", "no N-wire patterns", "PlusConfiguration/PhantomDefinition"),
        files(edit_config=drop_phantom),
    ),
    Case(
        "nwire-pattern-with-two-wires",
        NWIRE,
        ("config.xml", "PlusConfiguration/PhantomDefinition/Geometry/Pattern[1]", "2 wires, expected 3"),
        files(edit_config=drop_a_wire),
    ),
    Case(
        "nwire-no-segmented-calibration-frame",
        NWIRE,
        ("frames.xml", "only 0 usable middle-wire points"),
        files(edit_frames=no_segmented_calibration_frame),
    ),
    Case(
        "nwire-unknown-model",
        [*NWIRE, "--model", "4d-aniso"],
        ("--model", "invalid choice", "4d-aniso"),
        files(),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_nwire_refusals(case, tmp_path):
    check_refusal(case, tmp_path)
