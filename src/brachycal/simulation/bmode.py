"""B-mode-like ultrasound frames of the twin's samples: what the scanner would show of the needle.

:func:`render_frame` draws one 8-bit frame ``(H, W)`` (``frame[v, u]``) of a needle whose tip and
direction are given in the image frame ``us_image`` (metres). Every effect is a switch of
:class:`BModeSettings`; the same seed gives the same frame.

Design: ``docs/design/bmode.md``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.imaging.pixels import DEFAULT_IMAGE_SIZE_PX, DEFAULT_SPACING_M
from brachycal.model.names import NEEDLE_TIP, US_IMAGE
from brachycal.se3 import FloatArray
from brachycal.validate import check_range, check_seed

if TYPE_CHECKING:
    from brachycal.simulation.twin import Twin

__all__ = [
    "EFFECTS",
    "BModeSettings",
    "NeedleView",
    "needle_views",
    "render_frame",
    "render_samples",
    "true_tip_px",
]

#: The switches of :class:`BModeSettings`, one per effect.
EFFECTS = (
    "speckle",
    "shaft",
    "tip",
    "beam_thickness",
    "shadow",
    "attenuation",
    "tgc",
    "noise",
    "log_compression",
    "sector",
)
_FWHM_TO_SD = 1.0 / np.sqrt(8.0 * np.log(2.0))
#: Weakest elevational weight drawn: beyond it (1.58 FWHM off the plane) the needle's echo is
#: 60 dB below its in-plane echo, below the dynamic range.
_MIN_BEAM_WEIGHT = 1e-3
#: Points along the visible shaft that cast its shadow: the shadow is smooth over the rod's 1.27 mm width,
#: and the visible part is a few millimetres long in the beam (more add only time).
_SHADOW_POINTS = 16


@dataclass(frozen=True)
class BModeSettings:
    """How a frame is rendered: one switch per effect (:data:`EFFECTS`) and its parameters.

    See the module docstring for what each effect models and where its figure comes from. Levels
    are dB re full white (envelope 1); lengths metres; ``psf_fwhm_m`` is (lateral, axial).

    Raises:
        InputError: a switch that is not True/False, or a parameter outside its range (named).
    """

    seed: int = 0
    speckle: bool = True
    shaft: bool = True
    tip: bool = True
    beam_thickness: bool = True
    shadow: bool = True
    attenuation: bool = True
    tgc: bool = True
    noise: bool = True
    log_compression: bool = True
    sector: bool = True
    frequency_hz: float = 6.5e6
    psf_fwhm_m: tuple[float, float] = (0.8e-3, 0.35e-3)
    tissue_level_db: float = -35.0
    needle_level_db: float = -8.0
    tip_level_db: float = -2.0
    needle_diameter_m: float = 1.27e-3
    needle_length_m: float = 0.2
    elevation_fwhm_m: float = 1.5e-3
    shadow_db: float = 20.0
    attenuation_db_cm_mhz: float = 0.5
    tgc_fraction: float = 0.9
    noise_level_db: float = -80.0
    dynamic_range_db: float = 60.0
    apex_px: tuple[float, float] = (DEFAULT_IMAGE_SIZE_PX[0] / 2, 0.0)
    radius_m: float = 0.070
    angle_rad: float = float(np.radians(120.0))

    def __post_init__(self) -> None:
        check_seed(self.seed, "B-mode seed")
        for name in EFFECTS:
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputError(f"B-mode setting {name} must be True or False, got {getattr(self, name)!r}")
        check_range(self.frequency_hz, "B-mode frequency_hz", low=1e6, high=50e6, unit="Hz")
        for k, what in enumerate(("lateral", "axial")):
            check_range(self.psf_fwhm_m[k], f"B-mode {what} PSF width", low=1e-5, high=1e-2, unit="m")
        for name in ("tissue_level_db", "needle_level_db", "tip_level_db", "noise_level_db"):
            check_range(getattr(self, name), f"B-mode {name}", low=-200.0, high=40.0, unit="dB")
        check_range(self.needle_diameter_m, "B-mode needle diameter", low=0.0, high=1e-2, low_open=True, unit="m")
        check_range(self.needle_length_m, "B-mode needle length", low=0.0, high=1.0, low_open=True, unit="m")
        check_range(self.elevation_fwhm_m, "B-mode elevation FWHM", low=0.0, high=2e-2, low_open=True, unit="m")
        check_range(self.shadow_db, "B-mode shadow depth", low=0.0, high=120.0, unit="dB")
        check_range(self.attenuation_db_cm_mhz, "B-mode attenuation", low=0.0, high=10.0, unit="dB/(cm MHz)")
        check_range(self.tgc_fraction, "B-mode TGC fraction", low=0.0, high=1.0)
        check_range(self.dynamic_range_db, "B-mode dynamic range", low=1.0, high=200.0, unit="dB")
        check_range(self.radius_m, "B-mode sector radius", low=0.0, high=1.0, low_open=True, unit="m")
        check_range(self.angle_rad, "B-mode sector angle", low=0.0, high=np.pi, low_open=True, unit="rad")

    def only(self, *effects: str) -> BModeSettings:
        """The same parameters with only ``effects`` switched on (the others off)."""
        unknown = set(effects) - set(EFFECTS)
        if unknown:
            raise InputError(f"unknown B-mode effect(s) {', '.join(sorted(unknown))}; choose from {', '.join(EFFECTS)}")
        switches: dict[str, Any] = {name: name in effects for name in EFFECTS}
        return dataclasses.replace(self, **switches)

    def without(self, *effects: str) -> BModeSettings:
        """The same settings with ``effects`` switched off."""
        return self.only(*(name for name in EFFECTS if getattr(self, name) and name not in effects))


@dataclass(frozen=True)
class NeedleView:
    """The needle as the image sees it: tip and direction in ``us_image``.

    Attributes:
        tip_I_m: ``(3,)`` the tip in the image frame, metres (``z``: its distance from the plane).
        direction_I: ``(3,)`` unit vector along the shaft towards the tip (the insertion direction).
    """

    tip_I_m: FloatArray
    direction_I: FloatArray


def _levels(db: float) -> float:
    return float(10.0 ** (db / 20.0))


def _kernel(sd_px: float) -> FloatArray:
    half = max(1, int(np.ceil(3.0 * sd_px)))
    x = np.arange(-half, half + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sd_px) ** 2)
    return (k / k.sum()).astype(np.float32)


def _speckle(rng: np.random.Generator, shape: tuple[int, int], sd_px: tuple[float, float]) -> np.ndarray:
    """``(H, W)`` Rayleigh envelope of mean 1, correlated over a Gaussian PSF (SDs (lateral, axial) px)."""
    from scipy.ndimage import correlate1d  # lazy: start-up (scipy)

    k_lat, k_ax = _kernel(sd_px[0]), _kernel(sd_px[1])
    field = rng.standard_normal((2, *shape), dtype=np.float32)
    field = correlate1d(field, k_lat, axis=2, mode="wrap")
    field = correlate1d(field, k_ax, axis=1, mode="wrap")
    # Each component has variance sum(k_lat²)·sum(k_ax²); a Rayleigh of that sigma has mean sigma·sqrt(pi/2).
    sigma = np.sqrt(float(np.sum(k_lat.astype(float) ** 2) * np.sum(k_ax.astype(float) ** 2)))
    envelope = np.hypot(field[0], field[1])
    envelope *= np.float32(1.0 / (sigma * np.sqrt(np.pi / 2.0)))
    return envelope


def render_frame(
    needle: NeedleView | None,
    spacing_m: ArrayLike = DEFAULT_SPACING_M,
    settings: BModeSettings = BModeSettings(),
    *,
    size_px: tuple[int, int] = DEFAULT_IMAGE_SIZE_PX,
    frame_index: int = 0,
    echoes: Callable[[np.ndarray, tuple[int, int], tuple[float, float], FloatArray], None] | None = None,
) -> np.ndarray:
    """One B-mode-like frame ``(H, W)`` uint8 (``frame[v, u]``) of ``needle`` (``None``: no needle).

    Args:
        needle: the needle's tip and direction in ``us_image`` (metres), or ``None``.
        spacing_m: ``(2,)`` metres of the medium per displayed pixel ``(s_u, s_v)`` (the twin's true
            spacing: a depth pixel of water is 1482/1540 of the nominal one).
        settings: the effects and their parameters (:class:`BModeSettings`).
        size_px: ``(width, height)``.
        frame_index: which frame of ``settings.seed`` this is: the random effects draw from the
            streams of ``(seed, frame_index)``, so frames differ and each is reproducible.
        echoes: other reflectors (e.g. a phantom's faces,
            :func:`~brachycal.studies.phantom_images.render_wedge_frame`): called as
            ``echoes(envelope, origin_px, spacing_m, psf_sd_m)`` to add their linear echo to the
            envelope in place (``envelope[0, 0]`` is pixel ``origin_px`` ``(u, v)``; ``psf_sd_m``
            ``(lateral, axial)`` SDs), before the depth gains, noise and compression apply.
    """
    s = settings
    width, height = int(size_px[0]), int(size_px[1])
    su, sv = (float(x) for x in np.asarray(spacing_m, dtype=float))
    speckle_rng, noise_rng = (
        np.random.default_rng(child) for child in np.random.SeedSequence([s.seed, frame_index]).spawn(2)
    )
    psf_sd_m = np.asarray(s.psf_fwhm_m) * _FWHM_TO_SD  # (lateral, axial)
    geometry = _geometry(width, height, su, sv, _geometry_key(s))
    u0, v0, u1, v1 = geometry.box
    shape = (v1 - v0, u1 - u0)

    tissue = _levels(s.tissue_level_db)
    if s.speckle:
        envelope = _speckle(speckle_rng, shape, (psf_sd_m[0] / su, psf_sd_m[1] / sv))
        envelope *= np.float32(tissue)
    else:
        envelope = np.full(shape, tissue, dtype=np.float32)
    if needle is not None:
        _draw_needle(envelope, (u0, v0), needle, (su, sv), psf_sd_m, s)
    if echoes is not None:
        echoes(envelope, (u0, v0), (su, sv), psf_sd_m)
    if geometry.echo_gain is not None:
        envelope *= geometry.echo_gain
    if s.noise:
        n = noise_rng.standard_normal((2, *shape), dtype=np.float32)
        noise = np.hypot(n[0], n[1])
        noise *= np.float32(_levels(s.noise_level_db) / np.sqrt(np.pi / 2.0))
        if geometry.noise_gain is not None:
            noise *= geometry.noise_gain
        envelope += noise
    if s.log_compression:
        np.maximum(envelope, np.float32(1e-12), out=envelope)
        grey = np.log10(envelope)
        grey *= np.float32(20.0 * 255.0 / s.dynamic_range_db)
        grey += np.float32(255.0 + 0.5)
    else:
        grey = envelope * np.float32(255.0)
        grey += np.float32(0.5)
    np.clip(grey, 0, 255, out=grey)
    frame = np.zeros((height, width), dtype=np.uint8)
    inside = grey.astype(np.uint8)
    if geometry.outside is not None:
        inside[geometry.outside] = 0
    frame[v0:v1, u0:u1] = inside
    return frame


@dataclass(frozen=True)
class _Geometry:
    """What every frame of one size, spacing and set-up shares: the rendered box ``(u0, v0, u1, v1)``
    (the sector's bounding box, or the whole frame), the pixels of the box outside the sector, and
    the depth gains of echoes (attenuation and TGC) and of receiver noise (TGC), ``(v1-v0, u1-u0)``."""

    box: tuple[int, int, int, int]
    outside: np.ndarray | None
    echo_gain: np.ndarray | None
    noise_gain: np.ndarray | None


def _geometry_key(s: BModeSettings) -> tuple:
    return (
        s.sector,
        s.attenuation,
        s.tgc,
        s.noise,
        s.apex_px,
        s.radius_m,
        s.angle_rad,
        s.attenuation_db_cm_mhz,
        s.frequency_hz,
        s.tgc_fraction,
    )


@functools.lru_cache(maxsize=8)
def _geometry(width: int, height: int, su: float, sv: float, key: tuple) -> _Geometry:
    sector, attenuation, tgc, noise, apex_px, radius_m, angle_rad, alpha, frequency_hz, tgc_fraction = key
    au, av = apex_px
    u0, v0, u1, v1 = 0, 0, width, height
    if sector:
        half = angle_rad / 2
        reach = radius_m * np.array([np.sin(min(half, np.pi / 2)), 1.0])
        u0 = int(np.clip(np.floor(au - reach[0] / su) - 1, 0, width))
        u1 = int(np.clip(np.ceil(au + reach[0] / su) + 2, 0, width))
        v0 = int(np.clip(np.floor(av + min(0.0, radius_m * np.cos(half)) / sv) - 1, 0, height))
        v1 = int(np.clip(np.ceil(av + reach[1] / sv) + 2, 0, height))
        u1, v1 = max(u1, u0), max(v1, v0)
    cols = ((np.arange(u0, u1, dtype=np.float32) - au) * su)[None, :]
    rows = ((np.arange(v0, v1, dtype=np.float32) - av) * sv)[:, None]
    depth_m = np.hypot(cols, rows)  # distance from the apex
    outside = None
    if sector:
        outside = (depth_m > radius_m) | (np.arctan2(np.abs(cols), rows) > angle_rad / 2)
    loss_db_per_m = 2.0 * alpha * 100.0 * frequency_hz / 1e6  # round trip
    gain_db_per_m = loss_db_per_m * tgc_fraction if tgc else 0.0
    net_db_per_m = gain_db_per_m - loss_db_per_m if attenuation else gain_db_per_m

    def gain(db_per_m: float) -> np.ndarray | None:
        return np.power(np.float32(10.0), depth_m * np.float32(db_per_m / 20.0)) if db_per_m else None

    arrays = [outside, gain(net_db_per_m), gain(gain_db_per_m) if noise else None]
    for a in arrays:
        if a is not None:
            a.setflags(write=False)
    return _Geometry((u0, v0, u1, v1), *arrays)


def _beam(z_m: FloatArray, s: BModeSettings, *, one_way: bool = False) -> FloatArray:
    """Elevational weight of echoes at elevation ``z_m`` (pulse-echo, or one-way: twice as wide in dB)."""
    if not s.beam_thickness:
        return np.ones_like(z_m)
    fwhm = s.elevation_fwhm_m * (np.sqrt(2.0) if one_way else 1.0)
    return np.exp(-4.0 * np.log(2.0) * (z_m / fwhm) ** 2)


def _visible_span(needle: NeedleView, s: BModeSettings) -> tuple[float, float] | None:
    """The part ``[t0, t1]`` of the shaft (``t`` metres back from the tip) whose echo is drawn."""
    z0, dz = float(needle.tip_I_m[2]), float(needle.direction_I[2])
    t0, t1 = 0.0, s.needle_length_m
    if s.beam_thickness:
        reach = s.elevation_fwhm_m * np.sqrt(np.log(1.0 / _MIN_BEAM_WEIGHT) / (4.0 * np.log(2.0)))
        # z(t) = z0 - t·dz must stay within ±reach.
        if abs(dz) < 1e-12:
            return (t0, t1) if abs(z0) <= reach else None
        a, b = sorted(((z0 - reach) / dz, (z0 + reach) / dz))
        t0, t1 = max(t0, a), min(t1, b)
    return (t0, t1) if t1 >= t0 else None


def _draw_needle(
    envelope: np.ndarray,
    origin_px: tuple[int, int],
    needle: NeedleView,
    spacing: tuple[float, float],
    psf_sd_m: FloatArray,
    s: BModeSettings,
) -> None:
    """Add the shaft's and the tip's echoes and the shadow to ``envelope`` (in place, in the needle's
    bounding box); ``envelope[0, 0]`` is the pixel ``origin_px`` ``(u, v)`` of the frame."""
    if not (s.shaft or s.tip or s.shadow):
        return
    ou, ov = origin_px
    height, width = envelope.shape
    su, sv = spacing
    tip = np.asarray(needle.tip_I_m, dtype=float)
    d = np.asarray(needle.direction_I, dtype=float)
    d = d / np.linalg.norm(d)
    span = _visible_span(needle, s)
    # The echo's blur: the PSF widened by the needle's cross-section (radius as a further SD).
    sd = np.sqrt(psf_sd_m**2 + (s.needle_diameter_m / 4.0) ** 2)
    margin = 4.0 * sd
    t_ends = np.array(span if span is not None else (0.0, 0.0))
    ends = tip[None, :2] - t_ends[:, None] * d[None, :2]  # (2, 2) metres in the plane
    lo = np.floor((ends.min(axis=0) - margin) / (su, sv)).astype(int)
    hi = np.ceil((ends.max(axis=0) + margin) / (su, sv)).astype(int)
    u0, v0 = max(lo[0], ou), max(lo[1], ov)
    u1, v1 = min(hi[0], ou + width - 1), min(hi[1], ov + height - 1)
    if s.shadow and span is not None:  # first: it darkens the tissue behind the needle, not the needle's echo
        _cast_shadow(envelope, origin_px, tip, d, span, spacing, psf_sd_m, s)
    if span is not None and u1 >= u0 and v1 >= v0 and (s.shaft or s.tip):
        x = (np.arange(u0, u1 + 1) * su)[None, :]
        y = (np.arange(v0, v1 + 1) * sv)[:, None]
        echo = np.zeros((v1 - v0 + 1, u1 - u0 + 1))
        if s.shaft:
            back = -d[:2]
            length2 = float(back @ back)
            if length2 > 1e-12:  # the shaft projects to a segment
                t = ((x - tip[0]) * back[0] + (y - tip[1]) * back[1]) / length2
                t = np.clip(t, span[0], span[1])
            else:  # along the image normal: the shaft projects to the tip's point
                t = np.full(echo.shape, span[0])
            dx = x - (tip[0] + t * back[0])
            dy = y - (tip[1] + t * back[1])
            weight = _beam(tip[2] - t * d[2], s)
            echo += _levels(s.needle_level_db) * weight * np.exp(-0.5 * ((dx / sd[0]) ** 2 + (dy / sd[1]) ** 2))
        if s.tip:
            weight_tip = float(_beam(np.array(tip[2]), s))
            echo += (
                _levels(s.tip_level_db)
                * weight_tip
                * np.exp(-0.5 * (((x - tip[0]) / sd[0]) ** 2 + ((y - tip[1]) / sd[1]) ** 2))
            )
        envelope[v0 - ov : v1 + 1 - ov, u0 - ou : u1 + 1 - ou] += echo.astype(np.float32)


def _cast_shadow(
    envelope: np.ndarray,
    origin_px: tuple[int, int],
    tip: FloatArray,
    d: FloatArray,
    span: tuple[float, float],
    spacing: tuple[float, float],
    psf_sd_m: FloatArray,
    s: BModeSettings,
) -> None:
    """Darken the echoes beyond the needle along the rays from the apex (in place; ``envelope[0, 0]``
    is the pixel ``origin_px``)."""
    ou, ov = origin_px
    height, width = envelope.shape
    su, sv = spacing
    apex = np.array(s.apex_px) * (su, sv)
    t = np.linspace(span[0], span[1], _SHADOW_POINTS if span[1] > span[0] else 1)
    points = tip[None, :] - t[:, None] * d[None, :]  # (K, 3)
    rel = points[:, :2] - apex
    r_k = np.hypot(rel[:, 0], rel[:, 1])
    theta_k = np.arctan2(rel[:, 0], rel[:, 1])
    cover_k = _beam(points[:, 2], s, one_way=True)
    keep = (cover_k > _MIN_BEAM_WEIGHT) & (rel[:, 1] > 0)  # rays go down from the apex: nothing above it is imaged
    if not np.any(keep):
        return
    r_k, theta_k, cover_k = r_k[keep], theta_k[keep], cover_k[keep]
    half_width = s.needle_diameter_m / 2 + 3 * psf_sd_m[0]
    # Bounding box of the shadow: from the needle's shallowest point to the bottom, between the
    # rays through its lateral extremes (widened by the rod's half-width at the deepest row).
    widest = max(abs(ou * su - apex[0]), abs((ou + width - 1) * su - apex[0]))
    bottom = np.hypot(widest, (ov + height - 1) * sv - apex[1])
    spread = half_width / max(float(r_k.min()), 1e-6)
    lo_t, hi_t = float(theta_k.min()) - spread, float(theta_k.max()) + spread
    v0 = max(int(np.floor((float(points[keep, 1].min()) - 4 * psf_sd_m[1]) / sv)), ov)
    xs = apex[0] + np.outer([r_k.min(), bottom], np.sin([lo_t, hi_t])).ravel()
    u0 = max(int(np.floor(xs.min() / su)) - 1, ou)
    u1 = min(int(np.ceil(xs.max() / su)) + 1, ou + width - 1)
    if u1 < u0 or v0 >= ov + height:
        return
    x = (np.arange(u0, u1 + 1) * su - apex[0])[None, :]
    y = (np.arange(v0, ov + height) * sv - apex[1])[:, None]
    r = np.hypot(x, y)
    theta = np.arctan2(x, y)
    from scipy.special import erf  # lazy: start-up (scipy)

    blocked = np.zeros(r.shape)
    sd_lateral = s.needle_diameter_m * _FWHM_TO_SD  # a rod of that diameter covers the ray's width
    for rk, tk, ck in zip(r_k, theta_k, cover_k, strict=True):
        lateral = rk * (theta - tk)
        beyond = 0.5 * (1.0 + erf((r - rk) / (np.sqrt(2.0) * psf_sd_m[1])))
        np.maximum(blocked, ck * beyond * np.exp(-0.5 * (lateral / sd_lateral) ** 2), out=blocked)
    depth = 1.0 - _levels(-s.shadow_db)
    envelope[v0 - ov :, u0 - ou : u1 + 1 - ou] *= (1.0 - depth * blocked).astype(np.float32)


# --- the twin's frames ----------------------------------------------------------------------------
def needle_views(twin: Twin) -> list[NeedleView]:
    """The needle of each of the twin's samples as its image sees it (true joints, physical robot).

    The shaft is the needle tip frame's z axis (:class:`~brachycal.planning.PlanSpec`'s insertion
    direction).
    """
    views = []
    for q in twin.true_samples_q:
        T_I_Ntip = np.linalg.solve(twin.physical.fk(US_IMAGE, q), twin.physical.fk(NEEDLE_TIP, q))
        views.append(NeedleView(np.array(T_I_Ntip[:3, 3], dtype=float), np.array(T_I_Ntip[:3, 2], dtype=float)))
    return views


def true_tip_px(twin: Twin) -> FloatArray:
    """``(N, 2)`` where each sample's needle tip truly shows, pixels (its in-plane projection over the
    true spacing: what a perfect annotation gives)."""
    return np.array([view.tip_I_m[:2] / twin.truth.spacing_m for view in needle_views(twin)])


def render_samples(
    twin: Twin, settings: BModeSettings = BModeSettings(), samples: Sequence[int] | np.ndarray | None = None
) -> np.ndarray:
    """``(M, H, W)`` uint8 frames of the twin's samples (``samples``: which, with repeats; default
    each once), frame ``m`` drawn from the streams of ``(settings.seed, m)``."""
    views = needle_views(twin)
    which = range(len(views)) if samples is None else samples
    size = tuple(int(x) for x in twin.truth.size_px)
    frames = [
        render_frame(views[k], twin.truth.spacing_m, settings, size_px=(size[0], size[1]), frame_index=m)
        for m, k in enumerate(which)
    ]
    return np.stack(frames) if frames else np.zeros((0, size[1], size[0]), dtype=np.uint8)
