"""The twin's B-mode frames: seeded, and each effect present when on and absent when off."""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.errors import InputError
from brachycal.simulation.bmode import EFFECTS, BModeSettings, NeedleView, render_frame

DEFAULTS = BModeSettings()
SPACING = (0.19e-3, 0.19e-3)
SIZE = (1080, 720)
#: The needle as the SDA10F's plan sees it: crossing the plane at 35 deg and advancing in depth,
#: its tip at pixel (540, 200).
TIP_PX = np.array([540.0, 200.0])


def needle(elevation_m: float = 0.0) -> NeedleView:
    tip = np.array([TIP_PX[0] * SPACING[0], TIP_PX[1] * SPACING[1], elevation_m])
    return NeedleView(tip, np.array([0.0, np.cos(np.radians(35.0)), np.sin(np.radians(35.0))]))


def render(settings: BModeSettings, view: NeedleView | None = None, index: int = 0) -> np.ndarray:
    return render_frame(view, SPACING, settings, size_px=SIZE, frame_index=index)


def grey(db: float) -> float:
    """The grey level of an envelope ``db`` re white after log compression (the default 60 dB range)."""
    return 255.0 * (db + DEFAULTS.dynamic_range_db) / DEFAULTS.dynamic_range_db


def test_the_same_seed_gives_the_same_frame_and_other_seeds_or_frames_differ():
    a = render(BModeSettings(seed=3), needle(), index=5)
    assert a.shape == (SIZE[1], SIZE[0]) and a.dtype == np.uint8
    assert np.array_equal(a, render(BModeSettings(seed=3), needle(), index=5))
    assert not np.array_equal(a, render(BModeSettings(seed=4), needle(), index=5))
    assert not np.array_equal(a, render(BModeSettings(seed=3), needle(), index=6))


def test_switching_the_noise_off_leaves_the_speckle_draws_unchanged():
    only_speckle = BModeSettings().only("speckle")
    with_noise = BModeSettings().only("speckle", "noise")
    a, b = render(only_speckle), render(with_noise)
    # The receiver noise (-80 dB, no TGC gain here) is 45 dB under the tissue: it changes a grey
    # level by at most one step (rounding), and only because the speckle underneath is the same.
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 1


def test_with_every_effect_off_the_background_is_the_tissue_level_everywhere():
    frame = render(BModeSettings().only())  # no log compression either: 255 x the envelope
    assert np.all(frame == round(255 * 10 ** (BModeSettings().tissue_level_db / 20)))
    frame = render(BModeSettings().only("log_compression"))
    assert np.all(frame == round(grey(BModeSettings().tissue_level_db)))


def test_speckle_is_rayleigh_with_a_grain_wider_than_deep():
    frame = render(BModeSettings().only("speckle", "log_compression")).astype(float)
    # 20·log10 of a Rayleigh variable has SD 5.57 dB whatever its scale (sqrt(pi²/24) nepers) and
    # mean 20·log10(its mean) − 1.46 dB; ~10^5 speckle grains put the estimates within 3 % and 0.2 dB.
    sd_db = frame.std() * 60.0 / 255.0
    assert sd_db == pytest.approx(5.57, rel=0.03)
    mean_db = frame.mean() * 60.0 / 255.0 - 60.0
    assert mean_db == pytest.approx(-35.0 - 1.46, abs=0.2)
    centred = frame - frame.mean()

    def correlation(du: int, dv: int) -> float:
        a = centred[: centred.shape[0] - dv, : centred.shape[1] - du]
        b = centred[dv:, du:]
        return float((a * b).mean() / centred.var())

    # PSF FWHM 0.8 mm laterally, 0.35 mm axially (4.2 and 1.8 px): neighbours along u are much more alike.
    assert correlation(1, 0) > correlation(0, 1) + 0.2
    assert abs(correlation(30, 0)) < 0.05 and abs(correlation(0, 30)) < 0.05


def test_without_the_needles_echoes_and_shadow_the_frame_is_the_frame_without_a_needle():
    settings = BModeSettings().without("shaft", "tip", "shadow")
    assert np.array_equal(render(settings, needle()), render(settings, None))


def test_the_tip_is_the_brightest_point_and_it_fades_as_it_leaves_the_plane():
    settings = BModeSettings().only("tip", "beam_thickness", "log_compression")
    frame = render(settings, needle())
    v, u = np.unravel_index(np.argmax(frame), frame.shape)
    assert (u, v) == tuple(TIP_PX.astype(int))

    # The tip's echo adds to the tissue's (one grey level is 0.24 dB: rounding only).
    def tip_grey(weight: float) -> float:
        return grey(20 * np.log10(weight * 10 ** (settings.tip_level_db / 20) + 10 ** (settings.tissue_level_db / 20)))

    assert frame.max() == pytest.approx(tip_grey(1.0), abs=1)
    # Pulse-echo elevational profile, FWHM 1.5 mm: at 0.75 mm off the plane the echo is at half; at
    # 1.5 mm at 1/16.
    for z, weight in ((0.75e-3, 0.5), (1.5e-3, 1 / 16)):
        assert render(settings, needle(z)).max() == pytest.approx(tip_grey(weight), abs=1)
    flat = settings.without("beam_thickness")
    assert render(flat, needle(1.5e-3)).max() == render(flat, needle()).max()


def test_the_shaft_shows_behind_the_tip_only_where_it_is_in_the_beam():
    settings = BModeSettings().only("shaft", "beam_thickness", "log_compression")
    frame = render(settings, needle(0.0)).astype(float)
    background = grey(settings.tissue_level_db)
    column = frame[:, int(TIP_PX[0])]
    lit = np.flatnonzero(column > background + 20)
    # The shaft runs back (shallower) from the tip; it is lit over the part within ~1 FWHM of the
    # plane: 35 deg out of the plane, |z| < 1.5 mm spans 2.6 mm of needle, 11 px of depth.
    # It ends at the tip, blurred by the PSF and the needle's radius (SD 1.8 px along v): 27 dB over
    # the tissue, it stays 20 grey levels (4.7 dB) above it up to 2.25 SD (4 px) beyond the tip.
    assert TIP_PX[1] <= lit.max() <= TIP_PX[1] + 6
    assert 5 <= len(lit) <= 25 and lit.min() < TIP_PX[1] - 4
    whole = render(settings.without("beam_thickness"), needle(0.0)).astype(float)[:, int(TIP_PX[0])]
    assert np.flatnonzero(whole > background + 20).min() == 0  # without the beam profile the shaft reaches the top


def test_the_shadow_darkens_only_beyond_the_needle():
    settings = BModeSettings().only("shadow", "beam_thickness", "log_compression")
    frame = render(settings, needle()).astype(float)
    background = grey(settings.tissue_level_db)
    u = int(TIP_PX[0])
    assert frame[int(TIP_PX[1]) + 30, u] < background - 50  # 20 dB (85 grey levels) under the needle's core
    assert frame[int(TIP_PX[1]) - 30, u] == round(background)  # above (shallower): untouched
    assert frame[int(TIP_PX[1]) + 30, u + 40] == round(background)  # beside: untouched


def test_attenuation_darkens_with_depth_and_the_tgc_restores_its_share():
    settings = BModeSettings(attenuation_db_cm_mhz=0.1).only("attenuation", "log_compression")
    frame = render(settings).astype(float)
    apex = np.array(settings.apex_px)
    # 2·0.1 dB/(cm·MHz)·6.5 MHz = 1.3 dB per cm of depth from the apex, round trip (one grey level
    # is 0.24 dB: rounding only).
    depth_cm = (600 - apex[1]) * SPACING[1] * 100
    assert frame[600, int(apex[0])] == pytest.approx(grey(settings.tissue_level_db - 1.3 * depth_cm), abs=1)
    compensated = render(settings.only("attenuation", "tgc", "log_compression")).astype(float)
    assert compensated[600, int(apex[0])] == pytest.approx(grey(settings.tissue_level_db - 0.13 * depth_cm), abs=1)
    gain_only = render(settings.only("tgc", "log_compression")).astype(float)
    assert gain_only[600, int(apex[0])] == pytest.approx(grey(settings.tissue_level_db + 1.17 * depth_cm), abs=1)


def test_the_sector_blacks_out_what_the_convex_array_does_not_image():
    settings = BModeSettings().only("sector", "log_compression")
    frame = render(settings)
    assert frame[700, 540] == 0 and frame[5, 5] == 0  # beyond the 70 mm radius; outside the 120 deg
    assert frame[200, 540] == round(grey(settings.tissue_level_db))


def test_the_noise_shows_at_depth_where_the_gain_is_high():
    settings = BModeSettings().only("noise", "attenuation", "tgc", "log_compression")
    added = render(settings).astype(float) - render(settings.without("noise")).astype(float)
    # At -80 dB the receiver noise is 45 dB under the tissue near the probe: a rounding step at
    # most; 13 cm deep the TGC has raised it by 76 dB, over the tissue (left at -43 dB by the
    # attenuation the TGC does not make up).
    assert np.abs(added[5:15, 500:580]).max() <= 1
    assert added[650:700, 500:580].mean() > 20


def test_every_effect_is_a_switch_and_bad_settings_are_refused():
    assert set(BModeSettings().only().__dict__) >= set(EFFECTS)
    with pytest.raises(InputError, match="speckle"):
        BModeSettings(speckle=1)
    with pytest.raises(InputError, match="elevation"):
        BModeSettings(elevation_fwhm_m=0.0)
    with pytest.raises(InputError, match="unknown B-mode effect"):
        BModeSettings().only("glitter")
