"""Stepper calibration of PLUS recordings, and its result file ``brachycal-stepper/1`` (JSON).

:func:`calibrate_stepper_files` reads a PLUS device set (the N-wire phantom, its segmentation
settings) and three single-axis recordings of a TRUS probe on a brachytherapy stepper (probe
rotation, probe translation, template translation), segments every frame as ``brachycal nwire
segment`` does, reads each frame's encoder values, and runs the stepper calibration of
:mod:`brachycal.calibration.phantom.stepper`; :func:`write_stepper` writes the result.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from brachycal.calibration.phantom.stepper import StepperFit, centre_of_rotation, pixel_spacing
from brachycal.data.formats.metaimage import read_image_sequence
from brachycal.data.formats.plus_files import PlusConfig, read_plus_config, stepper_encoder_values
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.imaging.nwire_segmentation import segment_sequence
from brachycal.io import sha256_file, write_json
from brachycal.se3 import FloatArray

FORMAT = "brachycal-stepper/1"


@dataclass(frozen=True)
class StepperRecording:
    """One segmented single-axis recording.

    Attributes:
        path: its file.
        frames: the segmented frames' wire points (wire name → ``(u, v)`` px), in order.
        encoders: ``(K, 3)`` those frames' encoder values: probe position (m), probe rotation
            (rad), template position (m).
        total: frames in the recording.
    """

    path: str
    frames: list[dict[str, FloatArray]]
    encoders: FloatArray
    total: int


@dataclass(frozen=True)
class StepperFileResult:
    """A stepper calibration of three recordings.

    Attributes:
        spacing: pixel spacing ``(s_u, s_v)``, metres per pixel (the rotation recording).
        centre: centre of rotation ``(u, v)``, pixels (the rotation recording).
        recordings: ``"rotation"``, ``"probe_translation"``, ``"template_translation"`` → recording.
        config: the device set's file.
    """

    spacing: StepperFit
    centre: StepperFit
    recordings: dict[str, StepperRecording]
    config: str

    def to_json(self) -> dict:
        """The ``brachycal-stepper/1`` payload (metres, radians; ``_px``, ``_mm`` where a key says)."""
        return {
            "format": FORMAT,
            "pixel_spacing_m_per_px": self.spacing.value.tolist(),
            "centre_of_rotation_px": self.centre.value.tolist(),
            "recordings": {
                name: {"file": Path(r.path).name, "frames": r.total, "segmented": len(r.frames)}
                for name, r in self.recordings.items()
            },
            "inputs": {
                "config_sha256": sha256_file(self.config),
                **{f"{name}_sha256": sha256_file(r.path) for name, r in self.recordings.items()},
            },
        }


def read_stepper_recording(
    path: str | os.PathLike[str], config: PlusConfig, config_path: str | os.PathLike[str]
) -> StepperRecording:
    """Segment a stepper recording and read its frames' encoder values.

    Raises:
        InputError: a frame without the stepper's encoder fields (naming the file, frame, field),
            or frames that are not 8-bit.
    """
    sequence = read_image_sequence(path)
    encoders = stepper_encoder_values(sequence.frame_fields, path)
    result = segment_sequence(sequence, config, read_segmentation_parameters(config_path), source=path, poses=None)
    kept = [k for k, frame in enumerate(result.frames) if frame.ok]
    return StepperRecording(
        str(path), [result.frames[k].points_px for k in kept], encoders[kept].reshape(-1, 3), len(sequence)
    )


def calibrate_stepper_files(
    config: str | os.PathLike[str],
    rotation: str | os.PathLike[str],
    probe_translation: str | os.PathLike[str],
    template_translation: str | os.PathLike[str],
) -> StepperFileResult:
    """Calibrate a stepper from PLUS's three single-axis recordings (:class:`StepperFileResult`).

    Raises:
        InputError: a file that does not read, or a recording without encoder fields.
        DegenerateDataError: a recording that does not determine what it is for.
    """
    phantom = read_plus_config(config, require_registration=False)
    recordings = {
        name: read_stepper_recording(path, phantom, config)
        for name, path in (
            ("rotation", rotation),
            ("probe_translation", probe_translation),
            ("template_translation", template_translation),
        )
    }
    spacing = pixel_spacing(recordings["rotation"].frames, phantom.patterns)
    centre = centre_of_rotation(recordings["rotation"].frames, phantom.patterns, spacing.value)
    return StepperFileResult(spacing, centre, recordings, str(config))


def write_stepper(result: StepperFileResult, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``result`` as ``brachycal-stepper/1`` JSON, all or nothing (never NaN)."""
    return write_json(path, result.to_json(), force=force)


def summary_lines(result: StepperFileResult) -> list[str]:
    """What ``brachycal stepper calibrate`` prints: per recording the frames used, then the values."""
    lines = [f"{Path(r.path).name}: {len(r.frames)} of {r.total} frames segmented" for r in result.recordings.values()]
    s = result.spacing.value * 1e3
    c = result.centre.value
    lines.append(f"pixel spacing: {s[0]:.6f} x {s[1]:.6f} mm/px")
    lines.append(f"centre of rotation: {c[0]:.3f}, {c[1]:.3f} px")
    return lines
