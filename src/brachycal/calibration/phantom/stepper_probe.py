"""Image → Probe of a TRUS probe on a brachytherapy stepper (PLUS's iCal set-up), and the needle template in the image.

No tracker: the stepper's encoders give each frame's poses in ``StepperHome`` (``ProbeToStepperHome``,
``TemplateToStepperHome``), and the N-wire phantom rides on the template holder:

``p_probe = T_SH_probe⁻¹ · T_SH_template · T_template_phantom · p_phantom``

- :func:`register_phantom`: ``T_template_phantom`` as PLUS's ``vtkPlusBrachyStepperPhantomRegistrationAlgo``
  measures it from a probe-rotation recording (pixel spacing, centre of rotation, the rotation
  axis's distances to two lines of wires);
- :func:`corrected_frames`: each pose rebuilt from its encoder readings along the stepper's
  calibrated axes (PLUS's recordings move the probe along ``z`` exactly);
- :func:`calibrate_stepper_image_files`: the N-wire estimators of
  :mod:`~brachycal.calibration.phantom.nwire_file` with the stepper as the reference, on both pose models;
- :func:`hole_in_image`: a needle through a template hole, at a depth, in the image at a stepper pose.

Design and what random stepper motion determines: ``docs/stepper.md``, "Image to probe".
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.phantom.nwire_file import (
    FORMAT,
    NWireFile,
    NWireFileResult,
    calibrate_nwire_frames,
    check_model,
    read_nwire,
)
from brachycal.calibration.phantom.stepper import StepperFit, centre_of_rotation, pixel_spacing
from brachycal.calibration.phantom.stepper_file import FORMAT as STEPPER_FORMAT
from brachycal.calibration.phantom.stepper_file import (
    MIN_ROTATION_FRAMES,
    STEPPER_DOCUMENT,
    Progress,
    check_recording,
    read_stepper_recording,
)
from brachycal.data.formats.metaimage import read_image_sequence, read_sequence_header
from brachycal.data.formats.plus_files import (
    SegmentedFrame,
    Wire,
    read_plus_config,
    read_pose_streams,
    read_segmented_frames,
    stepper_encoder_values,
)
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.data.formats.plus_stepper import (
    STRAIGHT_AXES,
    StepperAxes,
    TemplateGrid,
    encoder_scale,
    read_stepper_axes,
    stepper_axis,
)
from brachycal.data.json_schema import (
    MAX_TRANSLATION_M,
    Obj,
    Where,
    array,
    integer,
    number,
    read_document,
    spacing,
    text,
    transform,
)
from brachycal.errors import DegenerateDataError, InputError
from brachycal.imaging.nwire_segmentation import segment_sequence
from brachycal.io import sha256_file, write_json
from brachycal.se3 import FloatArray, inverse, rotation, transform_points
from brachycal.validate import MAX_IMAGE_PX

MM = 1e-3
#: Largest lateral translation or tilt (metres, radians) a recorded encoder pose may carry: the
#: stepper's poses translate along ``z`` and turn about ``z`` only (PLUS writes 6 digits).
ENCODER_POSE_TOLERANCE = 1e-6


def _point_line_distance(o: FloatArray, a: FloatArray, b: FloatArray) -> float:
    """Distance from ``o`` to the line through ``a`` and ``b`` (points ``(2,)``), their unit."""
    ab, ao = b - a, o - a
    return float(abs(ab[0] * ao[1] - ab[1] * ao[0]) / np.linalg.norm(ab))


@dataclass(frozen=True)
class PhantomRegistration:
    """Where the phantom sits in the stepper's frame (the template at home).

    Attributes:
        T_template_phantom: ``(4, 4)`` the phantom frame in the template's (``StepperHome`` with
            the template at home), metres: PLUS's ``Phantom → StepperHome``.
        spacing: the pixel spacing fit ``(s_u, s_v)`` m/px
            (:func:`~brachycal.calibration.phantom.stepper.pixel_spacing`).
        centre: the centre-of-rotation fit ``(u, v)`` px.
        vertical_m, horizontal_m: the mean distances from the rotation axis to the two wire lines, metres.
        frames: rotation frames used.
    """

    T_template_phantom: FloatArray
    spacing: StepperFit
    centre: StepperFit
    vertical_m: float
    horizontal_m: float
    frames: int


def register_phantom(
    frames: Sequence[Mapping[str, ArrayLike]],
    patterns: Sequence[tuple[Wire, Wire, Wire]],
    axis_at_m: ArrayLike = (0.0, 0.0),
) -> PhantomRegistration:
    """PLUS's phantom registration on a stepper, from the segmented frames of a probe-rotation recording.

    Args:
        frames: per frame, wire name → ``(u, v)`` pixel (every wire of ``patterns``).
        patterns: the phantom's Ns (at least two).
        axis_at_m: ``(x, y)`` where the probe's rotation axis was in the stepper's frame during the
            recording, metres: ``(Tx, Ty) · d`` for a probe translated by ``d`` along a calibrated
            axis ``(Tx, Ty, 1)``; zero (PLUS's) when the poses move the probe along ``z``.

    Raises:
        DegenerateDataError: fewer than two Ns, or frames that do not determine the spacing or the
            centre of rotation (:func:`~brachycal.calibration.phantom.stepper.centre_of_rotation`).
    """
    if len(patterns) < 2:
        raise DegenerateDataError(
            f"the stepper's phantom registration needs at least two N patterns, got {len(patterns)}"
        )
    spacing = pixel_spacing(frames, patterns)
    centre = centre_of_rotation(frames, patterns, spacing.value)
    s = spacing.value
    o = centre.value * s
    a_wire, b_wire, c_wire = patterns[1][0], patterns[1][2], patterns[0][2]
    vertical, horizontal = [], []
    for points in frames:
        a, b, c = (np.asarray(points[w.name], dtype=float)[:2] * s for w in (a_wire, b_wire, c_wire))
        vertical.append(_point_line_distance(o, a, b))
        horizontal.append(_point_line_distance(o, b, c))
    d_v, d_h = float(np.mean(vertical)), float(np.mean(horizontal))
    T = np.eye(4)
    at = np.asarray(axis_at_m, dtype=float).reshape(2)
    T[:3, 3] = [at[0] - (b_wire.front_m[0] + d_h), at[1] - (b_wire.front_m[1] + d_v), 0.0]
    return PhantomRegistration(T, spacing, centre, d_v, d_h, len(frames))


def stepper_pose(
    translation_m: float, rotation_rad: float, axis: ArrayLike = (0.0, 0.0, 1.0), rotation_scale: float = 1.0
) -> FloatArray:
    """``T_SH_probe (4, 4)``: the probe at encoder readings ``translation_m``, ``rotation_rad``.

    PLUS's ``vtkPlusBrachyTracker``: a translation by ``axis · d`` (``axis = (Tx, Ty, 1)``), then a
    turn of ``rotation_scale · θ`` about the probe's ``z``.
    """
    T = np.eye(4)
    T[:3, :3] = rotation(np.array([0.0, 0.0, rotation_scale * rotation_rad]))
    T[:3, 3] = np.asarray(axis, dtype=float) * translation_m
    return T


def encoder_readings(T_SH_probe: ArrayLike, *, what: str = "pose") -> tuple[float, float]:
    """``(translation_m, rotation_rad)`` of a recorded stepper pose (a translation along ``z`` and a turn about it).

    Raises:
        InputError: the pose moves across ``z`` or tilts (more than :data:`ENCODER_POSE_TOLERANCE`):
            not a stepper's uncorrected encoder pose.
    """
    T = np.asarray(T_SH_probe, dtype=float)
    if np.abs(T[:2, 3]).max() > ENCODER_POSE_TOLERANCE or np.abs(T[2, :2]).max() > ENCODER_POSE_TOLERANCE:
        raise InputError(
            f"the {what} is not a stepper encoder pose (a translation along z and a turn about z): "
            "it is already corrected, or not a stepper's; use the poses as recorded (--recorded-poses)"
        )
    return float(T[2, 3]), float(np.arctan2(T[1, 0], T[0, 0]))


def corrected_frames(frames: Sequence[SegmentedFrame], axes: StepperAxes) -> list[SegmentedFrame]:
    """``frames`` with each pose rebuilt from its encoder readings along the calibrated axes.

    The probe's pose (:func:`stepper_pose` with ``axes.probe_translation`` and the encoder scale)
    and the template's (a translation along ``axes.template_translation``).

    Raises:
        InputError: naming the frame and the field, when a recorded pose is not an encoder pose.
    """
    out = []
    for frame in frames:
        T_probe, T_template = frame.T_tracker_probe, frame.T_tracker_reference
        try:
            if T_probe is not None:
                d, theta = encoder_readings(T_probe, what=frame.pose_names[0])
                T_probe = stepper_pose(d, theta, axes.probe_translation, axes.rotation_encoder_scale)
            if T_template is not None:
                d, _ = encoder_readings(T_template, what=frame.pose_names[1])
                T_template = stepper_pose(d, 0.0, axes.template_translation)
        except InputError as exc:
            raise InputError(exc.problem, file=frame.source, row=frame.index, row_label=frame.label) from None
        out.append(replace(frame, T_tracker_probe=T_probe, T_tracker_reference=T_template))
    return out


def read_calibrated_axes(path: str | os.PathLike[str]) -> StepperAxes:
    """The stepper's axes from a ``brachycal stepper calibrate`` result (``brachycal-stepper/1``), PLUS's form.

    Raises:
        InputError: another format, or a value :data:`~brachycal.calibration.phantom.stepper_file.STEPPER_DOCUMENT`
            refuses: an axis or scale that is missing or not PLUS's ``Tx Ty 1`` within 0.2 of the
            stepper's z (a scale within 0.5–2), naming the key.
    """
    raw = read_document(path, STEPPER_FORMAT, STEPPER_DOCUMENT)
    axes = [
        np.array(raw[key]["plus_orientation"], dtype=float)
        for key in ("probe_translation_axis", "template_translation_axis")
    ]
    scale = float(raw["rotation_encoder"]["plus_scale"])
    return StepperAxes(axes[0], axes[1], scale, f"brachycal stepper calibrate ({Path(path).name})")


@dataclass(frozen=True)
class StepperImageResult:
    """Image → Probe of a probe on a stepper, with the phantom's registration and both pose models.

    Attributes:
        nwire: the N-wire calibration with the poses corrected by ``axes`` (as recorded if straight).
        recorded: the same on the recorded poses (PLUS's fit), None when ``axes`` are straight.
        registration: the phantom's registration (PLUS's, from the rotation recording).
        axes: the stepper's axis calibration used.
    """

    nwire: NWireFileResult
    recorded: NWireFileResult | None
    registration: PhantomRegistration
    axes: StepperAxes

    def to_json(self) -> dict[str, object]:
        """``brachycal-nwire/1`` (the corrected fit) with a ``stepper`` block: metres, ``*_mm`` where the key says."""
        r = self.registration
        stepper: dict[str, object] = {
            "pose_source": "stepper encoders (StepperHome)",
            "T_Template_Phantom": r.T_template_phantom.tolist(),
            "registration": {
                "method": "PLUS brachy-stepper phantom registration (probe-rotation recording)",
                "frames": r.frames,
                "spacing_mm": (r.spacing.value * 1e3).tolist(),
                "centre_of_rotation_px": r.centre.value.tolist(),
                "vertical_distance_mm": r.vertical_m * 1e3,
                "horizontal_distance_mm": r.horizontal_m * 1e3,
            },
            "axes": {
                "probe_translation": self.axes.probe_translation.tolist(),
                "template_translation": self.axes.template_translation.tolist(),
                "rotation_encoder_scale": self.axes.rotation_encoder_scale,
                "source": self.axes.source,
                "poses": "as recorded" if self.recorded is None else "corrected along the axes",
            },
        }
        if self.recorded is not None:
            payload = self.recorded.to_json()
            stepper["recorded_poses"] = {key: payload[key] for key in ("errors", "model", "models")}
        return self.nwire.to_json() | {"stepper": stepper}


def calibrate_stepper_image_files(
    config_path: str | os.PathLike[str],
    rotation_path: str | os.PathLike[str],
    calibration_path: str | os.PathLike[str],
    validation_path: str | os.PathLike[str] | None = None,
    *,
    model: str | None = None,
    correct_axes: bool = True,
    axes: StepperAxes | None = None,
    progress: Progress | None = None,
) -> StepperImageResult:
    """Image → Probe of a TRUS probe on a stepper from PLUS files, validated as PLUS does.

    Args:
        config_path: PLUS's stepper device set (phantom, segmentation settings, its
            ``vtkPlusProbeCalibrationAlgo`` reference ``StepperHome``, the ``StepperCalibration`` axes).
        rotation_path: B-mode sequence (``.mha``) of the probe turned by the stepper: segmented here,
            for the phantom's registration.
        calibration_path: B-mode sequence of random stepper motion (segmented here, with its
            stepper pose streams), or a segmented-frames XML holding both frame sets (then
            ``validation_path`` is None).
        validation_path: B-mode sequence of the validation frames, or None.
        model: a :data:`~brachycal.calibration.phantom.nwire_file.NWIRE_MODELS` name, or None (lowest
            best-95 % validation mean).
        correct_axes: rebuild the poses along the calibrated axes (False: as recorded).
        axes: the stepper's axes to rebuild them along; None: the device set's ``StepperCalibration``
            (refused when it has none: the poses as recorded are asked for with ``correct_axes=False``).
        progress: ``progress(name, frames)``, a context whose value's ``update(1)`` is called after
            each frame segmented (a progress bar per recording), or None.

    Raises:
        InputError: unreadable or malformed files, a device set without a stepper, or without a
            ``StepperCalibration`` (with ``correct_axes`` and no ``axes``), recorded poses that are
            not encoder poses (with ``correct_axes``), an unknown model.
        DegenerateDataError: frames that cannot determine the registration or the fit.
    """
    check_model(model)  # before any frame is segmented
    streams = read_pose_streams(config_path)
    if streams.source != "stepper":
        raise InputError(
            "not a stepper device set: no iCal element or BrachyTracker device "
            "(use `brachycal nwire` for a tracked probe)",
            file=config_path,
        )
    config = read_plus_config(config_path, require_registration=False)
    if not correct_axes:
        axes = STRAIGHT_AXES
    elif axes is None:
        axes = read_stepper_axes(config_path)
        if axes is None:
            raise InputError(
                "no StepperCalibration in the device set: the axes the stepper moves along are unknown; give "
                "--stepper STEPPER.json (from `brachycal stepper calibrate`), or --recorded-poses to take the "
                "poses as recorded (the probe moving along the stepper's z exactly: a tilted axis is not corrected)",
                file=config_path,
            )
    # The rotation recording's encoders (its header only) are checked before any frame is segmented.
    encoders = stepper_encoder_values(read_sequence_header(rotation_path)[1], rotation_path)
    check_recording("rotation", rotation_path, encoders)
    params = read_segmentation_parameters(config_path)
    if validation_path is None:
        calibration, validation = read_segmented_frames(calibration_path, poses=streams.fields)
    else:

        def segmented(label: str, path: str | os.PathLike[str]) -> list[SegmentedFrame]:
            sequence = read_image_sequence(path)
            with progress(Path(path).name, len(sequence)) if progress is not None else nullcontext() as bar:
                return segment_sequence(
                    sequence,
                    config,
                    params,
                    source=path,
                    label=f"{label} Frame",
                    poses=streams,
                    require_poses=True,
                    progress=None if bar is None else bar.update,
                ).frames

        calibration = segmented("CalibrationData", calibration_path)
        validation = segmented("ValidationData", validation_path)
    rotation = read_stepper_recording(
        rotation_path, encoders, config, params, minimum=MIN_ROTATION_FRAMES, progress=progress
    )
    plus_registration = register_phantom(rotation.frames, config.patterns)
    paths = [p for p in (config_path, rotation_path, calibration_path, validation_path) if p is not None]
    inputs = {Path(p).name: sha256_file(p) for p in paths}

    def fit(registration: PhantomRegistration, cal: list[SegmentedFrame], val: list[SegmentedFrame]) -> NWireFileResult:
        T = registration.T_template_phantom
        registered = replace(config, transforms={**config.transforms, ("Phantom", "Reference"): T})
        return calibrate_nwire_frames(registered, cal, val, model=model, inputs=inputs)

    recorded = fit(plus_registration, calibration, validation)
    if axes.straight:
        return StepperImageResult(recorded, None, plus_registration, axes)
    # the probe's axis during the rotation recording, moved across z by the calibrated translation axis
    d_rotation = float(np.mean(rotation.encoders[:, 0])) if len(rotation.encoders) else 0.0
    registration = register_phantom(rotation.frames, config.patterns, axes.probe_translation[:2] * d_rotation)
    corrected = fit(registration, corrected_frames(calibration, axes), corrected_frames(validation, axes))
    return StepperImageResult(corrected, recorded, registration, axes)


def write_stepper_image(result: StepperImageResult, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``result`` as ``brachycal-nwire/1`` JSON with its ``stepper`` block, all or nothing."""
    return write_json(path, result.to_json(), force=force)


#: The schema of the ``stepper`` block of a stepper Image → Probe file (:mod:`brachycal.data.json_schema`):
#: the phantom's registration (metres) and the stepper axes the poses were rebuilt along.
STEPPER_BLOCK = Obj(
    required={
        "T_Template_Phantom": transform,
        "axes": Obj(
            required={
                "probe_translation": stepper_axis,
                "template_translation": stepper_axis,
                "rotation_encoder_scale": encoder_scale,
            },
            optional={"source": text(), "poses": text()},
        ),
    },
    optional={
        "pose_source": text(),
        "registration": Obj(
            optional={
                "frames": integer(),
                "spacing_mm": spacing,
                "centre_of_rotation_px": array(number(-MAX_IMAGE_PX, MAX_IMAGE_PX, "px"), length=2),
                "vertical_distance_mm": number(0.0, MAX_TRANSLATION_M * 1e3, "mm"),
                "horizontal_distance_mm": number(0.0, MAX_TRANSLATION_M * 1e3, "mm"),
            }
        ),
    },
)


@dataclass(frozen=True)
class StepperImageFile:
    """What a stepper Image → Probe file holds: the N-wire result, the registration and the axes.

    Attributes:
        nwire: the N-wire part (:class:`~brachycal.calibration.phantom.nwire_file.NWireFile`).
        T_template_phantom: ``(4, 4)`` the phantom's registration, metres.
        axes: the stepper axes the poses were corrected with.
    """

    nwire: NWireFile
    T_template_phantom: FloatArray
    axes: StepperAxes

    @property
    def image_to_probe(self) -> FloatArray:
        """The chosen model's Image → Probe ``(4, 4)``, pixels → metres (PLUS's form)."""
        return self.nwire.image_to_probe


def read_stepper_image(path: str | os.PathLike[str]) -> StepperImageFile:
    """Read a stepper Image → Probe file (:func:`write_stepper_image`).

    Raises:
        InputError: not a ``brachycal-nwire/1`` file, no ``stepper`` block (an N-wire result of a
            tracked probe), or a registration or axis that is not what it should be (naming the key).
    """
    nwire = read_nwire(path)
    stepper = nwire.raw.get("stepper")
    if not isinstance(stepper, dict):
        raise InputError(
            f"no stepper registration: a {FORMAT} result of a tracked probe (`brachycal stepper image` writes one)",
            file=path,
            column="stepper",
        )
    STEPPER_BLOCK(stepper, Where(path, "stepper"))
    T = np.array(stepper["T_Template_Phantom"], dtype=float)
    raw_axes = stepper["axes"]
    probe, template = (np.array(raw_axes[key], dtype=float) for key in ("probe_translation", "template_translation"))
    scale = float(raw_axes["rotation_encoder_scale"])
    return StepperImageFile(nwire, T, StepperAxes(probe, template, scale, str(raw_axes.get("source", ""))))


@dataclass(frozen=True)
class HoleInImage:
    """Where a needle through a template hole lands in the image.

    Attributes:
        hole: the hole's ID.
        depth_m: insertion depth past the template along its ``z``, metres.
        u_px, v_px: the needle point projected onto the image plane, pixels.
        distance_m: signed distance of the point from the image plane (along the image's ``z``), metres.
        p_probe_m: ``(3,)`` the point in the probe frame, metres.
    """

    hole: str
    depth_m: float
    u_px: float
    v_px: float
    distance_m: float
    p_probe_m: FloatArray


def hole_in_image(
    image_to_probe: ArrayLike,
    T_template_phantom: ArrayLike,
    template: TemplateGrid,
    hole: str,
    depth_m: float,
    *,
    probe_translation_m: float,
    probe_rotation_rad: float = 0.0,
    template_translation_m: float = 0.0,
    axes: StepperAxes | None = None,
) -> HoleInImage:
    """A planned needle (template ``hole``, ``depth_m`` past the template) in the image at a stepper pose.

    ``p_probe = T_SH_probe⁻¹ · T_SH_template · T_template_phantom · T_phantom_grid · (hole + depth · z)``;
    the image point is Image → Probe's inverse of it: ``(u, v)`` in pixels and the distance off the
    plane in metres.

    Args:
        image_to_probe: ``(4, 4)`` Image → Probe, pixels → metres (PLUS's form: the third column
            the image normal times the mean pixel size).
        T_template_phantom: ``(4, 4)`` the phantom's registration, metres.
        template: the template's holes and its place on the phantom.
        axes: the stepper's axes (the poses are built as :func:`stepper_pose`); None: straight.

    Raises:
        InputError: an unknown hole ID (naming the device set), a non-finite depth or pose.
    """
    values = (depth_m, probe_translation_m, probe_rotation_rad, template_translation_m)
    if not np.all(np.isfinite(values)):
        raise InputError(f"depth and stepper readings must be finite numbers, got {values}")
    axes = axes or STRAIGHT_AXES
    p_template = template.hole(hole) + np.array([0.0, 0.0, depth_m])
    p_phantom = transform_points(template.T_phantom_template, p_template)
    T_SH_probe = stepper_pose(
        probe_translation_m, probe_rotation_rad, axes.probe_translation, axes.rotation_encoder_scale
    )
    T_SH_template = stepper_pose(template_translation_m, 0.0, axes.template_translation)
    T_probe_phantom = inverse(T_SH_probe) @ T_SH_template @ np.asarray(T_template_phantom, dtype=float)
    p_probe = transform_points(T_probe_phantom, p_phantom)
    M = np.asarray(image_to_probe, dtype=float)
    u, v, w = np.linalg.solve(M[:3, :3], p_probe - M[:3, 3])
    return HoleInImage(hole, float(depth_m), float(u), float(v), float(w * np.linalg.norm(M[:3, 2])), p_probe)
