"""Hostile input to ``brachycal stepper calibrate``: recordings without the stepper's encoder fields,
axes that do not move, a rotation under 10°, a translation under 5 mm, an axis that moves in
another's recording (each refused in one line naming the file and the encoder field), frames
where no N is found, a phantom of one N; exit code 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal

from brachycal.data.formats.metaimage import write_image_sequence

WIRES = """
<Pattern Type="NWire">
  <Wire Name="Wire1" EndPointFront="49.86 54.385 62.05" EndPointBack="49.86 54.385 142.05" />
  <Wire Name="Wire2" EndPointFront="39.86 54.385 62.05" EndPointBack="19.86 54.385 142.05" />
  <Wire Name="Wire3" EndPointFront="9.86 54.385 62.05" EndPointBack="9.86 54.385 142.05" />
</Pattern>
<Pattern Type="NWire">
  <Wire Name="Wire4" EndPointFront="49.86 34.385 62.05" EndPointBack="49.86 34.385 142.05" />
  <Wire Name="Wire5" EndPointFront="19.86 34.385 62.05" EndPointBack="39.86 34.385 142.05" />
  <Wire Name="Wire6" EndPointFront="9.86 34.385 62.05" EndPointBack="9.86 34.385 142.05" />
</Pattern>"""
CONFIG = (
    '<PlusConfiguration><Segmentation ApproximateSpacingMmPerPixel="0.145" />'
    f"<PhantomDefinition><Geometry>{WIRES}</Geometry></PhantomDefinition></PlusConfiguration>"
)
FRAMES = 12


def encoders(probe=(-44.65, -44.65), rotation=(-1.16, -1.16), template=(0.0, 0.0)) -> list[dict[str, str]]:
    """Frames' encoder fields, each encoder swept linearly from its first value to its second."""
    sweep = [np.linspace(a, b, FRAMES) for a, b in (probe, rotation, template)]
    return [
        {"ProbePosition": f"{p:g}", "ProbeRotation": f"{r:g}", "TemplatePosition": f"{t:g}"}
        for p, r, t in zip(*sweep, strict=True)
    ]


GOOD = {
    "rot.mha": encoders(rotation=(-30.0, 30.0)),
    "pt.mha": encoders(probe=(-90.0, -15.0)),
    "tt.mha": encoders(template=(0.0, 30.0)),
}


def recordings(config: str = CONFIG, **changed: list[dict[str, str]]):
    """Write ``config.xml`` and the three recordings (blank 8-bit frames): the good ones but ``changed``
    (keyword: the file's stem, ``rot``, ``pt`` or ``tt``)."""

    def setup(tmp: Path) -> None:
        (tmp / "config.xml").write_text(config)
        for name, fields in GOOD.items():
            fields = changed.get(name.removesuffix(".mha"), fields)
            write_image_sequence(tmp / name, np.zeros((FRAMES, 48, 64), np.uint8), frame_fields=fields)

    return setup


def with_poses(fields: list[dict[str, str]], **units: float) -> list[dict[str, str]]:
    """``fields`` with PLUS's stepper poses (mm) added from the encoder values, then the encoder
    fields named in ``units`` rewritten in another unit (keyword: the field, value: the new unit's
    size in the field's, e.g. ``ProbePosition=10.0`` for centimetres)."""
    out = []
    for frame in fields:
        d, theta, t = (float(frame[name]) for name in ("ProbePosition", "ProbeRotation", "TemplatePosition"))
        c, s = np.cos(np.radians(theta)), np.sin(np.radians(theta))
        probe = [c, -s, 0, 0, s, c, 0, 0, 0, 0, 1, d, 0, 0, 0, 1]
        template = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, t, 0, 0, 0, 1]
        poses = {
            "ProbeToStepperHomeTransform": " ".join(f"{v:.6g}" for v in probe),
            "ProbeToStepperHomeTransformStatus": "OK",
            "TemplateToStepperHomeTransform": " ".join(f"{v:.6g}" for v in template),
            "TemplateToStepperHomeTransformStatus": "OK",
        }
        changed = {name: f"{float(frame[name]) / size:.6g}" for name, size in units.items()}
        out.append({**frame, **poses, **changed})
    return out


def without(field: str, fields: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in frame.items() if k != field} for frame in fields]


STEPPER = ["stepper", "calibrate", "{tmp}/rot.mha", "{tmp}/pt.mha", "{tmp}/tt.mha", "--config", "{tmp}/config.xml"]
OUT = ["--out", "{tmp}/stepper.json"]

CASES = [
    Case(
        "rotation-without-encoder-field",
        [*STEPPER, *OUT],
        ("rot.mha", "frame 0", "ProbeRotation", "missing"),
        recordings(rot=without("ProbeRotation", GOOD["rot.mha"])),
    ),
    Case(
        "template-translation-without-encoder-fields",
        [*STEPPER, *OUT],
        ("tt.mha", "ProbePosition", "missing"),
        recordings(tt=[{} for _ in range(FRAMES)]),
    ),
    Case(
        "rotation-under-10-degrees",
        [*STEPPER, *OUT],
        ("rot.mha", "ProbeRotation", "covers only 8°", "10°"),
        recordings(rot=encoders(rotation=(0.0, 8.0))),
    ),
    Case(
        "rotation-does-not-move",
        [*STEPPER, *OUT],
        ("rot.mha", "ProbeRotation", "does not move"),
        recordings(rot=encoders()),
    ),
    Case(
        "probe-translation-does-not-move",
        [*STEPPER, *OUT],
        ("pt.mha", "ProbePosition", "does not move"),
        recordings(pt=encoders()),
    ),
    Case(
        "template-translation-too-short",
        [*STEPPER, *OUT],
        ("tt.mha", "TemplatePosition", "covers only 2 mm", "5 mm"),
        recordings(tt=encoders(template=(0.0, 2.0))),
    ),
    Case(
        "probe-turns-during-its-translation",
        [*STEPPER, *OUT],
        ("pt.mha", "ProbeRotation", "only one axis"),
        recordings(pt=encoders(probe=(-90.0, -15.0), rotation=(0.0, 20.0))),
    ),
    Case(
        "encoder-value-not-a-number",
        [*STEPPER, *OUT],
        ("pt.mha", "TemplatePosition", "not a finite number"),
        recordings(pt=[{**frame, "TemplatePosition": "nan"} for frame in GOOD["pt.mha"]]),
    ),
    # An encoder in another unit than its field's, found from the poses the frames also carry (mm, degrees).
    Case(
        "probe-encoder-in-cm",
        [*STEPPER, *OUT],
        ("pt.mha", "ProbePosition", "ratio 10", "looks like cm (mm expected)"),
        recordings(pt=with_poses(GOOD["pt.mha"], ProbePosition=10.0)),
    ),
    Case(
        "template-encoder-in-metres",
        [*STEPPER, *OUT],
        ("tt.mha", "TemplatePosition", "looks like m (mm expected)"),
        recordings(tt=with_poses(GOOD["tt.mha"], TemplatePosition=1000.0)),
    ),
    Case(
        "rotation-encoder-in-radians",
        [*STEPPER, *OUT],
        ("rot.mha", "ProbeRotation", "looks like radians (degrees expected)"),
        recordings(rot=with_poses(GOOD["rot.mha"], ProbeRotation=float(np.degrees(1.0)))),
    ),
    Case(
        "probe-encoder-in-no-known-unit",
        [*STEPPER, *OUT],
        ("pt.mha", "ProbePosition", "ratio 3", "not in mm"),
        recordings(pt=with_poses(GOOD["pt.mha"], ProbePosition=3.0)),
    ),
    Case(
        # the same recordings with poses in the fields' units: only their blank frames are refused
        "encoders-and-poses-agree",
        [*STEPPER, *OUT, "--quiet"],
        ("rot.mha", "only 0 of 12 frames segmented"),
        recordings(**{name.removesuffix(".mha"): with_poses(fields) for name, fields in GOOD.items()}),
    ),
    Case(
        "no-frame-segmented",  # blank frames: no N found
        [*STEPPER, *OUT, "--quiet"],
        ("rot.mha", "only 0 of 12 frames segmented", "at least 30"),
        recordings(),
    ),
    Case(
        "phantom-with-one-n",
        [*STEPPER, *OUT],
        ("config.xml", "PhantomDefinition", "two N patterns"),
        recordings(config=CONFIG.replace(WIRES[WIRES.index("<Pattern", 10) :], "")),
    ),
    Case("out-is-an-input", [*STEPPER, "--out", "{tmp}/rot.mha", "--force"], ("rot.mha",), recordings()),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_stepper_calibrate_refuses(case: Case, tmp_path: Path) -> None:
    check_refusal(case, tmp_path)
