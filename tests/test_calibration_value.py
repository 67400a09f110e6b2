"""The ``Calibration`` value: what every consumer takes, the same whether computed or read back.

A calibration written to a result file and read back is the calibration it was written from (to
1e-12: the file stores the transforms' decimal text), and the consumers give the same numbers
through the value as through the loose transforms they took before.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from brachycal.calibration import calibrate, read_result, write_result
from brachycal.calibration.result import Calibration, locate
from brachycal.calibration.sequential import image_to_probe

METHODS = ("kabsch", "horn")


@pytest.fixture(scope="module")
def result(exact, robot):
    return calibrate(exact, robot, methods=METHODS)


@pytest.fixture(scope="module")
def stored(result, robot, tmp_path_factory):
    path = tmp_path_factory.mktemp("result") / "result.json"
    write_result(result, path, robot=robot)
    return read_result(path)


@pytest.mark.parametrize("method", [*METHODS, None])
def test_a_result_file_gives_back_the_calibration_it_was_written_from(result, stored, method):
    written, read = result.calibration(method), stored.calibration(method)
    assert read.method == written.method
    assert read.max_difference(written) <= 1e-12


def test_the_default_method_is_the_result_files_best_method(result, stored):
    assert result.calibration().method == stored.best_method() == stored.calibration().method


def test_provenance_names_the_file_and_the_session_inputs(result, stored):
    calibration = stored.calibration()
    assert calibration.provenance.source == stored.source
    assert calibration.provenance.sha256 == stored.sha256 and len(stored.sha256) == 64
    assert dict(calibration.provenance.inputs) == result.inputs == dict(result.calibration().provenance.inputs)


def test_a_calibration_cannot_be_changed(stored):
    calibration = stored.calibration()
    with pytest.raises(dataclasses.FrozenInstanceError):
        calibration.T_EL_Ptip = np.eye(4)  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        calibration.T_ER_Ntip[0, 3] = 1.0


def test_max_difference_sees_a_moved_tool(stored):
    calibration = stored.calibration()
    moved = calibration.T_ER_Ntip.copy()
    moved[2, 3] += 1e-6
    assert dataclasses.replace(calibration, T_ER_Ntip=moved).max_difference(calibration) == pytest.approx(1e-6)
    assert dataclasses.replace(calibration, image=stored.image["horn"]).max_difference(
        stored.calibration("kabsch")
    ) == float("inf")


def test_locate_through_the_value_is_the_loose_form(robot, exact, stored):
    calibration = stored.calibration("kabsch")
    q, uv = exact.samples_q, exact.uv_px
    loose = image_to_probe.predict_base(
        stored.image["kabsch"], robot.fk(robot.rig.probe_flange, q), stored.T_EL_Ptip, uv
    )
    np.testing.assert_array_equal(locate(robot, q, uv, calibration), loose)


def test_the_loose_locate_still_works_for_one_release_and_warns(robot, exact, stored):
    from brachycal.calibration import locate as sequential_locate

    calibration = stored.calibration("kabsch")
    q, uv = exact.samples_q[:3], exact.uv_px[:3]
    with pytest.warns(DeprecationWarning, match="pass one Calibration"):
        loose = sequential_locate(robot, q, uv, stored.T_EL_Ptip, stored.image["kabsch"])
    np.testing.assert_array_equal(sequential_locate(robot, q, uv, calibration), loose)


def test_the_calibrated_robot_carries_the_values_frames(robot, exact, stored):
    from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE

    calibration = stored.calibration()
    shown = calibration.robot(robot)
    q = exact.samples_q[0]
    T_R_EL = robot.fk(robot.rig.probe_flange, q)
    np.testing.assert_allclose(shown.fk(PROBE_TIP, q), T_R_EL @ calibration.T_EL_Ptip, atol=1e-12)
    np.testing.assert_allclose(shown.fk(US_IMAGE, q), T_R_EL @ calibration.T_EL_Ptip @ calibration.T_Ptip_I, atol=1e-12)
    T_R_ER = robot.fk(robot.rig.needle_flange, q)
    np.testing.assert_allclose(shown.fk(NEEDLE_TIP, q), T_R_ER @ calibration.T_ER_Ntip, atol=1e-12)


def test_a_calibration_is_the_public_type(stored):
    assert isinstance(stored.calibration(), Calibration)


def test_the_old_image_on_probe_spelling_still_reads_for_one_release():
    from brachycal.calibration import NWireResult

    T = np.eye(4)
    T[:3, 3] = [0.01, 0.02, 0.03]
    nwire = NWireResult(T, np.array([1e-4, 1e-4]), T, np.ones(3, dtype=bool), np.zeros(3))
    with pytest.warns(DeprecationWarning, match="use T_Ptip_I"):
        old = nwire.T_probe_image
    assert old is nwire.T_Ptip_I


def test_a_chain_result_file_gives_back_the_chains_calibration(session_dir, robot, tmp_path):
    from brachycal.calibration import calibrate_folder

    calibrated = calibrate_folder(session_dir, robot, ("kabsch",), chain=True)
    path = write_result(calibrated.result, tmp_path / "chain.json", chain=calibrated.chain, robot=robot)
    stored = read_result(path)
    assert stored.best_method() == "chain" == calibrated.calibration().method
    assert stored.calibration().max_difference(calibrated.calibration()) <= 1e-12
    assert calibrated.calibration("kabsch").method == "kabsch"  # the file keeps it under "sequential" only
    assert calibrated.chain is not None
    fit = calibrated.chain.fit
    np.testing.assert_array_equal(calibrated.calibration().T_EL_Ptip, fit.T_EL_Ptip)
