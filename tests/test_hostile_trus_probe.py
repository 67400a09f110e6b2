"""Hostile inputs to ``brachycal stepper image``, ``stepper template`` and ``stepper export``: a
template with no registration, an unknown hole, a result without the stepper's registration, a
device set that is not a stepper's — each refused in one line, nothing written.

The inputs are written in the case's folder: a small stepper device set (the iCal phantom, a
3 × 3 template) and a stepper result of exact synthetic frames (``test_trus_probe``'s).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import reference
from hostile import Case, check_refusal
from test_trus_probe import (
    TILTED_AXES,
    frames,
    ical_config,
    image_to_probe,
    random_motion,
    true_registration,
)

from brachycal.calibration.phantom.nwire_file import calibrate_nwire_frames
from brachycal.calibration.phantom.stepper_probe import (
    StepperImageResult,
    corrected_frames,
    register_phantom,
    write_stepper_image,
)
from brachycal.studies.stepper_twin import ICAL_WIRES_MM

HOLDER_TO_HOME = '<Transform From="TemplateHolder" To="TemplateHome" Matrix="1 0 0 5 0 1 0 63.5 0 0 1 0 0 0 0 1"/>'
HOLDER_TO_PHANTOM = '<Transform From="TemplateHolder" To="Phantom" Matrix="1 0 0 5 0 1 0 63.5 0 0 1 0 0 0 0 1"/>'


def device_set(definitions: str = HOLDER_TO_HOME + HOLDER_TO_PHANTOM, stepper: bool = True) -> str:
    wires = "".join(
        f'<Pattern Type="NWire">{"".join(lines)}</Pattern>'
        for lines in np.array(
            [
                f'<Wire Name="{name}" EndPointFront="{" ".join(map(str, f))}" EndPointBack="{" ".join(map(str, b))}"/>'
                for name, (f, b) in ICAL_WIRES_MM.items()
            ]
        ).reshape(3, 3)
    )
    holes = "".join(
        f'<Hole ID="{c}{r}" PositionXYZ="{10 * i} {10 * j} 0"/>'
        for i, c in enumerate("ABC")
        for j, r in enumerate("321")
    )
    ical = (
        '<iCal ProbeCoordinateFrame="Probe" TemplateCoordinateFrame="Template"/>'
        '<vtkPlusProbeCalibrationAlgo ReferenceCoordinateFrame="StepperHome"/>'
        if stepper
        else ""
    )
    return (
        f"<PlusConfiguration><CoordinateDefinitions>{definitions}</CoordinateDefinitions>{ical}"
        f"<PhantomDefinition><Geometry>{wires}</Geometry></PhantomDefinition>"
        f"<TemplateModel><HolePositions>{holes}</HolePositions></TemplateModel></PlusConfiguration>"
    )


def stepper_result(path: Path) -> None:
    """A stepper result of exact synthetic frames."""
    from dataclasses import replace

    config = replace(ical_config(), transforms={("Phantom", "Reference"): true_registration()})
    M = image_to_probe(tilt=False)
    rotation = frames(M, config, [(-0.045, np.radians(a)) for a in np.linspace(-30, 30, 31)], TILTED_AXES, "R")
    registration = register_phantom([f.points_px for f in rotation], config.patterns)
    cal = corrected_frames(frames(M, config, random_motion(1, 12), TILTED_AXES, "CalibrationData"), TILTED_AXES)
    val = corrected_frames(frames(M, config, random_motion(2, 6), TILTED_AXES, "ValidationData"), TILTED_AXES)
    nwire = calibrate_nwire_frames(config, cal, val)
    write_stepper_image(StepperImageResult(nwire, None, registration, TILTED_AXES), path)


def files(config: str | None = None, result: bool = True, plain_nwire: bool = False, edit=None):
    """Setup: ``config.xml``, a stepper result ``result.json`` (without its stepper block with
    ``plain_nwire``; changed by ``edit(document)``) and empty recordings."""

    def setup(tmp: Path) -> None:
        (tmp / "config.xml").write_text(config if config is not None else device_set())
        if result:
            stepper_result(tmp / "result.json")
        if plain_nwire or edit is not None:
            raw = json.loads((tmp / "result.json").read_text())
            if plain_nwire:
                raw.pop("stepper")
            if edit is not None:
                edit(raw)
            (tmp / "result.json").write_text(json.dumps(raw))
        for name in ("rotation.mha", "calibration.mha", "validation.mha"):
            (tmp / name).write_bytes(b"")

    return setup


def chosen(key: str, row: int, column: int, value: float):
    """An edit: element ``[row][column]`` of the chosen model's ``key`` (``image_to_probe_mm``) set to ``value``."""

    def edit(raw: dict) -> None:
        raw["models"][raw["model"]][key][row][column] = value

    return edit


def set_in(value: object, *keys: str | int):
    """An edit: ``raw[keys[0]][keys[1]]...`` set to ``value``."""

    def edit(raw: dict) -> None:
        for key in keys[:-1]:
            raw = raw[key]
        raw[keys[-1]] = value

    return edit


TEMPLATE = ["stepper", "template", "{tmp}/result.json", "--config", "{tmp}/config.xml", "--probe-position", "-50"]
IMAGE = [
    "stepper",
    "image",
    "{tmp}/rotation.mha",
    "{tmp}/calibration.mha",
    "{tmp}/validation.mha",
    "--config",
    "{tmp}/config.xml",
    "--out",
    "{tmp}/out.json",
]
CASES = [
    Case(
        "template-without-registration",
        [*TEMPLATE, "--hole", "B2"],
        ["config.xml", "no template registration", "Transform[@From='TemplateHolder'][@To='TemplateHome']"],
        files(device_set(HOLDER_TO_PHANTOM)),
    ),
    Case(
        "template-not-on-the-phantom",
        [*TEMPLATE, "--hole", "B2"],
        ["no template registration", "[@To='Phantom']"],
        files(device_set(HOLDER_TO_HOME)),
    ),
    Case("unknown-hole", [*TEMPLATE, "--hole", "Z9"], ["config.xml", "no template hole 'Z9'", "A3"], files()),
    Case(
        "not-a-finite-depth",
        [*TEMPLATE, "--hole", "B2", "--depth", "nan"],
        ["finite"],
        files(),
    ),
    Case(
        "result-without-stepper",
        [*TEMPLATE, "--hole", "B2"],
        ["result.json", "no stepper registration", "stepper"],
        files(plain_nwire=True),
    ),
    Case(
        "export-result-without-stepper",
        ["stepper", "export", "{tmp}/result.json", "--out", "{tmp}/exports"],
        ["no stepper registration"],
        files(plain_nwire=True),
    ),
    # A result file is checked whole before it is used (brachycal.data.json_schema), by every reader.
    *(
        Case(
            f"{command}-{name}",
            argv,
            ["result.json", *expect],
            files(edit=edit),
        )
        for command, argv in (
            ("template", [*TEMPLATE, "--hole", "B2"]),
            ("export", ["stepper", "export", "{tmp}/result.json", "--out", "{tmp}/exports"]),
        )
        for name, edit, expect in (
            (
                "sheared-image-to-probe",
                chosen("image_to_probe_mm", 0, 1, 5.0),
                ["models.", ".image_to_probe_mm", "v column", "not a pixel spacing"],
            ),
            (
                "slightly-sheared-image-to-probe",
                chosen("image_to_probe_mm", 0, 1, 0.02),
                ["image_to_probe_mm", "off a right angle", "sheared"],
            ),
            (
                "image-to-probe-a-terametre-away",
                chosen("image_to_probe_mm", 0, 3, 1e12),
                ["image_to_probe_mm", "translation of 1e+12 mm", "beyond 5 m"],
            ),
            (
                "mirrored-image-to-probe",
                lambda raw: [row.__setitem__(2, -row[2]) for row in raw["models"][raw["model"]]["image_to_probe_mm"]],
                ["image_to_probe_mm", "left-handed"],
            ),
            (
                "phantom-a-terametre-away",
                set_in(1e12, "stepper", "T_Template_Phantom", 0, 3),
                ["stepper.T_Template_Phantom", "beyond 5 m"],
            ),
            (
                "sheared-phantom-registration",
                set_in(0.5, "stepper", "T_Template_Phantom", 0, 1),
                ["stepper.T_Template_Phantom", "not a rigid transform"],
            ),
            (
                "probe-axis-far-off-z",
                set_in([0.5, 0.0, 1.0], "stepper", "axes", "probe_translation"),
                ["stepper.axes.probe_translation", "Tx Ty 1"],
            ),
            (
                "encoder-scale-in-degrees-per-radian",
                set_in(57.3, "stepper", "axes", "rotation_encoder_scale"),
                ["stepper.axes.rotation_encoder_scale", "0.5", "2"],
            ),
            (
                "spacing-in-metres",
                set_in([1.5e-4, 1.5e-4], "spacing_mm"),
                ["spacing_mm", "metres"],
            ),
        )
    ),
    Case(
        "image-stepper-file-of-another-format",
        [*IMAGE, "--stepper", "{tmp}/result.json"],
        ["result.json", "format", "brachycal-stepper/1"],
        files(),
    ),
    Case(
        "image-stepper-axes-with-recorded-poses",
        [*IMAGE, "--stepper", "{tmp}/result.json", "--recorded-poses"],
        ["--recorded-poses", "--stepper"],
        files(),
    ),
    Case(
        "image-device-set-without-stepper-calibration",
        IMAGE,
        ["config.xml", "no StepperCalibration", "--stepper", "--recorded-poses"],
        files(result=False),
    ),
    Case(
        "image-tracker-device-set",
        IMAGE,
        ["config.xml", "not a stepper device set", "brachycal nwire"],
        files(device_set(stepper=False), result=False),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_stepper_probe_refusals(case, tmp_path):
    check_refusal(case, tmp_path)


def test_nwire_points_a_stepper_device_set_to_stepper_image(tmp_path):
    """`brachycal nwire` on PLUS's iCal device set (no Phantom→StepperHome: PLUS registers it at run time)."""
    config = reference("plus_trus_stepper", "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml")
    frames_file = reference("plus_trus_stepper", "UsTemplateCalibration_3NWires.results.xml")
    case = Case(
        "nwire-on-ical",
        ["nwire", str(config), str(frames_file), "--out", "{tmp}/nwire.json"],
        ["no phantom registration", "StepperHome", "brachycal stepper image"],
    )
    check_refusal(case, tmp_path)
