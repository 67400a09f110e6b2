"""Pieces of the PLUS XML files the twins write (device sets, segmented frames): numbers as PLUS
reads them, the phantom's N-wire definition, the probe calibration's frame names, the file itself."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from brachycal.io import atomic_open


def numbers_text(values: ArrayLike) -> str:
    """Space-separated numbers, each written so that it reads back exactly (``repr``)."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def add_phantom_definition(
    root: ET.Element,
    patterns_mm: Sequence[Sequence[tuple[str, ArrayLike, ArrayLike]]],
    *,
    name: str,
    version: str,
    wiring_version: str,
) -> ET.Element:
    """Add ``PhantomDefinition`` with its N-wire ``patterns_mm`` (per pattern, each wire's name and
    front and back end points, millimetres, phantom frame); returns its ``Geometry`` element."""
    phantom = ET.SubElement(root, "PhantomDefinition")
    ET.SubElement(phantom, "Description", Name=name, Type="Multi-N", Version=version, WiringVersion=wiring_version)
    geometry = ET.SubElement(phantom, "Geometry")
    for pattern in patterns_mm:
        element = ET.SubElement(geometry, "Pattern", Type="NWire")
        for wire, front, back in pattern:
            ET.SubElement(
                element, "Wire", Name=wire, EndPointFront=numbers_text(front), EndPointBack=numbers_text(back)
            )
    return geometry


def add_probe_calibration_algo(root: ET.Element, reference: str) -> None:
    """Add ``vtkPlusProbeCalibrationAlgo`` naming the frames (Image, Probe, Phantom, ``reference``)."""
    ET.SubElement(
        root,
        "vtkPlusProbeCalibrationAlgo",
        ImageCoordinateFrame="Image",
        ProbeCoordinateFrame="Probe",
        PhantomCoordinateFrame="Phantom",
        ReferenceCoordinateFrame=reference,
    )


def write_xml(path: str | os.PathLike[str], root: ET.Element) -> None:
    """Write ``root`` indented, with a final line break (all or nothing: :func:`~brachycal.io.atomic_open`)."""
    ET.indent(root, space="  ")
    with atomic_open(path) as handle:
        handle.write(ET.tostring(root, encoding="unicode"))
        handle.write("\n")
