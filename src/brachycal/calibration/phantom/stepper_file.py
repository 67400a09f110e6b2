"""Stepper calibration of PLUS recordings, and its result file ``brachycal-stepper/1`` (JSON).

:func:`calibrate_stepper_files` reads a PLUS device set (the N-wire phantom, its segmentation
settings) and three single-axis recordings of a TRUS probe on a brachytherapy stepper (probe
rotation, probe translation, template translation), checks that each moves its axis (and only
it), segments every frame as ``brachycal nwire segment`` does, reads each frame's encoder values,
and runs the stepper calibration of :mod:`brachycal.calibration.phantom.stepper`: pixel spacing,
centre of rotation, rotation axis and encoder, both translation axes, each with its SD;
:func:`write_stepper` writes the result.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from brachycal.calibration.phantom.stepper import (
    MIN_ROTATION_FRAMES,
    MIN_ROTATION_RAD,
    MIN_TRANSLATION_M,
    STILL_ROTATION_RAD,
    STILL_TRANSLATION_M,
    EncoderFit,
    RotationAxisFit,
    StepperFit,
    TranslationAxisFit,
    check_range,
    jackknife_spacing_sd,
    pixel_spacing,
    relative_axis,
    rotation_axis,
    rotation_encoder,
    translation_axis,
)
from brachycal.calibration.sequential.method import naming_file
from brachycal.data.formats.metaimage import MF, pixel_frame_text, read_image_sequence, read_sequence_header
from brachycal.data.formats.plus_files import (
    STEPPER_ENCODER_FIELDS,
    PlusConfig,
    read_plus_config,
    stepper_encoder_values,
)
from brachycal.data.formats.plus_segmentation import NWireSegmentationParameters, read_segmentation_parameters
from brachycal.data.formats.plus_stepper import encoder_scale, stepper_axis
from brachycal.data.json_schema import Obj, array, number, spacing
from brachycal.errors import DegenerateDataError
from brachycal.imaging.nwire_segmentation import segment_sequence
from brachycal.io import sha256_file, write_json
from brachycal.se3 import FloatArray
from brachycal.validate import MAX_IMAGE_PX

FORMAT = "brachycal-stepper/1"
#: Fewest segmented frames a translation recording needs (a line through the encoder's positions
#: with room for its residuals).
MIN_TRANSLATION_FRAMES = 3
#: A progress report: ``progress(name, frames)`` is a context whose value has ``update(n)``.
Progress = Callable[[str, int], AbstractContextManager[Any]]
#: The three recordings, in the command's order, with the encoder (index into
#: :data:`~brachycal.data.formats.plus_files.STEPPER_ENCODER_FIELDS`) each must move.
RECORDINGS = {"rotation": 1, "probe_translation": 0, "template_translation": 2}
#: What the frame's axes are: the image's, PLUS's convention for the orientations.
AXES_NOTE = (
    "slopes are the still wires' dots' motion in the image (x = u * spacing_u, y = v * spacing_v) per "
    "metre of the encoder; plus_orientation is PLUS's (-slope_x, slope_y, 1), comparable with a device "
    "set's StepperCalibration; each translation axis is relative to the phantom's wires, their sum "
    "(template relative to probe) is not"
)


@dataclass(frozen=True)
class StepperRecording:
    """One segmented single-axis recording.

    Attributes:
        path: its file.
        frames: the segmented frames' wire points (wire name → ``(u, v)`` px), in order.
        encoders: ``(K, 3)`` those frames' encoder values: probe position (m), probe rotation
            (rad), template position (m).
        total: frames in the recording.
        stored: how the file stored its frames (its ``UltrasoundImageOrientation``, None if not
            stated); the points are in PLUS's ``MF`` image frame whatever it is.
    """

    path: str
    frames: list[dict[str, FloatArray]]
    encoders: FloatArray
    total: int
    stored: str | None = MF


@dataclass(frozen=True)
class StepperFileResult:
    """A stepper calibration of three recordings.

    Attributes:
        spacing: pixel spacing ``(s_u, s_v)``, metres per pixel (the rotation recording, as PLUS's
            baseline), with ``spacing_sd`` (jackknife over frames).
        spacing_all: the spacing from all three recordings' frames (a cross-check).
        rotation: the centre of rotation and what the recording says of the axis's tilt.
        encoder: the rotation encoder's scale and offset against the image.
        probe_axis, template_axis: the translation axes.
        recordings: ``"rotation"``, ``"probe_translation"``, ``"template_translation"`` → recording.
        config: the device set's file.
    """

    spacing: StepperFit
    spacing_sd: FloatArray
    spacing_all: StepperFit
    rotation: RotationAxisFit
    encoder: EncoderFit
    probe_axis: TranslationAxisFit
    template_axis: TranslationAxisFit
    recordings: dict[str, StepperRecording]
    config: str

    def to_json(self) -> dict:
        """The ``brachycal-stepper/1`` payload (metres, radians; ``_px``, ``_mm``, ``_deg`` where a key says)."""
        rot = self.rotation
        relative, relative_sd = relative_axis(self.probe_axis, self.template_axis)
        return {
            "format": FORMAT,
            "pixel_spacing": {
                "value_m_per_px": self.spacing.value.tolist(),
                "sd_m_per_px": self.spacing_sd.tolist(),
                "value_mm_per_px": (self.spacing.value * 1e3).tolist(),
                "sd_mm_per_px": (self.spacing_sd * 1e3).tolist(),
                "from": "rotation",
                "residual_mean_m2": self.spacing.residual_mean,
                "residual_sd_m2": self.spacing.residual_sd,
                "equations": self.spacing.equations,
                "kept": self.spacing.kept,
                "all_recordings_m_per_px": self.spacing_all.value.tolist(),
            },
            "centre_of_rotation": {
                "pixel_frame": pixel_frame_text(self.recordings["rotation"].stored),
                "value_px": rot.centre_px.tolist(),
                "sd_px": rot.centre_sd_px.tolist(),
                "dot_sd_m": rot.dot_sd_m,
                "residual_mean_m2": rot.fit.residual_mean,
                "residual_sd_m2": rot.fit.residual_sd,
                "equations": rot.fit.equations,
                "kept": rot.fit.kept,
            },
            "rotation_axis": {
                "probe_positions_m": rot.positions_m.tolist(),
                "rotation_range_rad": rot.range_rad,
                "tilt": None if rot.tilt is None else rot.tilt.tolist(),
                "tilt_sd": None if rot.tilt_sd is None else rot.tilt_sd.tolist(),
                "plus_orientation": None if rot.tilt is None else [-rot.tilt[0], rot.tilt[1], 1.0],
                "determined": rot.tilt is not None,
                "note": rot.tilt_note,
            },
            "rotation_encoder": {
                "scale": self.encoder.scale,
                "scale_sd": self.encoder.scale_sd,
                "plus_scale": -self.encoder.scale,
                "offset_rad": self.encoder.offset_rad,
                "offset_sd_rad": self.encoder.offset_sd_rad,
                "residual_sd_rad": self.encoder.residual_sd_rad,
                "equations": self.encoder.equations,
                "kept": self.encoder.kept,
            },
            "probe_translation_axis": _axis_json(self.probe_axis),
            "template_translation_axis": _axis_json(self.template_axis),
            "template_relative_to_probe": {
                "slope": relative.tolist(),
                "slope_sd": relative_sd.tolist(),
                "plus_orientation": [-relative[0], relative[1], 1.0],
                "angle_deg": float(np.degrees(np.arctan(np.hypot(*relative)))),
            },
            "axes": AXES_NOTE,
            "recordings": {
                name: {
                    "file": Path(r.path).name,
                    "frames": r.total,
                    "segmented": len(r.frames),
                    "stored_orientation": r.stored,
                }
                for name, r in self.recordings.items()
            },
            "inputs": {
                "config_sha256": sha256_file(self.config),
                **{f"{name}_sha256": sha256_file(r.path) for name, r in self.recordings.items()},
            },
        }


#: The schema of a ``brachycal-stepper/1`` document (:mod:`brachycal.data.json_schema`): the axes
#: and the scale ``brachycal stepper image --stepper`` reads (PLUS's form), and the spacing and the
#: centre of rotation (metres and millimetres per pixel, pixels).
STEPPER_DOCUMENT = Obj(
    required={
        "probe_translation_axis": Obj(required={"plus_orientation": stepper_axis}),
        "template_translation_axis": Obj(required={"plus_orientation": stepper_axis}),
        "rotation_encoder": Obj(required={"plus_scale": encoder_scale}),
    },
    optional={
        "pixel_spacing": Obj(optional={"value_mm_per_px": spacing}),
        "centre_of_rotation": Obj(optional={"value_px": array(number(-MAX_IMAGE_PX, MAX_IMAGE_PX, "px"), length=2)}),
    },
)


def _axis_json(axis: TranslationAxisFit) -> dict:
    direction = axis.plus_orientation / np.linalg.norm(axis.plus_orientation)
    return {
        "slope": axis.slope.tolist(),
        "slope_sd": axis.slope_sd.tolist(),
        "plus_orientation": axis.plus_orientation.tolist(),
        "direction": direction.tolist(),
        "angle_to_wires_deg": axis.angle_deg,
        "angle_to_wires_sd_deg": axis.angle_sd_deg,
        "range_m": axis.range_m,
        "frames": axis.frames,
        "residual_sd_m": axis.residual_sd_m.tolist(),
        "equations": axis.equations,
        "kept": axis.kept,
    }


def check_recording(name: str, path: str | os.PathLike[str], encoders: FloatArray) -> None:
    """Refuse a recording whose axis does not move enough, or whose other axes move.

    The rotation recording must turn at least :data:`MIN_ROTATION_RAD` and keep the template
    still (the probe may sit at several positions: that gives the axis's tilt); a translation
    recording must move its encoder at least :data:`MIN_TRANSLATION_M` and keep the others still.

    Raises:
        DegenerateDataError: naming the file and the encoder field.
    """
    moving = RECORDINGS[name]
    for j, field in enumerate(STEPPER_ENCODER_FIELDS):
        rotation = j == 1
        unit, scale = ("°", 180.0 / np.pi) if rotation else ("mm", 1e3)
        values = encoders[:, j]
        try:
            if j == moving:
                check_range(values, MIN_ROTATION_RAD if rotation else MIN_TRANSLATION_M, field, unit, scale)
                continue
            if name == "rotation" and j == 0:
                continue
            still = STILL_ROTATION_RAD if rotation else STILL_TRANSLATION_M
            span = float(np.ptp(values)) if len(values) else 0.0
            if span > still:
                sep = "" if rotation else " "
                raise DegenerateDataError(
                    f"{field} moves {span * scale:.3g}{sep}{unit} in the {name.replace('_', ' ')} recording "
                    f"(at most {still * scale:.3g}{sep}{unit}: only one axis may move)"
                )
        except DegenerateDataError as exc:
            raise DegenerateDataError(exc.problem, file=path, row_label="frame", column=field) from None


def read_stepper_recording(
    path: str | os.PathLike[str],
    encoders: FloatArray,
    config: PlusConfig,
    params: NWireSegmentationParameters,
    *,
    minimum: int,
    progress: Progress | None = None,
) -> StepperRecording:
    """Segment a stepper recording (its frames' ``encoders`` read and checked already); the
    segmented frames with their encoder values. ``config``, ``params``: the device set's phantom
    and segmentation settings.

    Raises:
        InputError: frames that are not 8-bit.
        DegenerateDataError: fewer than ``minimum`` frames segmented (naming the file).
    """
    sequence = read_image_sequence(path)
    with progress(Path(path).name, len(sequence)) if progress is not None else nullcontext() as bar:
        result = segment_sequence(
            sequence, config, params, source=path, poses=None, progress=None if bar is None else bar.update
        )
    kept = [k for k, frame in enumerate(result.frames) if frame.ok]
    if len(kept) < minimum:
        raise DegenerateDataError(
            f"only {len(kept)} of {len(sequence)} frames segmented (the phantom's Ns found); at least {minimum} needed",
            file=path,
        )
    return StepperRecording(
        str(path),
        [result.frames[k].points_px for k in kept],
        encoders[kept].reshape(-1, 3),
        len(sequence),
        sequence.file_orientation,
    )


def calibrate_stepper_files(
    config: str | os.PathLike[str],
    rotation: str | os.PathLike[str],
    probe_translation: str | os.PathLike[str],
    template_translation: str | os.PathLike[str],
    *,
    progress: Progress | None = None,
) -> StepperFileResult:
    """Calibrate a stepper from PLUS's three single-axis recordings (:class:`StepperFileResult`).

    Every recording's encoder fields are read and checked (:func:`check_recording`) before any
    frame is segmented. ``progress(name, frames)``: a context giving an object whose ``update(1)``
    is called after each frame segmented (a progress bar), or None.

    Raises:
        InputError: a file that does not read, or a recording without encoder fields (naming the
            file, frame and field).
        DegenerateDataError: a phantom with fewer than two Ns, a recording that does not move its
            axis as it must (naming the file and the encoder field), or too few frames segmented.
    """
    phantom = read_plus_config(config, require_registration=False)
    if len(phantom.patterns) < 2:
        raise DegenerateDataError(
            f"PhantomDefinition: the pixel spacing needs at least two N patterns, got {len(phantom.patterns)}",
            file=config,
        )
    paths = {"rotation": rotation, "probe_translation": probe_translation, "template_translation": template_translation}
    encoders = {}
    for name, path in paths.items():
        encoders[name] = stepper_encoder_values(read_sequence_header(path)[1], path)
        check_recording(name, path, encoders[name])
    params = read_segmentation_parameters(config)
    recordings = {
        name: read_stepper_recording(
            path,
            encoders[name],
            phantom,
            params,
            minimum=MIN_ROTATION_FRAMES if name == "rotation" else MIN_TRANSLATION_FRAMES,
            progress=progress,
        )
        for name, path in paths.items()
    }
    rot = recordings["rotation"]
    with naming_file(rot.path):
        spacing = pixel_spacing(rot.frames, phantom.patterns)
        spacing_sd = jackknife_spacing_sd(rot.frames, phantom.patterns)
        axis = rotation_axis(rot.frames, rot.encoders[:, 1], rot.encoders[:, 0], phantom.patterns, spacing.value)
        encoder = rotation_encoder(rot.frames, rot.encoders[:, 1], phantom.patterns, spacing.value)
    spacing_all = pixel_spacing([points for r in recordings.values() for points in r.frames], phantom.patterns)
    probe = recordings["probe_translation"]
    with naming_file(probe.path):
        probe_axis = translation_axis(probe.frames, probe.encoders[:, 0], phantom.patterns, spacing.value)
    template = recordings["template_translation"]
    with naming_file(template.path):
        template_axis = translation_axis(template.frames, template.encoders[:, 2], phantom.patterns, spacing.value)
    return StepperFileResult(
        spacing, spacing_sd, spacing_all, axis, encoder, probe_axis, template_axis, recordings, str(config)
    )


def write_stepper(result: StepperFileResult, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``result`` as ``brachycal-stepper/1`` JSON, all or nothing (never NaN: a missing value is null)."""
    return write_json(path, result.to_json(), force=force)


def summary_lines(result: StepperFileResult) -> list[str]:
    """What ``brachycal stepper calibrate`` prints: per recording the frames used, then the values."""
    lines = [f"{Path(r.path).name}: {len(r.frames)} of {r.total} frames segmented" for r in result.recordings.values()]
    s, sd = result.spacing.value * 1e3, result.spacing_sd * 1e3
    rot = result.rotation
    c, csd = rot.centre_px, rot.centre_sd_px
    lines.append(f"pixel spacing: {s[0]:.6f} ± {sd[0]:.6f} x {s[1]:.6f} ± {sd[1]:.6f} mm/px (SD)")
    lines.append(f"centre of rotation: {c[0]:.3f} ± {csd[0]:.3f}, {c[1]:.3f} ± {csd[1]:.3f} px (SD)")
    lines.append(f"pixels: {pixel_frame_text(result.recordings['rotation'].stored)}")
    if rot.tilt is None:
        lines.append(f"rotation axis tilt: not determined: {rot.tilt_note}")
    else:
        t, tsd = rot.tilt, rot.tilt_sd if rot.tilt_sd is not None else np.zeros(2)
        lines.append(f"rotation axis tilt: {t[0]:.5f} ± {tsd[0]:.5f}, {t[1]:.5f} ± {tsd[1]:.5f} (PLUS: -x, y, 1)")
    e = result.encoder
    lines.append(f"rotation encoder scale: {-e.scale:.5f} ± {e.scale_sd:.5f} (PLUS's sign)")
    for label, axis in (("probe", result.probe_axis), ("template", result.template_axis)):
        o = axis.plus_orientation
        lines.append(
            f"{label} translation axis (PLUS): {o[0]:.6f} ± {axis.slope_sd[0]:.6f}, "
            f"{o[1]:.6f} ± {axis.slope_sd[1]:.6f}, 1 ({axis.angle_deg:.3f}° to the wires)"
        )
    return lines
