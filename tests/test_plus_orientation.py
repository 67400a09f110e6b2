"""PLUS recordings in any ultrasound image orientation give the same results in PLUS's MF frame.

Specifications:
- a sequence's frames are read in PLUS's MF image frame whatever its ``UltrasoundImageOrientation``:
  each real recording rewritten as UF, MN or UN (columns, rows or both reversed; in the two-letter
  and in PLUS's own three-letter spellings) reads to the original's pixels, and says how it was stored;
  a sequence without the field reads as MF; a value PLUS does not turn to MF is refused in one
  line naming the file and the field;
- every command that reads PLUS's recordings gives, on the recording rewritten in another
  orientation, the MF recording's results: `stepper calibrate` (centre within 0.01 px, spacing
  1e-4 relative, axes 0.01°, rotation encoder scale 1e-4), `stepper image` (Image→Probe and the
  phantom registration), `nwire segment` and `nwire` (the same frames segmented, the same points
  and Image→Probe), `temporal` (the lag, the line's scale with its sign); each output names its
  pixel frame. Fast tests use a subset of the frames; the whole recordings run as slow tests.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import reference
from hostile import Case, check_refusal
from plus_orientation import rewrite_orientation

from brachycal.cli.main import main
from brachycal.data.formats.metaimage import read_image_sequence
from brachycal.data.formats.plus_files import read_segmented_frames

STEPPER = "plus_trus_stepper"
ICAL = "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"
FCAL = "plus_fcal_nwire"
FCAL_CONFIG = "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
TEMPORAL = "plus_temporal"

#: The orientations a recording is rewritten in, with the field text written: PLUS's own spelling
#: for some (it writes MFA, UFD, MND, UNA), the two letters for others.
VARIANTS = [("UF", "UFD"), ("MN", "MN"), ("MN", "MND"), ("UN", "un")]
IDS = [field for _, field in VARIANTS]
SLOW = pytest.mark.slow


def variants(fast: str) -> list:
    """:data:`VARIANTS` as parameters, all but the one whose field is ``fast`` marked slow (a
    command's run on even a subset of frames takes seconds; the reader's test covers them all fast)."""
    return [pytest.param(o, f, id=f, marks=() if f == fast else (SLOW,)) for o, f in VARIANTS]


def _stepper(name: str) -> Path:
    return reference(STEPPER, f"USTC_3NWires_{name}.igs.mha")


def _rewrite(folder: Path, sources: dict[str, Path], orientation: str, field: str, step: int | None) -> list[str]:
    """``sources`` (name → MF recording) rewritten into ``folder``, every ``step``-th frame (None: all)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name, source in sources.items():
        count = read_image_sequence(source).pixels.shape[0] if step is not None else None
        frames = None if count is None else range(0, count, step)
        out.append(str(rewrite_orientation(source, folder / name, orientation, field=field, frames=frames)))
    return out


def _angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


# --- the reader ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("orientation", "field"), [("MF", "MFA"), ("MF", "MFD"), *VARIANTS])
def test_every_plus_orientation_reads_to_the_mf_frames(tmp_path, orientation, field):
    source = _stepper("ProbeRotation")
    original = read_image_sequence(rewrite_orientation(source, tmp_path / "mf.mha", "MF", frames=range(3)))
    rewritten = rewrite_orientation(source, tmp_path / "x.mha", orientation, field=field, frames=range(3))
    sequence = read_image_sequence(rewritten)
    assert not np.array_equal(original.pixels[:, ::-1], original.pixels)  # a flip would show
    np.testing.assert_array_equal(sequence.pixels, original.pixels)
    assert sequence.file_orientation == orientation
    assert f"stored {orientation}" in sequence.pixel_frame


def test_a_sequence_without_the_field_reads_as_mf(tmp_path):
    source = _stepper("ProbeRotation")
    original = read_image_sequence(rewrite_orientation(source, tmp_path / "mf.mha", "MF", frames=range(2)))
    bare = read_image_sequence(rewrite_orientation(source, tmp_path / "bare.mha", "MF", field="", frames=range(2)))
    np.testing.assert_array_equal(bare.pixels, original.pixels)
    assert bare.file_orientation is None and "no UltrasoundImageOrientation: read as MF" in bare.pixel_frame


@pytest.mark.parametrize("field", ["XYZ", "FM", "NU", "UFA", "MNA", "UND", "AMF", ""])
def test_orientations_plus_does_not_turn_to_mf_are_refused(tmp_path, field):
    """PLUS turns UFA, MNA, UND (and the transposed RF orientations) to nothing: its GetFlipAxes fails."""
    text = field or " "
    rewrite_orientation(_stepper("ProbeRotation"), tmp_path / "cal.mha", "MF", field=text, frames=range(2))
    rewrite_orientation(_stepper("ProbeRotation"), tmp_path / "val.mha", "MF", frames=range(2))
    argv = ["nwire", "segment", "{tmp}/cal.mha", "{tmp}/val.mha", "--config", str(reference(STEPPER, ICAL))]
    case = Case(field, [*argv, "--out", "{tmp}/f.xml"], ("cal.mha", "UltrasoundImageOrientation", "MF, UF, MN or UN"))
    check_refusal(case, tmp_path)


# --- stepper calibrate --------------------------------------------------------------------------------

STEPPER_CALIBRATE = {
    "USTC_3NWires_ProbeRotation.igs.mha": 4,
    "USTC_3NWires_ProbeTranslation.igs.mha": 16,
    "USTC_3NWires_TemplateTranslation.igs.mha": 20,
}


def _stepper_calibrate(folder: Path, orientation: str, field: str, whole: bool, capsys) -> dict:
    """`stepper calibrate` on PLUS's three recordings rewritten in ``orientation`` (a subset of
    their frames unless ``whole``); checks the pixel frame is named (printed too, given ``capsys``),
    returns the result file."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, step in STEPPER_CALIBRATE.items():
        source = reference(STEPPER, name)
        frames = None if whole else range(0, len(read_image_sequence(source)), step)
        paths.append(str(rewrite_orientation(source, folder / name, orientation, field=field, frames=frames)))
    out = folder / "stepper.json"
    argv = ["stepper", "calibrate", *paths, "--config", str(reference(STEPPER, ICAL)), "--out", str(out), "--quiet"]
    assert main(argv) == 0
    if capsys is not None:
        printed = capsys.readouterr().out
        assert "pixels: PLUS's MF image frame (u: columns, towards the probe's marked side" in printed
    result = json.loads(out.read_text())
    assert result["centre_of_rotation"]["pixel_frame"].startswith("PLUS's MF image frame")
    assert {r["stored_orientation"] for r in result["recordings"].values()} == {orientation}
    return result


def _same_stepper_calibration(got: dict, want: dict) -> None:
    for name in ("rotation", "probe_translation", "template_translation"):
        assert got["recordings"][name]["segmented"] == want["recordings"][name]["segmented"]
    np.testing.assert_allclose(
        got["centre_of_rotation"]["value_px"], want["centre_of_rotation"]["value_px"], rtol=0, atol=0.01
    )
    np.testing.assert_allclose(
        got["pixel_spacing"]["value_m_per_px"], want["pixel_spacing"]["value_m_per_px"], rtol=1e-4
    )
    assert abs(got["rotation_encoder"]["scale"] - want["rotation_encoder"]["scale"]) < 1e-4
    for axis in ("probe_translation_axis", "template_translation_axis"):
        assert _angle_deg(got[axis]["plus_orientation"], want[axis]["plus_orientation"]) < 0.01


@pytest.fixture(scope="module")
def stepper_calibrate_mf(tmp_path_factory):
    """`stepper calibrate` on every 4th, 16th, 20th frame of PLUS's three MF recordings."""
    return _stepper_calibrate(tmp_path_factory.mktemp("mf"), "MF", "MFA", False, None)


@pytest.mark.parametrize(("orientation", "field"), variants("MND"))
def test_stepper_calibrate_is_the_same_in_every_orientation(tmp_path, capsys, stepper_calibrate_mf, orientation, field):
    got = _stepper_calibrate(tmp_path, orientation, field, False, capsys)
    assert got["recordings"]["rotation"]["segmented"] >= 34  # of 36: the subset determines the centre
    _same_stepper_calibration(got, stepper_calibrate_mf)


@pytest.mark.slow  # segments the three recordings (524 frames) twice: ~45 s of CPU
@pytest.mark.parametrize(("orientation", "field"), [("MN", "MND"), ("UN", "UNA")])
def test_stepper_calibrate_on_whole_recordings_is_plus_s_in_every_orientation(tmp_path, capsys, orientation, field):
    """The whole recordings stored MN and UN give PLUS's baseline, as the MF recordings do."""
    want = _stepper_calibrate(tmp_path / "mf", "MF", "MFA", True, capsys)
    got = _stepper_calibrate(tmp_path / "other", orientation, field, True, capsys)
    _same_stepper_calibration(got, want)
    assert got["recordings"]["rotation"]["segmented"] == 142
    np.testing.assert_allclose(got["centre_of_rotation"]["value_px"], [414.092, 22.591], atol=0.01)
    assert got["rotation_encoder"]["plus_scale"] > 0  # PLUS's sign: +0.96


# --- stepper image --------------------------------------------------------------------------------

STEPPER_IMAGE = {
    "USTC_3NWires_ProbeRotation.igs.mha": 4,
    "USTC_3NWires_RandomStepperMotionCalibration.igs.mha": 8,
    "USTC_3NWires_RandomStepperMotionValidation.igs.mha": 8,
}


def _stepper_image(folder: Path, orientation: str, field: str, capsys) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    paths = [
        str(
            rewrite_orientation(
                reference(STEPPER, name),
                folder / name,
                orientation,
                field=field,
                frames=range(0, len(read_image_sequence(reference(STEPPER, name))), step),
            )
        )
        for name, step in STEPPER_IMAGE.items()
    ]
    out = folder / "image.json"
    assert main(["stepper", "image", *paths, "--config", str(reference(STEPPER, ICAL)), "--out", str(out)]) == 0
    if capsys is not None:
        assert "pixels: PLUS's MF image frame" in capsys.readouterr().out
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def stepper_image_mf(tmp_path_factory):
    return _stepper_image(tmp_path_factory.mktemp("mf"), "MF", "MFA", None)


@pytest.mark.parametrize(("orientation", "field"), variants("MND"))
def test_stepper_image_is_the_same_in_every_orientation(tmp_path, capsys, stepper_image_mf, orientation, field):
    want = stepper_image_mf
    got = _stepper_image(tmp_path, orientation, field, capsys)
    assert got["pixel_frame"].startswith("PLUS's MF image frame")
    assert got["calibration_points"] == want["calibration_points"]
    assert got["validation_points"] == want["validation_points"]
    np.testing.assert_allclose(got["affine_mm"], want["affine_mm"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got["T_Probe_Image"], want["T_Probe_Image"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        got["stepper"]["T_Template_Phantom"], want["stepper"]["T_Template_Phantom"], rtol=0, atol=1e-9
    )


# --- nwire segment, nwire ---------------------------------------------------------------------------

NWIRE_STEP = 10  # every 10th frame: 19 calibration frames, 11 validation frames
FCAL_SEQUENCES = ("fCal_Test_Calibration_3NWires_fCal2.0.igs.mha", "fCal_Test_Validation_3NWires_fCal2.0.igs.mha")


def _nwire(folder: Path, orientation: str, field: str, step: int | None, capsys):
    paths = _rewrite(folder, {name: reference(FCAL, name) for name in FCAL_SEQUENCES}, orientation, field, step)
    config = str(reference(FCAL, FCAL_CONFIG))
    frames = folder / "frames.xml"
    assert main(["nwire", "segment", *paths, "--config", config, "--out", str(frames), "--quiet"]) == 0
    if capsys is not None:
        assert f"stored {orientation}, turned to MF" in capsys.readouterr().out
    assert "<!-- pixels: PLUS's MF image frame" in frames.read_text()
    out = folder / "nwire.json"
    assert main(["nwire", config, str(frames), "--out", str(out)]) == 0
    if capsys is not None:
        assert "pixels: PLUS's MF image frame" in capsys.readouterr().out
    return read_segmented_frames(frames), json.loads(out.read_text())


def _same_nwire(got, want) -> None:
    (got_frames, got_result), (want_frames, want_result) = got, want
    for g_list, w_list in zip(got_frames, want_frames, strict=True):
        assert [f.ok for f in g_list] == [f.ok for f in w_list]  # the same frames segmented
        for g, w in zip(g_list, w_list, strict=True):
            assert set(g.points_px) == set(w.points_px)
            for name in w.points_px:
                np.testing.assert_allclose(g.points_px[name], w.points_px[name], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got_result["T_Probe_Image"], want_result["T_Probe_Image"], rtol=0, atol=1e-9)
    assert got_result["pixel_frame"].startswith("PLUS's MF image frame")


@pytest.fixture(scope="module")
def nwire_mf(tmp_path_factory):
    return _nwire(tmp_path_factory.mktemp("mf"), "MF", "MFA", NWIRE_STEP, None)


@pytest.mark.parametrize(("orientation", "field"), variants("UFD"))
def test_nwire_segment_and_nwire_are_the_same_in_every_orientation(tmp_path, capsys, nwire_mf, orientation, field):
    got = _nwire(tmp_path, orientation, field, NWIRE_STEP, capsys)
    assert sum(f.ok for f in nwire_mf[0][0]) >= 15  # of 19: the subset holds a calibration
    _same_nwire(got, nwire_mf)


@pytest.mark.slow  # segments the two recordings (293 frames) twice: ~30 s of CPU
def test_nwire_on_whole_recordings_is_the_same_stored_un(tmp_path, capsys):
    want = _nwire(tmp_path / "mf", "MF", "MFA", None, None)
    _same_nwire(_nwire(tmp_path / "other", "UN", "UNA", None, capsys), want)


# --- temporal ---------------------------------------------------------------------------------------


def _temporal(video: Path, capsys) -> dict:
    tracker = str(reference(TEMPORAL, "WaterTankBottomTranslationTrackerBuffer.igs.mha"))
    config = str(reference(TEMPORAL, "PlusDeviceSet_fCal_Sim_TemporalCalibration.xml"))
    out = video.with_suffix(".json")
    assert main(["temporal", str(video), tracker, "--config", config, "--out", str(out)]) == 0
    if capsys is not None:
        assert "pixels: PLUS's MF image frame" in capsys.readouterr().out
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def temporal_mf(tmp_path_factory):
    video = reference(TEMPORAL, "WaterTankBottomTranslationVideoBuffer.igs.mha")
    return _temporal(rewrite_orientation(video, tmp_path_factory.mktemp("mf") / "mf.mha", "MF", field="MFA"), None)


@pytest.mark.parametrize(("orientation", "field"), variants("MND"))
def test_temporal_is_the_same_in_every_orientation(tmp_path, capsys, temporal_mf, orientation, field):
    """The water-tank recording (the device set's clip rectangle applied) in another orientation."""
    video = reference(TEMPORAL, "WaterTankBottomTranslationVideoBuffer.igs.mha")
    got = _temporal(rewrite_orientation(video, tmp_path / "video.mha", orientation, field=field), capsys)
    want = temporal_mf
    assert got["frames"] == want["frames"]
    assert got["lag_s"] == pytest.approx(want["lag_s"], abs=1e-6)
    assert got["inverted"] == want["inverted"]
    assert got["scale"] == pytest.approx(want["scale"], rel=1e-6)  # px per m along v: its sign is MF's
    assert got["pixel_frame"].startswith("PLUS's MF image frame")
