"""B-mode images of a multi-wedge phantom session: each face a bright specular line, thickened by the beam.

Design: ``docs/design/bmode.md``, "B-mode frames of a multi-wedge phantom".
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np

from brachycal.calibration.phantom.phantom_file import PhantomObservations
from brachycal.calibration.phantom.wedge import Face, WedgePhantom
from brachycal.errors import InputError
from brachycal.imaging.wedge_lines import find_wedge_lines
from brachycal.se3 import FloatArray, inverse
from brachycal.simulation.bmode import BModeSettings, render_frame
from brachycal.studies.phantom_twin import PhantomSession

__all__ = [
    "FACE_HALF_WIDTH_M",
    "FACE_LEVEL_DB",
    "RenderedWedgeSegmentation",
    "face_lines_px",
    "nominal_face_order",
    "render_wedge_frame",
    "render_wedge_session",
    "rendered_wedge_observations",
]

#: A face's extent from its ridge outwards, metres (half the bundled wedges' 24 mm width).
FACE_HALF_WIDTH_M = 0.012
#: The faces' echo, dB re white (a water/PLA interface: module docstring).
FACE_LEVEL_DB = -10.0
#: Elevation samples across the beam (±1.5 FWHM, where the pulse-echo weight falls to 2e-3).
_ELEVATION_SAMPLES = 25
_ELEVATION_REACH_FWHM = 1.5
_FWHM_TO_SD = 1.0 / np.sqrt(8.0 * np.log(2.0))


def _outward(faces: Sequence[Face]) -> dict[str, FloatArray]:
    """Each face's outward direction ``(3,)`` in the phantom: horizontal, across its ridge, to its side.

    The ridge runs along the cross product of the wedge's two normals; a roof face lies on the
    side its normal leans to (as :mod:`~brachycal.studies.phantom_twin` places it).
    """
    out = {}
    for face in faces:
        partner = next(f for f in faces if f.wedge == face.wedge and f.name != face.name)
        ridge = np.cross(face.normal, partner.normal)
        across = np.cross(ridge, [0.0, 0.0, 1.0])
        across /= np.linalg.norm(across)
        out[face.name] = across if across @ face.normal > 0 else -across
    return out


def _face_echoes(
    faces: Sequence[Face],
    T_image_phantom: FloatArray,
    settings: BModeSettings,
    level_db: float,
    half_width_m: float,
    shown: Collection[str] | None,
):
    """The ``echoes`` hook of :func:`~brachycal.simulation.bmode.render_frame` drawing ``faces`` (those ``shown``)."""
    outward = _outward(faces)
    faces = [f for f in faces if shown is None or f.name in shown]
    if settings.beam_thickness:
        fwhm = settings.elevation_fwhm_m
        z = np.linspace(-_ELEVATION_REACH_FWHM, _ELEVATION_REACH_FWHM, _ELEVATION_SAMPLES) * fwhm
        weight = np.exp(-4.0 * np.log(2.0) * (z / fwhm) ** 2)
    else:
        z, weight = np.zeros(1), np.ones(1)
    weight = weight / weight.sum()  # an untilted face peaks at its level
    level = 10.0 ** (level_db / 20.0)
    R, t = T_image_phantom[:3, :3], T_image_phantom[:3, 3]
    R_phantom_image = R.T

    def draw(envelope: np.ndarray, origin_px: tuple[int, int], spacing: tuple[float, float], psf_sd_m) -> None:
        ou, ov = origin_px
        height, width = envelope.shape
        su, sv = spacing
        sd_axial_px = float(psf_sd_m[1]) / sv
        half_rows = int(np.ceil(4.0 * sd_axial_px))
        rows = np.arange(-half_rows, half_rows + 1)[:, None]  # (2K+1, 1) offsets from the nearest row
        columns = np.arange(width)
        x = (columns + ou) * su  # (W,) metres, image frame
        for face in faces:
            n = R @ face.normal
            if abs(n[1]) < 1e-6:  # a face along the beam shows no line
                continue
            c = n @ (R @ face.point_m + t)
            for zk, wk in zip(z, weight, strict=True):
                y = (c - n[0] * x - n[2] * zk) / n[1]  # (W,) depth of the face at elevation zk
                p_phantom = (np.column_stack([x, y, np.full_like(x, zk)]) - t) @ R_phantom_image.T
                off = (p_phantom - face.point_m) @ outward[face.name]
                keep = (off >= 0.0) & (off <= half_width_m)
                if not np.any(keep):
                    continue
                v = y[keep] / sv - ov  # fractional row in the envelope
                nearest = np.rint(v).astype(int)
                r = nearest[None, :] + rows  # (2K+1, M)
                gauss = np.exp(-0.5 * ((r - v[None, :]) / sd_axial_px) ** 2) * (level * wk)
                cols = np.broadcast_to(columns[keep][None, :], r.shape)
                inside = (r >= 0) & (r < height)
                np.add.at(envelope, (r[inside], cols[inside]), gauss[inside].astype(np.float32))

    return draw


def render_wedge_frame(
    faces: Sequence[Face],
    T_image_phantom: FloatArray,
    spacing_m: FloatArray,
    settings: BModeSettings | None = None,
    *,
    size_px: tuple[int, int],
    frame_index: int = 0,
    level_db: float = FACE_LEVEL_DB,
    half_width_m: float = FACE_HALF_WIDTH_M,
    shown: Collection[str] | None = None,
) -> np.ndarray:
    """One B-mode frame ``(H, W)`` uint8 of a multi-wedge phantom's faces (module docstring).

    Args:
        faces: the phantom's faces (phantom frame, metres; the printed ones for a twin's truth),
            in pairs per wedge.
        T_image_phantom: ``(4, 4)`` the phantom frame in the image frame ``us_image``, metres.
        spacing_m: ``(2,)`` metres per pixel ``(s_u, s_v)``. size_px: ``(width, height)``.
        settings: the renderer's effects (its needle is absent; its beam, PSF and speckle apply).
        frame_index: the frame's random streams (:func:`~brachycal.simulation.bmode.render_frame`).
        level_db: the faces' echo, dB re white. half_width_m: a face's extent from its ridge.
        shown: the names of the faces drawn (default all; e.g. one hidden by a bubble on it).
    """
    settings = settings or BModeSettings()
    T = np.asarray(T_image_phantom, dtype=float)
    echoes = _face_echoes(faces, T, settings, level_db, half_width_m, shown)
    return render_frame(None, spacing_m, settings, size_px=size_px, frame_index=frame_index, echoes=echoes)


def face_lines_px(
    faces: Sequence[Face], T_image_phantom: FloatArray, spacing_m: FloatArray, u_px: FloatArray
) -> dict[str, FloatArray]:
    """Each face's true line in the image plane (elevation 0): ``v`` pixels ``(C,)`` at columns ``u_px (C,)``."""
    R, t = T_image_phantom[:3, :3], T_image_phantom[:3, 3]
    out = {}
    for face in faces:
        n = R @ face.normal
        c = n @ (R @ face.point_m + t)
        out[face.name] = (c - n[0] * np.asarray(u_px) * spacing_m[0]) / (n[1] * spacing_m[1])
    return out


def nominal_face_order(phantom: WedgePhantom, T_image_phantom: FloatArray) -> tuple[list[str], list[int]]:
    """The faces left to right in the image of a nominal pose, and the sign of each line's slope ``dv/du``.

    Where each face's middle (half its width from the ridge, on the ridge's point) shows along
    ``u`` orders them; the sign of ``dv/du`` of its line tells a face rising towards its ridge
    (``−1``: depth decreases to the right) from one falling away from it (``+1``). A scan within
    the twin's ±6° (SD) of the nominal pose keeps both (module :mod:`brachycal.imaging.wedge_lines`).
    """
    outward = _outward(phantom.faces)
    R, t = T_image_phantom[:3, :3], T_image_phantom[:3, 3]
    middles, slopes = [], []
    for face in phantom.faces:
        middle = R @ (face.point_m + outward[face.name] * FACE_HALF_WIDTH_M / 2) + t
        middles.append(middle[0])
        n = R @ face.normal
        slopes.append(int(np.sign(-n[0] / n[1])))
    order = np.argsort(middles)
    return [phantom.faces[k].name for k in order], [slopes[k] for k in order]


def render_wedge_session(
    session: PhantomSession,
    spacing_m: FloatArray,
    size_px: tuple[int, int],
    settings: BModeSettings | None = None,
) -> np.ndarray:
    """``(F, H, W)`` uint8: every frame of a simulated multi-wedge session, from its true poses and printed faces.

    Args:
        session: a :class:`~brachycal.studies.phantom_twin.PhantomSession` of ``"wedge"``.
        spacing_m: ``(2,)`` the true pixel spacing. size_px: ``(width, height)``.
        settings: the renderer's effects; frame ``f`` draws from the streams of ``(settings.seed, f)``.
    """
    if session.T_phantom_image is None or session.physical is None or not isinstance(session.phantom, WedgePhantom):
        raise InputError("not a simulated multi-wedge session with its truth (simulate_phantom('wedge', ...))")
    settings = settings or BModeSettings()
    faces = [f for f in session.physical if isinstance(f, Face)]
    return np.stack(
        [
            render_wedge_frame(faces, inverse(T), spacing_m, settings, size_px=size_px, frame_index=k)
            for k, T in enumerate(session.T_phantom_image)
        ]
    )


@dataclass(frozen=True)
class RenderedWedgeSegmentation:
    """Observations segmented from a session's rendered frames, and how they compare with the truth.

    Attributes:
        observations: the frames where every face was found (tracker readings as the session's).
        skipped: frames where not every face was found (or the lines did not match the expected
            order and slopes).
        line_error_px: ``(K, 2)`` each found line end's depth minus the true line's at its column
            (pixels, ``v``; the true line is the printed face at elevation 0).
    """

    observations: PhantomObservations
    skipped: int
    line_error_px: FloatArray


def rendered_wedge_observations(
    session: PhantomSession,
    spacing_m: FloatArray,
    size_px: tuple[int, int],
    settings: BModeSettings | None = None,
) -> RenderedWedgeSegmentation:
    """Render a simulated multi-wedge session's frames and segment their lines into observations.

    The face order and slopes come from the session's nominal scan pose (the phantom's ``x`` along
    ``u``, depth along its ``−z``): :func:`nominal_face_order` at the first frame's pose is the same
    for every pose of the twin's ±6° scan (checked: a frame whose lines disagree is skipped).

    Raises:
        DegenerateDataError: fewer than 3 frames have all their faces found (from the calibration).
    """
    settings = settings or BModeSettings()
    frames = render_wedge_session(session, spacing_m, size_px, settings)
    phantom = session.phantom
    if not isinstance(phantom, WedgePhantom) or session.T_phantom_image is None or session.physical is None:
        raise InputError("not a simulated multi-wedge session with its truth (simulate_phantom('wedge', ...))")
    faces = [f for f in session.physical if isinstance(f, Face)]
    seen = session.observations
    order, slopes = nominal_face_order(phantom, inverse(session.T_phantom_image[0]))
    kept: list[int] = []
    feature: list[str] = []
    uv: list[FloatArray] = []
    frame_of: list[int] = []
    errors: list[FloatArray] = []
    for k, frame in enumerate(frames):
        found = find_wedge_lines(frame, order, slopes, dynamic_range_db=settings.dynamic_range_db)
        if found is None:
            continue
        truth = {}
        for name, ends in found.items():
            truth[name] = face_lines_px(faces, inverse(session.T_phantom_image[k]), spacing_m, ends[:, 0])[name]
        frame_of += [len(kept)] * len(found)
        kept.append(k)
        for name in phantom.names:
            feature.append(name)
            uv.append(found[name])
            errors.append(found[name][:, 1] - truth[name])
    observations = PhantomObservations(
        [seen.frames[k] for k in kept],
        seen.T_tracker_probe[kept],
        seen.T_tracker_reference[kept],
        np.array(frame_of, dtype=int),
        feature,
        np.array(uv).reshape(-1, 2, 2),
        list(range(2, len(feature) + 2)),
    )
    return RenderedWedgeSegmentation(observations, len(frames) - len(kept), np.array(errors).reshape(-1, 2))
