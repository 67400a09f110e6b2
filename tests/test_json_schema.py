"""The one check every result file brachycal reads goes through (``data/json_schema.py``).

Specifications:
- PLUS's own Image → Probe matrices (pixels → mm: its stepper calibration's affine, 1.5° off square
  pixels, and two of its fCal refinements) are accepted; the same matrices with one element
  corrupted (a shear, a column scaled, a mirrored image, a translation a terametre away) are
  refused, naming the place in the document;
- the readers of ``brachycal-nwire/1``, its stepper block and ``brachycal-stepper/1`` accept what
  brachycal writes from files of different origin: the bundled stepper twin, and exact synthetic
  frames (PLUS's recordings: ``test_trus_probe``).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, reference

from brachycal.calibration.phantom.stepper_probe import read_calibrated_axes, read_stepper_image
from brachycal.cli.main import main
from brachycal.data.formats.plus_files import read_coordinate_definitions
from brachycal.data.json_schema import Where, image_to_probe_mm
from brachycal.errors import InputError
from brachycal.studies.stepper_twin import STEPPER_NAMES

PLUS_MATRICES = (
    ("plus_trus_stepper", "UsTemplateCalibration_3NWires.results.xml"),
    ("plus_nwire_variants", "OPEA_OptimizationMethod_Calibration.results.xml"),
    ("plus_nwire_variants", "OPEI_OptimizationMethod_Calibration.results.xml"),
)


def plus_image_to_probe(folder: str, name: str) -> np.ndarray:
    return read_coordinate_definitions(reference(folder, name))["Image", "Probe"]


def check(M: np.ndarray) -> None:
    image_to_probe_mm(np.asarray(M).tolist(), Where("result.json", "models.affine.image_to_probe_mm"))


@pytest.mark.parametrize("source", PLUS_MATRICES, ids=lambda s: s[1].split("_")[0])
def test_plus_s_own_image_to_probe_matrices_are_accepted(source):
    check(plus_image_to_probe(*source))


@pytest.mark.parametrize(
    ("row", "column", "value", "problem"),
    [
        (0, 1, 5.0, "v column is 5"),  # the stepper result's shear of 42 mm at the needle
        (1, 0, 0.03, "off a right angle"),  # a shear within the spacing range
        (2, 2, 5.0, "normal column is 5"),
        (0, 3, 1e12, "translation of 1e+12 mm"),
        (3, 0, 0.1, "last row"),
    ],
)
def test_a_corrupted_image_to_probe_is_refused_naming_the_place(row, column, value, problem):
    M = plus_image_to_probe(*PLUS_MATRICES[0])
    M[row, column] = value
    with pytest.raises(
        InputError, match=rf"result\.json, column 'models\.affine\.image_to_probe_mm': .*{re.escape(problem)}"
    ):
        check(M)


def test_a_mirrored_image_to_probe_is_refused():
    M = plus_image_to_probe(*PLUS_MATRICES[0])
    M[:3, 2] *= -1.0
    with pytest.raises(InputError, match="left-handed"):
        check(M)


def test_the_readers_accept_what_brachycal_writes_from_the_bundled_twin(tmp_path):
    s = {key: str(ROOT / "examples" / name) for key, name in STEPPER_NAMES.items()}
    calibrate = ["stepper", "calibrate", s["rotation"], s["probe_translation"], s["template_translation"]]
    assert main([*calibrate, "--config", s["config"], "--out", str(tmp_path / "stepper.json"), "--quiet"]) == 0
    image = ["stepper", "image", s["rotation"], s["calibration"], s["validation"], "--config", s["config"]]
    assert main([*image, "--out", str(tmp_path / "image.json"), "--stepper", str(tmp_path / "stepper.json")]) == 0
    written = json.loads((tmp_path / "stepper.json").read_text())
    axes = read_calibrated_axes(tmp_path / "stepper.json")
    np.testing.assert_array_equal(axes.probe_translation, written["probe_translation_axis"]["plus_orientation"])
    stored = read_stepper_image(tmp_path / "image.json")
    np.testing.assert_array_equal(stored.axes.probe_translation, axes.probe_translation)
    raw = json.loads(Path(tmp_path / "image.json").read_text())
    np.testing.assert_allclose(
        stored.image_to_probe[:3] * 1e3, np.array(raw["models"][raw["model"]]["image_to_probe_mm"])[:3]
    )
