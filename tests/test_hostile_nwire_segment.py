"""Hostile input to ``brachycal nwire segment`` (and ``brachycal nwire`` given sequences): each is refused
in one line naming the file and the field or option, exit code 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal

from brachycal.data.formats.metaimage import write_image_sequence

IDENTITY = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"
WIRES = """
<Pattern Type="NWire">
  <Wire Name="7:G1_g1" EndPointFront="30 0 20" EndPointBack="30 40 20" />
  <Wire Name="8:L1_h1" EndPointFront="55 0 20" EndPointBack="35 40 20" />
  <Wire Name="9:M1_m1" EndPointFront="60 0 20" EndPointBack="60 40 20" />
</Pattern>"""


def config_text(segmentation: str = '<Segmentation ApproximateSpacingMmPerPixel="0.078" />', wires: str = WIRES) -> str:
    return (
        "<PlusConfiguration><CoordinateDefinitions>"
        f'<Transform From="Phantom" To="Reference" Matrix="{IDENTITY}" /></CoordinateDefinitions>'
        f"{segmentation}<PhantomDefinition><Geometry>{wires}</Geometry></PhantomDefinition></PlusConfiguration>"
    )


def files(*, config: str | None = None, frames=None, fields=None, raw: str | None = None):
    """Write ``{tmp}/config.xml`` and ``{tmp}/cal.mha`` (and ``val.mha``): good ones unless told otherwise."""

    def setup(tmp: Path) -> None:
        (tmp / "config.xml").write_text(config if config is not None else config_text())
        pixels = np.zeros((2, 64, 80), np.uint8) if frames is None else frames
        tracked = [{"ProbeToTrackerTransform": IDENTITY, "ReferenceToTrackerTransform": IDENTITY}] * len(pixels)
        for name in ("cal.mha", "val.mha"):
            if raw is not None and name == "cal.mha":
                (tmp / name).write_bytes(raw.encode("latin-1"))
            else:
                write_image_sequence(tmp / name, pixels, frame_fields=tracked if fields is None else fields)

    return setup


#: A brachytherapy stepper's device set (PLUS's iCal layout): its poses are ProbeToStepperHome and
#: TemplateToStepperHome.
STEPPER = (
    '<DataCollection><Device Id="TrackerDevice" Type="BrachyTracker" /></DataCollection>'
    '<iCal ProbeCoordinateFrame="Probe" TemplateCoordinateFrame="Template" />'
    '<vtkPlusProbeCalibrationAlgo ProbeCoordinateFrame="Probe" ReferenceCoordinateFrame="StepperHome" />'
)
#: A stepper recording's frame: its encoders and the poses they give, mm.
STEPPER_FRAME = {
    "ProbePosition": "-44.65",
    "ProbeRotation": "-2.3",
    "TemplatePosition": "0",
    "ProbeToStepperHomeTransform": IDENTITY,
    "TemplateToStepperHomeTransform": IDENTITY,
}


def stepper_config(device: str = STEPPER) -> str:
    return config_text().replace("<PlusConfiguration>", f"<PlusConfiguration>{device}")


def without(*names: str) -> list[dict[str, str]]:
    """Two stepper frames without the fields ``names``."""
    return [{k: v for k, v in STEPPER_FRAME.items() if k not in names}] * 2


def colour_mha() -> str:
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nCompressedData = False\nDimSize = 4 4 1\n"
        "ElementNumberOfChannels = 3\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
    )
    return header + "\0" * (4 * 4 * 3)


def mha_with_orientation(orientation: str) -> str:
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nCompressedData = False\nDimSize = 4 4 1\n"
        f"ElementType = MET_UCHAR\nUltrasoundImageOrientation = {orientation}\n"
        f"Seq_Frame0000_ProbeToTrackerTransform = {IDENTITY}\nSeq_Frame0000_ReferenceToTrackerTransform = {IDENTITY}\n"
        "ElementDataFile = LOCAL\n"
    )
    return header + "\0" * 16


SEGMENT = ["nwire", "segment", "{tmp}/cal.mha", "{tmp}/val.mha", "--config", "{tmp}/config.xml", "--out", "{tmp}/f.xml"]
NWIRE = ["nwire", "{tmp}/config.xml", "--out", "{tmp}/n.json", "--quiet"]

CASES = [
    Case("not-metaimage", SEGMENT, ("cal.mha",), files(raw="hello, I am not an image\n")),
    Case("colour-frames", SEGMENT, ("cal.mha", "single-channel"), files(raw=colour_mha())),
    Case("16-bit-frames", SEGMENT, ("cal.mha", "8-bit"), files(frames=np.zeros((1, 64, 80), np.uint16))),
    Case(
        "orientation-unknown",
        SEGMENT,
        ("cal.mha", "UltrasoundImageOrientation", "MF"),
        files(raw=mha_with_orientation("XYZ")),
    ),
    Case("orientation-option-unknown", [*SEGMENT, "--orientation", "FM"], ("--orientation",), files()),
    Case(
        "orientation-option-on-a-sequence-stored-mn",  # its frames are turned to MF already
        [*SEGMENT, "--orientation", "UF"],
        ("cal.mha", "--orientation UF", "stored MN"),
        files(raw=mha_with_orientation("MND")),
    ),
    Case("sequence-missing", [*SEGMENT[:3], "{tmp}/nothing.mha", *SEGMENT[4:]], ("nothing.mha",), files()),
    Case("no-segmentation-element", SEGMENT, ("config.xml", "segmentation"), files(config=config_text(""))),
    Case("no-phantom", SEGMENT, ("config.xml", "n-wire"), files(config=config_text(wires=""))),
    Case(
        "threshold-over-100",
        SEGMENT,
        ("config.xml", "ThresholdImagePercent"),
        files(config=config_text('<Segmentation ThresholdImagePercent="150" />')),
    ),
    Case(
        "spacing-not-a-number",
        SEGMENT,
        ("config.xml", "ApproximateSpacingMmPerPixel"),
        files(config=config_text('<Segmentation ApproximateSpacingMmPerPixel="fast" />')),
    ),
    Case(
        "clip-origin-without-size",
        SEGMENT,
        ("config.xml", "ClipRectangleSize"),
        files(config=config_text('<Segmentation ClipRectangleOrigin="27 27" />')),
    ),
    Case(
        "clip-size-negative",
        SEGMENT,
        ("config.xml", "ClipRectangleSize"),
        files(config=config_text('<Segmentation ClipRectangleOrigin="0 0" ClipRectangleSize="-5 100" />')),
    ),
    Case(
        "theta-range-empty",
        SEGMENT,
        ("config.xml", "MaxThetaDegrees"),
        files(config=config_text('<Segmentation MinThetaDegrees="30" MaxThetaDegrees="-30" />')),
    ),
    Case(
        "candidates-zero",
        SEGMENT,
        ("config.xml", "NumberOfMaximumFiducialPointCandidates"),
        files(config=config_text('<Segmentation NumberOfMaximumFiducialPointCandidates="0" />')),
    ),
    Case(
        "settings-from-phantom",
        SEGMENT,
        ("config.xml", "not supported"),
        files(config=config_text('<Segmentation ComputeSegmentationParametersFromPhantomDefinition="1" />')),
    ),
    Case(
        "tracker-reading-not-16-numbers",
        SEGMENT,
        ("cal.mha", "frame 0", "ProbeToTrackerTransform"),
        files(fields=[{"ProbeToTrackerTransform": "1 2 3", "ReferenceToTrackerTransform": IDENTITY}] * 2),
    ),
    Case(
        "tracker-reading-scaled",
        SEGMENT,
        ("cal.mha", "ReferenceToTrackerTransform"),
        files(
            fields=[{"ProbeToTrackerTransform": IDENTITY, "ReferenceToTrackerTransform": IDENTITY.replace("1", "2", 1)}]
            * 2
        ),
    ),
    Case(
        "stepper-recording-without-poses",
        SEGMENT,
        ("cal.mha", "ProbeToStepperHomeTransform", "no frame has the probe pose"),
        files(config=stepper_config(), fields=without("ProbeToStepperHomeTransform", "TemplateToStepperHomeTransform")),
    ),
    Case(
        "stepper-recording-without-encoders-or-poses",
        SEGMENT,
        ("cal.mha", "ProbeToStepperHomeTransform", "transforms: none"),
        files(config=stepper_config(), fields=[{}, {}]),
    ),
    Case(
        "stepper-recording-without-template-pose",
        SEGMENT,
        ("cal.mha", "TemplateToStepperHomeTransform", "reference pose"),
        files(config=stepper_config(), fields=without("TemplateToStepperHomeTransform")),
    ),
    Case(
        "stepper-recording-with-a-tracker-device-set",
        SEGMENT,
        ("cal.mha", "ProbeToTrackerTransform", "ProbeToStepperHomeTransform"),
        files(fields=without()),
    ),
    Case(
        "stepper-device-set-without-template-frame",
        SEGMENT,
        ("config.xml", "iCal/@TemplateCoordinateFrame"),
        files(config=stepper_config(STEPPER.replace(' TemplateCoordinateFrame="Template"', "")), fields=without()),
    ),
    Case(
        "stepper-device-set-without-base-frame",
        SEGMENT,
        ("config.xml", "vtkPlusProbeCalibrationAlgo/@ReferenceCoordinateFrame"),
        files(config=stepper_config(STEPPER.replace(' ReferenceCoordinateFrame="StepperHome"', "")), fields=without()),
    ),
    Case(
        "named-stream-not-recorded",
        [*SEGMENT, "--probe-transform", "ProbeToStepperHome", "--reference-transform", "TemplateToStepperHome"],
        ("cal.mha", "ProbeToStepperHomeTransform", "ProbeToTrackerTransform"),
        files(),
    ),
    # A B-mode sequence without a tracker's transforms: the refusal names the way to segment it.
    Case(
        "tracker-recording-without-poses",
        SEGMENT,
        ("cal.mha", "ProbeToTrackerTransform", "transforms: none", "--images-only", "--probe-transform"),
        files(fields=[{}, {}]),
    ),
    Case("transform-name-malformed", [*SEGMENT, "--probe-transform", "probe pose"], ("--probe-transform",), files()),
    Case(
        "images-only-with-a-stream",
        [*SEGMENT, "--images-only", "--probe-transform", "ProbeToTracker"],
        ("--images-only",),
        files(),
    ),
    Case(
        "nwire-sequences-stream-not-recorded",
        [
            *NWIRE,
            "--calibration-sequence",
            "{tmp}/cal.mha",
            "--validation-sequence",
            "{tmp}/val.mha",
            "--probe-transform",
            "ProbeToStepperHome",
        ],
        ("cal.mha", "ProbeToStepperHomeTransform", "--reference-transform"),
        files(),
    ),
    Case("config-missing", [*SEGMENT[:5], "{tmp}/none.xml", *SEGMENT[6:]], ("none.xml",), files()),
    Case("no-config-option", SEGMENT[:4] + SEGMENT[6:], ("--config",), files()),
    Case(
        "nwire-frames-and-sequences",
        [*NWIRE[:2], "{tmp}/f.xml", *NWIRE[2:], "--calibration-sequence", "{tmp}/cal.mha"],
        ("not both",),
        files(),
    ),
    Case("nwire-one-sequence", [*NWIRE, "--calibration-sequence", "{tmp}/cal.mha"], ("both",), files()),
    Case(
        "nwire-bad-sequence",
        [*NWIRE, "--calibration-sequence", "{tmp}/cal.mha", "--validation-sequence", "{tmp}/val.mha"],
        ("cal.mha",),
        files(raw="not an image\n"),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_refused(case, tmp_path):
    check_refusal(case, tmp_path)


def test_an_existing_output_is_kept(tmp_path):
    def setup(tmp: Path) -> None:
        files()(tmp)
        (tmp / "f.xml").write_text("mine")

    check_refusal(Case("out-exists", SEGMENT, ("f.xml", "exists"), setup), tmp_path)
