"""A TRUS probe on a brachytherapy stepper with its needle template, simulated: PLUS's iCal files with a known truth.

The set-up of PLUS's iCal (``docs/stepper.md``): the probe on a stepper whose encoders read its
translation and rotation, a needle-guide template in front, the iCal 1.1 N-wire phantom (three Ns,
wires along the stepper's z) on the template holder. The truth:

- Image → Probe (:data:`T_PROBE_IMAGE`, pixel spacing :data:`SPACING_M`): the image's u along the
  probe's x, v along −y (depth), its plane a little off the probe's cross-section;
- the phantom's registration ``T_template_phantom`` (:data:`T_TEMPLATE_PHANTOM`: the probe's rotation
  axis 29.7 mm and 79.1 mm from the phantom's origin, as on PLUS's iCal);
- the stepper's axes (:data:`AXES`): the probe travels along PLUS's ``(Tx, Ty, 1)`` of the iCal
  device set, the template along its own; the recorded poses, as PLUS records them, move along z;
- the template's holes (a 7 × 7 grid at 5 mm, ``A7`` … ``G1`` as PLUS's iCal template names them,
  placed on the phantom by ``TemplateHolder`` definitions).

Each frame's wire points are the exact crossings of the wires with the image plane plus Gaussian
segmentation noise (:data:`NOISE_PX` per axis), rendered as Gaussian dots on a dark, noiseless
background (small compressed files) and segmented by the real segmentation. :func:`write_stepper_files`
writes the three single-axis recordings (probe rotation, probe translation, template translation),
the random-motion calibration and validation recordings (PLUS ``.igs.mha`` with the stepper's
per-frame fields: ``ProbePosition`` mm, ``ProbeRotation`` degrees, ``TemplatePosition`` mm,
``ProbeToStepperHomeTransform``, ``TemplateToStepperHomeTransform``,
``StepperEncoderValuesToStepperHomeTransform`` with their statuses), the device set and ``truth.json``.
Metres and radians inside; millimetres and degrees in the files, as PLUS writes them.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brachycal.calibration.phantom.stepper_probe import stepper_pose
from brachycal.data.formats.metaimage import write_image_sequence
from brachycal.data.formats.plus_files import SegmentedFrame, Wire
from brachycal.data.formats.plus_stepper import StepperAxes
from brachycal.io import json_text
from brachycal.se3 import FloatArray, from_xyz_rpy, inverse, transform_points
from brachycal.studies.plus_device_set import (
    add_phantom_definition,
    add_probe_calibration_algo,
    numbers_text,
    write_xml,
)

__all__ = [
    "AXES",
    "ICAL_WIRES_MM",
    "NOISE_PX",
    "SIZE_PX",
    "SPACING_M",
    "STEPPER_NAMES",
    "STEPPER_TWIN",
    "T_PROBE_IMAGE",
    "T_TEMPLATE_PHANTOM",
    "StepperFrame",
    "StepperSetup",
    "centre_of_rotation_px",
    "expected_axis_orientation",
    "image_to_probe",
    "render_dots",
    "simulate_recordings",
    "template_holes_mm",
    "wire_points",
    "write_stepper_files",
]

MM = 1e-3
#: PLUS's iCal 1.1 phantom (its device set's ``PhantomDefinition``), millimetres: (front, back) per wire.
ICAL_WIRES_MM = {
    "Wire1": ((49.86, 54.385, 62.05), (49.86, 54.385, 142.05)),
    "Wire2": ((39.86, 54.385, 62.05), (19.86, 54.385, 142.05)),
    "Wire3": ((9.86, 54.385, 62.05), (9.86, 54.385, 142.05)),
    "Wire4": ((49.86, 34.385, 62.05), (49.86, 34.385, 142.05)),
    "Wire5": ((19.86, 34.385, 62.05), (39.86, 34.385, 142.05)),
    "Wire6": ((9.86, 34.385, 62.05), (9.86, 34.385, 142.05)),
    "Wire7": ((39.86, 14.385, 62.05), (39.86, 14.385, 142.05)),
    "Wire8": ((29.86, 14.385, 62.05), (19.86, 14.385, 142.05)),
    "Wire9": ((9.86, 14.385, 62.05), (9.86, 14.385, 142.05)),
}
#: The image: width and height (px), spacing along u and v (m/px, anisotropic as a scanner's), and
#: the pixel where the probe's rotation axis crosses it (near the transducer, at the top).
SIZE_PX = (296, 284)
SPACING_M = np.array([0.300e-3, 0.290e-3])
_AXIS_PX = (150.0, 15.0)
#: Image → Probe (metres): u along the probe's x, v along −y, the plane 160 mm along the probe's z
#: and turned a few milliradians off its cross-section; the axis crosses it near :data:`_AXIS_PX`.
T_PROBE_IMAGE = from_xyz_rpy((0.0, 0.0, 0.160), (np.pi + 0.006, 0.004, 0.010))
T_PROBE_IMAGE[:3, 3] -= T_PROBE_IMAGE[:3, :2] @ (np.array(_AXIS_PX) * SPACING_M)
#: The phantom in the stepper's frame with the template at home (PLUS's Phantom → StepperHome).
T_TEMPLATE_PHANTOM = np.eye(4)
T_TEMPLATE_PHANTOM[:2, 3] = [-29.7e-3, -79.1e-3]
#: The stepper's axes (PLUS's iCal device set's StepperCalibration): the probe and the template travel
#: along them; the rotation encoder reads the turn exactly.
AXES = StepperAxes(np.array([0.004635, -0.05344, 1.0]), np.array([-0.003557, 0.031474, 1.0]), 1.0, "the twin")
#: Segmentation noise added to each wire point before it is rendered, px (SD per axis).
NOISE_PX = 0.3
#: Width of a rendered wire echo (Gaussian σ, px) and its height above the background (grey levels).
_ECHO_SIGMA_PX, _ECHO_PEAK, _BACKGROUND = 1.3, 200.0, 20.0
#: The template: columns A a B b C c D (5 mm apart), rows 7 6.5 6 5.5 5 4.5 4 (5 mm apart), its
#: holes in the template frame (TemplateHome), millimetres; TemplateHolder → TemplateHome and
#: TemplateHolder → Phantom as PLUS's iCal device set has them (the template frame is the phantom's).
_COLUMNS, _ROWS = "AaBbCcD", ("7", "6.5", "6", "5.5", "5", "4.5", "4")
_HOLDER_MM = (5.0, 63.5)
#: File names in ``examples/stepper`` (device set, recordings, truth).
STEPPER_NAMES = {
    "config": "stepper/PlusDeviceSet_twin_iCal.xml",
    "rotation": "stepper/twin_ProbeRotation.igs.mha",
    "probe_translation": "stepper/twin_ProbeTranslation.igs.mha",
    "template_translation": "stepper/twin_TemplateTranslation.igs.mha",
    "calibration": "stepper/twin_RandomStepperMotionCalibration.igs.mha",
    "validation": "stepper/twin_RandomStepperMotionValidation.igs.mha",
    "truth": "stepper/truth.json",
}
#: Seeds' tag (the stepper's streams never coincide with the other examples').
_TAG = 0x5354


def wires() -> list[Wire]:
    """The iCal 1.1 wires, metres, phantom frame."""
    return [Wire(name, np.array(f) * MM, np.array(b) * MM) for name, (f, b) in ICAL_WIRES_MM.items()]


def image_to_probe() -> FloatArray:
    """The true Image → Probe in PLUS's form ``(4, 4)``: pixels → metres, the third column the
    image normal times the mean pixel size."""
    M = T_PROBE_IMAGE.copy()
    M[:3, :3] = T_PROBE_IMAGE[:3, :3] * np.array([*SPACING_M, SPACING_M.mean()])
    return M


def template_holes_mm() -> dict[str, tuple[float, float, float]]:
    """Hole ID → its centre in the template frame, millimetres (PLUS's naming: column letter, row number)."""
    return {f"{c}{r}": (5.0 * i, 5.0 * j, 0.0) for j, r in enumerate(_ROWS) for i, c in enumerate(_COLUMNS)}


@dataclass(frozen=True)
class StepperSetup:
    """A probe on a stepper over an N-wire phantom on the template holder, as the truth of simulated frames.

    Attributes:
        image_to_probe: ``(4, 4)`` Image → Probe, PLUS's form (pixels → metres, the third column the
            image normal times the mean pixel size).
        T_template_phantom: ``(4, 4)`` the phantom in the stepper's frame with the template at home, metres.
        axes: the stepper's axes: the probe and the template truly travel along them.
        wires: the phantom's wires, metres, phantom frame.
    """

    image_to_probe: FloatArray
    T_template_phantom: FloatArray
    axes: StepperAxes
    wires: Sequence[Wire]

    def probe_pose(self, probe_m: float, rotation_rad: float) -> FloatArray:
        """``T_SH_probe``: where the probe truly is at encoder readings (along the calibrated axis)."""
        return stepper_pose(probe_m, rotation_rad, self.axes.probe_translation, self.axes.rotation_encoder_scale)

    def template_pose(self, template_m: float) -> FloatArray:
        """``T_SH_template``: where the template truly is at its encoder reading."""
        return stepper_pose(template_m, 0.0, self.axes.template_translation)

    def points(self, probe_m: float, rotation_rad: float, template_m: float = 0.0) -> dict[str, FloatArray]:
        """Each wire's exact crossing of the image plane at encoder readings, ``(u, v)`` px."""
        T_probe_phantom = inverse(self.probe_pose(probe_m, rotation_rad)) @ self.template_pose(template_m)
        T_image_phantom = np.linalg.inv(self.image_to_probe) @ T_probe_phantom @ self.T_template_phantom
        out = {}
        for wire in self.wires:
            a, b = transform_points(T_image_phantom, np.stack([wire.front_m, wire.back_m]))
            out[wire.name] = (a + (-a[2] / (b[2] - a[2])) * (b - a))[:2]
        return out

    def noisy_points(
        self,
        probe_m: float,
        rotation_rad: float,
        template_m: float = 0.0,
        *,
        rng: np.random.Generator,
        noise_px: float,
    ) -> dict[str, FloatArray]:
        """:meth:`points` plus Gaussian segmentation noise of SD ``noise_px`` per axis (two draws a wire,
        in the wires' order, whatever ``noise_px``)."""
        exact = self.points(probe_m, rotation_rad, template_m)
        return {k: uv + rng.normal(0.0, noise_px, 2) for k, uv in exact.items()}

    def segmented_frame(
        self,
        index: int,
        probe_m: float,
        rotation_rad: float,
        template_m: float = 0.0,
        *,
        rng: np.random.Generator,
        noise_px: float = NOISE_PX,
        label: str = "frame",
    ) -> SegmentedFrame:
        """One segmented frame as ``brachycal stepper image`` reads it: the noisy wire points and the
        poses as PLUS records them (the probe along the stepper's z, turned about it; the template along z)."""
        return SegmentedFrame(
            index,
            True,
            self.noisy_points(probe_m, rotation_rad, template_m, rng=rng, noise_px=noise_px),
            stepper_pose(probe_m, rotation_rad),
            stepper_pose(template_m, 0.0),
            source="simulated",
            label=label,
            pose_names=("ProbeToStepperHomeTransform", "TemplateToStepperHomeTransform"),
        )


#: The twin's set-up (the truth of ``examples/stepper``).
STEPPER_TWIN = StepperSetup(image_to_probe(), T_TEMPLATE_PHANTOM, AXES, wires())


def wire_points(probe_m: float, rotation_rad: float, template_m: float) -> dict[str, FloatArray]:
    """Each wire's exact crossing of the twin's image plane at encoder readings, ``(u, v)`` px."""
    return STEPPER_TWIN.points(probe_m, rotation_rad, template_m)


def centre_of_rotation_px() -> FloatArray:
    """``(2,)`` where the probe's rotation axis (its z through its origin) crosses the image, px."""
    R, t = T_PROBE_IMAGE[:3, :3], T_PROBE_IMAGE[:3, 3]
    # R @ (x, y, 0) + t = (0, 0, z): solve for x, y, z.
    x, y, _ = np.linalg.solve(np.column_stack([R[:, 0], R[:, 1], [0.0, 0.0, -1.0]]), -t)
    return np.array([x, y]) / SPACING_M


def expected_axis_orientation(which: str) -> FloatArray:
    """PLUS's ``(−slope_x, slope_y, 1)`` that ``stepper calibrate`` measures for the ``"probe"`` or
    ``"template"`` translation axis: the still wires' dots' motion in the image (``x = u·s_u``,
    ``y = v·s_v``) per metre of the encoder, from the plane's geometry (not from a fit)."""
    R = T_PROBE_IMAGE[:3, :3]
    e_u, e_v, n = R[:, 0], R[:, 1], R[:, 2]
    w = np.array([0.0, 0.0, 1.0])  # the phantom's wires, in the probe frame at rotation 0
    axis = AXES.probe_translation if which == "probe" else AXES.template_translation
    sign = -1.0 if which == "probe" else 1.0  # the probe moves the plane; the template moves the wires
    # A wire moved by δ relative to the plane: its dot moves by δ − w (n·δ)/(n·w) in the plane.
    motion = sign * (axis - w * (n @ axis) / (n @ w))
    slope = np.array([e_u @ motion, e_v @ motion])
    return np.array([-slope[0], slope[1], 1.0])


@dataclass(frozen=True)
class StepperFrame:
    """One frame of a stepper recording: encoder readings and the wire points rendered (with noise).

    Attributes:
        probe_m, rotation_rad, template_m: the encoders' readings (metres, radians).
        points_px: wire name → ``(u, v)`` px, the exact crossing plus segmentation noise.
    """

    probe_m: float
    rotation_rad: float
    template_m: float
    points_px: dict[str, FloatArray]


def simulate_recordings(seed: int = 0, *, noise_px: float = NOISE_PX) -> dict[str, list[StepperFrame]]:
    """The five recordings' frames: ``rotation`` (36 frames, ±12° at −45 mm), ``probe_translation``
    (10 frames, −80 … −30 mm), ``template_translation`` (10 frames, −15 … +15 mm, probe at −45 mm),
    ``calibration`` (40) and ``validation`` (20) frames of random stepper motion (probe −85 … −30 mm,
    ±3°, template at home)."""
    rng = np.random.default_rng([seed, _TAG])
    readings: dict[str, list[tuple[float, float, float]]] = {
        "rotation": [(-0.045, a, 0.0) for a in np.radians(np.linspace(-12.0, 12.0, 36))],
        "probe_translation": [(d, 0.0, 0.0) for d in np.linspace(-0.080, -0.030, 10)],
        "template_translation": [(-0.045, 0.0, t) for t in np.linspace(-0.015, 0.015, 10)],
    }
    for name, count in (("calibration", 40), ("validation", 20)):
        travel = rng.uniform(-0.085, -0.030, count)
        turn = np.radians(rng.uniform(-3.0, 3.0, count))
        readings[name] = [(d, a, 0.0) for d, a in zip(travel.tolist(), turn.tolist(), strict=True)]
    out = {}
    for name, values in readings.items():
        frames = []
        for d, a, t in values:
            # PLUS writes the encoders with 4 decimals (mm, degrees): the readings are those values.
            d, t = round(d / MM, 4) * MM, round(t / MM, 4) * MM
            a = np.radians(round(float(np.degrees(a)), 4))
            noisy = STEPPER_TWIN.noisy_points(d, a, t, rng=rng, noise_px=noise_px)
            frames.append(StepperFrame(d, a, t, noisy))
        out[name] = frames
    return out


def render_dots(points_px: Sequence[FloatArray]) -> np.ndarray:
    """A B-mode-like uint8 frame of :data:`SIZE_PX`: a dark noiseless background and a Gaussian dot
    (σ :data:`_ECHO_SIGMA_PX`) at each ``(u, v)`` px, so that it compresses to ~1 kB."""
    width, height = SIZE_PX
    image = np.full((height, width), _BACKGROUND)
    reach = int(np.ceil(6 * _ECHO_SIGMA_PX))
    for pu, pv in points_px:
        v0, u0 = max(int(pv) - reach, 0), max(int(pu) - reach, 0)
        v1, u1 = min(int(pv) + reach + 1, height), min(int(pu) + reach + 1, width)
        v, u = np.mgrid[v0:v1, u0:u1]
        image[v, u] += _ECHO_PEAK * np.exp(-((u - pu) ** 2 + (v - pv) ** 2) / (2 * _ECHO_SIGMA_PX**2))
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _pose_text(T_m: FloatArray) -> str:
    """A pose as PLUS writes it: row-major ``(4, 4)``, millimetres, 6 significant digits."""
    T = np.array(T_m, dtype=float)
    T[:3, 3] /= MM
    return " ".join(f"{v:.6g}" for v in T.ravel() + 0.0)  # + 0.0: no "-0"


def _write_recording(path: str | os.PathLike[str], frames: Sequence[StepperFrame]) -> None:
    """A PLUS stepper recording: the rendered frames with each frame's encoder values and poses as PLUS
    records them (the probe along z, the template along z: the device's uncompensated poses)."""
    pixels = np.stack([render_dots(list(f.points_px.values())) for f in frames])
    fields = []
    for f in frames:
        d_mm, a_deg, t_mm = f.probe_m / MM, float(np.degrees(f.rotation_rad)), f.template_m / MM
        encoders = np.eye(4)
        encoders[:3, 3] = [d_mm, a_deg, t_mm]
        fields.append(
            {
                "ProbePosition": f"{d_mm:.4f}",
                "ProbeRotation": f"{a_deg:.4f}",
                "ProbeToStepperHomeTransform": _pose_text(stepper_pose(f.probe_m, f.rotation_rad)),
                "ProbeToStepperHomeTransformStatus": "OK",
                "StepperEncoderValuesToStepperHomeTransform": " ".join(f"{v:.6g}" for v in encoders.ravel() + 0.0),
                "StepperEncoderValuesToStepperHomeTransformStatus": "OK",
                "TemplatePosition": f"{t_mm:.4f}",
                "TemplateToStepperHomeTransform": _pose_text(stepper_pose(f.template_m, 0.0)),
                "TemplateToStepperHomeTransformStatus": "OK",
            }
        )
    write_image_sequence(path, pixels, timestamps_s=0.2 * np.arange(len(frames)), frame_fields=fields)


def write_device_set(path: str | os.PathLike[str]) -> None:
    """The twin's PLUS device set, as PLUS's iCal one: the BrachyTracker device with its
    ``StepperCalibration`` axes, ``Segmentation`` for the twin's frames, the ``TemplateHolder``
    definitions, the ``iCal`` element (frame names), the stepper's phantom registration and probe
    calibration elements (reference ``StepperHome``), the ``PhantomDefinition`` and a ``TemplateModel``."""
    root = ET.Element("PlusConfiguration", version="2.3")
    collection = ET.SubElement(root, "DataCollection", StartupDelaySec="1.0")
    ET.SubElement(
        collection,
        "DeviceSet",
        Name="brachycal twin: TRUS probe on a brachytherapy stepper, iCal 1.1 phantom (3 N-wires)",
        Description="Simulated by brachycal's stepper twin (brachycal.studies.stepper_twin): a known truth",
    )
    device = ET.SubElement(collection, "Device", Id="TrackerDevice", Type="BrachyTracker")
    ET.SubElement(
        device,
        "StepperCalibration",
        ProbeTranslationAxisOrientation=numbers_text(AXES.probe_translation),
        TemplateTranslationAxisOrientation=numbers_text(AXES.template_translation),
        ProbeRotationEncoderScale=repr(AXES.rotation_encoder_scale),
    )
    outputs = ET.SubElement(device, "OutputChannels")
    ET.SubElement(outputs, "OutputChannel", Id="TrackerOutput")
    width, height = SIZE_PX
    ET.SubElement(
        root,
        "Segmentation",
        ApproximateSpacingMmPerPixel=repr(round(float(SPACING_M.mean() / MM), 4)),
        MorphologicalOpeningCircleRadiusMm="0.27",
        MorphologicalOpeningBarSizeMm="2.0",
        ClipRectangleOrigin="4 4",
        ClipRectangleSize=f"{width - 8} {height - 8}",
        MaxLinePairDistanceErrorPercent="10",
        MinThetaDegrees="-70",
        MaxThetaDegrees="70",
        MaxLineShiftMm="10.0",
        AngleToleranceDegrees="10",
        ThresholdImagePercent="10",
        CollinearPointsMaxDistanceFromLineMm="0.8",
        NumberOfMaximumFiducialPointCandidates="20",
    )
    definitions = ET.SubElement(root, "CoordinateDefinitions")
    holder = np.eye(4)
    holder[:2, 3] = _HOLDER_MM
    for target in ("TemplateHome", "Phantom"):
        ET.SubElement(definitions, "Transform", From="TemplateHolder", To=target, Matrix=numbers_text(holder))
    ET.SubElement(
        root,
        "iCal",
        version="1.0",
        ImageCoordinateFrame="Image",
        ProbeCoordinateFrame="Probe",
        TemplateHomeCoordinateFrame="TemplateHome",
        TemplateCoordinateFrame="Template",
        TemplateHolderCoordinateFrame="TemplateHolder",
        BrachyTrackerId="TrackerDevice",
    )
    ET.SubElement(
        root,
        "vtkPlusBrachyStepperPhantomRegistrationAlgo",
        PhantomCoordinateFrame="Phantom",
        ReferenceCoordinateFrame="StepperHome",
    )
    add_probe_calibration_algo(root, "StepperHome")
    wires_mm = [(name, front, back) for name, (front, back) in ICAL_WIRES_MM.items()]
    patterns_mm = [wires_mm[k : k + 3] for k in range(0, len(wires_mm), 3)]
    add_phantom_definition(root, patterns_mm, name="iCAL", version="1.0", wiring_version="1.1")
    template = ET.SubElement(root, "TemplateModel", version="1.0")
    ET.SubElement(template, "OriginFromTemplateHolder", OriginX=repr(_HOLDER_MM[0]), OriginY=repr(_HOLDER_MM[1]))
    holes = ET.SubElement(template, "HolePositions")
    for hole, position in template_holes_mm().items():
        ET.SubElement(holes, "Hole", ID=hole, PositionXYZ=numbers_text(position))
    write_xml(path, root)


def truth(seed: int, noise_px: float = NOISE_PX) -> dict[str, object]:
    """The twin's truth (``truth.json``): metres, radians and pixels unless a key says mm."""
    return {
        "what": "truth of the stepper example (brachycal.studies.stepper_twin)",
        "seed": seed,
        "noise_px": noise_px,
        "size_px": list(SIZE_PX),
        "spacing_mm": (SPACING_M / MM).tolist(),
        "centre_of_rotation_px": centre_of_rotation_px().tolist(),
        "image_to_probe": image_to_probe().tolist(),
        "T_probe_image": T_PROBE_IMAGE.tolist(),
        "T_template_phantom": T_TEMPLATE_PHANTOM.tolist(),
        "probe_translation_axis": AXES.probe_translation.tolist(),
        "template_translation_axis": AXES.template_translation.tolist(),
        "rotation_encoder_scale": AXES.rotation_encoder_scale,
        "probe_axis_plus_orientation_in_image": expected_axis_orientation("probe").tolist(),
        "template_axis_plus_orientation_in_image": expected_axis_orientation("template").tolist(),
        "template_holes_mm": template_holes_mm(),
        "T_phantom_template": np.eye(4).tolist(),
    }


def write_stepper_files(staged: dict[str, Path], seed: int = 0, *, noise_px: float = NOISE_PX) -> None:
    """Write the stepper example's files to the staged paths of :data:`STEPPER_NAMES` (keys as there;
    straight to them: callers that need all-or-nothing outputs pass staged paths)."""
    recordings = simulate_recordings(seed, noise_px=noise_px)
    write_device_set(staged["config"])
    for name, frames in recordings.items():
        _write_recording(staged[name], frames)
    staged["truth"].write_text(json_text(truth(seed, noise_px)))
