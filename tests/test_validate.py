"""The one input validator (``brachycal.validate``) and the library entry points that use it.

What every check promises: the value comes back when it is acceptable; otherwise one
``InputError`` naming the value (an option, a field) and what is wrong. NaN and ±infinity never
pass a range check (a NaN compares False with everything, so a check written the obvious way
would let it through), and a spacing a thousand times off is named as the unit slip it is.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

import numpy as np
import pytest

from brachycal.calibration.result import Calibration, ImageCalibration
from brachycal.cli.option_types import (
    bounded_int,
    direction,
    finite_float,
    name_list,
    number_list,
    probability,
    seed,
    spacing_mm,
)
from brachycal.errors import InputError
from brachycal.model.collision import ClearanceChecker, collision_link_pairs
from brachycal.planning import IKSettings, PlanSpec, PoseVerifier, RectFOV, SectorFOV, Thresholds, plan_poses
from brachycal.planning.pose_checks import MIN_JOINT_MARGIN_RAD
from brachycal.simulation.twin import TwinConfig
from brachycal.studies.study import RunParams, run_study, sweep
from brachycal.studies.targeting import targeting_error
from brachycal.validate import (
    MAX_IMAGE_PX,
    SEED_LIMIT,
    check_direction,
    check_int,
    check_pixel,
    check_probability,
    check_range,
    check_seed,
    check_spacing_m,
    check_spacing_mm,
    check_transform,
    parse_name_list,
    parse_number_list,
)

NON_FINITE = [math.nan, math.inf, -math.inf]


def refused(call, *args, **kwargs) -> str:
    """The one-line message of the InputError that ``call`` must raise."""
    with pytest.raises(InputError) as info:
        call(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# --- numbers ----------------------------------------------------------------------------------------
def test_range_ends_are_inclusive_unless_open():
    assert check_range(0.0, "x", low=0.0, high=1.0) == 0.0
    assert check_range(1.0, "x", low=0.0, high=1.0) == 1.0
    assert "x must be in (0, 1], got 0" in refused(check_range, 0.0, "x", low=0.0, high=1.0, low_open=True)
    assert "x must be in [0, 1), got 1" in refused(check_range, 1.0, "x", low=0.0, high=1.0, high_open=True)
    assert "--edge-mm must be in [1, 500] mm, got 0.5 mm" in refused(
        check_range, 0.5, "--edge-mm", low=1, high=500, unit="mm"
    )
    assert ">= 0" in refused(check_range, -1e-300, "x", low=0.0)  # one-sided ranges say so


@pytest.mark.parametrize("value", NON_FINITE)
def test_range_refuses_nan_and_infinity_even_without_bounds(value):
    assert "x must be a finite number" in refused(check_range, value, "x")
    assert "x must be a finite number" in refused(check_range, value, "x", low=-math.inf, high=math.inf)


def test_range_refuses_what_is_not_a_number_and_ints_beyond_float():
    assert "must be a number, got 'abc'" in refused(check_range, "abc", "x")
    assert "finite" in refused(check_range, 10**400, "x")


def test_whole_numbers():
    assert check_int(3, "n", low=2, high=20) == 3
    assert check_int(np.int64(20), "n", low=2, high=20) == 20
    assert check_int(3.0, "n") == 3  # a float that is a whole number (JSON writes 3.0 for 3 sometimes)
    for bad in (3.5, math.nan, math.inf, True, "3", None):
        assert "must be a whole number" in refused(check_int, bad, "n")
    assert "n must be in [2, 20], got 21" in refused(check_int, 21, "n", low=2, high=20)
    assert "n must be in [2, 20], got 1" in refused(check_int, 1, "n", low=2, high=20)
    assert "in [2, 20]" in refused(check_int, 10**400, "n", low=2, high=20)  # exact, no float overflow


def test_seeds_are_32_bit_unsigned():
    assert check_seed(0) == 0 and check_seed(SEED_LIMIT - 1) == SEED_LIMIT - 1
    assert "seed must be in [0, 2**32), got -1" in refused(check_seed, -1)
    assert "2**32" in refused(check_seed, SEED_LIMIT)


def test_probability():
    assert check_probability(0.0, "p") == 0.0 and check_probability(1.0, "p") == 1.0
    assert "p must be in [0, 1], got 1.5" in refused(check_probability, 1.5, "p")
    assert "in [0, 0.5]" in refused(check_probability, 0.6, "p", high=0.5)
    assert "finite" in refused(check_probability, math.nan, "p")


# --- pixel spacing ------------------------------------------------------------------------------------
def test_plausible_spacings_pass_in_both_units():
    assert np.array_equal(check_spacing_mm([0.19, 0.183], "s"), [0.19, 0.183])
    assert np.array_equal(check_spacing_mm([0.005, 2.0], "s"), [0.005, 2.0])  # the ends of the range
    assert np.array_equal(check_spacing_m([0.19e-3, 0.183e-3], "s"), [0.19e-3, 0.183e-3])


@pytest.mark.parametrize("bad", [0.0, -0.19, *NON_FINITE])
def test_spacing_must_be_positive_and_finite(bad):
    assert "s s_v" in refused(check_spacing_mm, [0.19, bad], "s")
    assert "s s_u" in refused(check_spacing_m, [bad, 0.19e-3], "s")


def test_a_spacing_in_metres_typed_as_millimetres_is_named_so():
    message = refused(check_spacing_mm, [1.9e-4, 1.9e-4], "--spacing-mm")
    assert "looks like a spacing in metres typed as millimetres; give 0.19" in message


def test_a_spacing_in_millimetres_given_as_metres_is_named_so():
    message = refused(check_spacing_m, [0.19, 0.19], "spacing_m")
    assert "looks like a spacing in millimetres given as metres; give 0.00019" in message


def test_implausible_spacings_are_refused_without_a_wrong_hint():
    for bad in (0.004, 2.1, 190.0, 1e-9):
        message = refused(check_spacing_mm, [bad, 0.19], "s")
        assert "must be in [0.005, 2] mm/px" in message and "looks like" not in message
    assert "two numbers" in refused(check_spacing_mm, [0.19], "s")


# --- pixels and directions --------------------------------------------------------------------------
def test_pixels_inside_the_image_including_its_half_pixel_border():
    size = (1080, 720)
    assert np.array_equal(check_pixel([-0.5, -0.5], "--uv", size_px=size), [-0.5, -0.5])
    assert np.array_equal(check_pixel([1079.5, 719.5], "--uv", size_px=size), [1079.5, 719.5])
    assert "u = 1080 px is outside the 1080 x 720 px image (-0.5 <= u <= 1079.5)" in refused(
        check_pixel, [1080, 3], "--uv", size_px=size
    )
    assert "v = -0.6 px" in refused(check_pixel, [3, -0.6], "--uv", size_px=size)
    assert "u must be a finite number" in refused(check_pixel, [math.nan, 3], "--uv", size_px=size)
    assert "(pixel 2)" in refused(check_pixel, [[3, 3], [3, 800]], "uv", size_px=size)  # batches name the pixel


def test_pixels_without_an_image_size_are_bounded_by_any_image():
    assert check_pixel([MAX_IMAGE_PX, 0], "p").tolist() == [MAX_IMAGE_PX, 0]
    assert "outside any ultrasound image" in refused(check_pixel, [MAX_IMAGE_PX + 1, 0], "p")


def test_directions_are_normalised_and_the_zero_vector_refused():
    assert np.allclose(check_direction([1e-12, 0, 0], "d"), [1, 0, 0])  # any scale has a direction
    assert np.allclose(check_direction([1e300, 1e300, 0], "d"), [2**-0.5, 2**-0.5, 0])  # no overflow
    assert np.allclose(check_direction([3, 0, 4], "d"), [0.6, 0, 0.8])
    assert "d is the zero vector" in refused(check_direction, [0, 0, 0], "d")
    assert "finite" in refused(check_direction, [0, math.nan, 1], "d")
    assert "3 numbers" in refused(check_direction, [1, 0], "d")


# --- transforms ---------------------------------------------------------------------------------------
def rotation(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def rigid(angle: float = 0.3) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation(2, angle) @ rotation(0, 0.2), [0.1, -0.2, 1.5]
    return T


def test_a_rigid_transform_passes_alone_and_in_batches():
    assert np.array_equal(check_transform(rigid(), "T"), rigid())
    batch = np.stack([rigid(a) for a in np.linspace(0, 3, 5)])
    assert check_transform(batch, "T").shape == (5, 4, 4)


@pytest.mark.parametrize(
    "defect, words",
    [
        (lambda T: T @ np.diag([1.001, 1.0, 1.0, 1.0]), "scaled, sheared or mirrored"),  # 0.1 % scale
        (lambda T: T @ np.array([[1, 0.01, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "rigid"),
        (lambda T: T @ np.diag([1.0, 1.0, -1.0, 1.0]), "determinant -1"),  # mirrored: orthonormal, det -1
        (lambda T: T + np.array([[0, 0, 0, 0]] * 3 + [[0, 0, 0.5, 0]]), "last row"),
    ],
    ids=["scaled", "sheared", "mirrored", "projective"],
)
def test_non_rigid_matrices_are_refused(defect, words):
    assert words in refused(check_transform, defect(rigid()), "ProbeToTracker")


@pytest.mark.parametrize("value", NON_FINITE)
def test_non_finite_transforms_are_refused(value):
    T = rigid()
    T[1, 3] = value
    assert "non-finite" in refused(check_transform, T, "T")


def test_a_bad_matrix_in_a_batch_is_named_by_its_place():
    batch = np.stack([rigid(), rigid(), rigid() @ np.diag([2.0, 2.0, 2.0, 1.0])])
    assert "T (matrix 3 of 3) is not a rigid transform" in refused(check_transform, batch, "T")
    assert "4x4" in refused(check_transform, np.eye(3), "T")


# --- comma lists and argparse types -------------------------------------------------------------------
def test_each_item_of_a_list_is_checked_and_named():
    assert parse_number_list("3, 4,5", "--points", kind=int, low=2, high=20) == [3, 4, 5]
    assert "--points value 3 must be in [2, 20], got 50" in refused(
        parse_number_list, "3,4,50", "--points", kind=int, low=2, high=20
    )
    assert "--points value 2 is empty" in refused(parse_number_list, "3,,4", "--points", kind=int)
    assert "--points value 2 must be a whole number, got '4.5'" in refused(
        parse_number_list, "3,4.5", "--points", kind=int
    )
    assert "--uv value 1 must be a finite number, got nan" in refused(parse_number_list, "nan,3", "--uv", count=2)
    assert "must be 2 comma-separated numbers, got 3" in refused(parse_number_list, "1,2,3", "--uv", count=2)
    assert "at most 100 values" in refused(parse_number_list, ",".join(["1"] * 101), "--edge-mm")


def test_name_lists_refuse_empty_unknown_and_repeated_names():
    assert parse_name_list("kabsch, horn", "--methods", ("kabsch", "horn")) == ["kabsch", "horn"]
    assert "'icpp' is not one of: kabsch, horn" in refused(parse_name_list, "icpp", "--methods", ("kabsch", "horn"))
    assert "names 'horn' twice" in refused(parse_name_list, "horn,horn", "--methods")
    assert "item 1 is empty" in refused(parse_name_list, "", "--frames")


def test_argparse_types_refuse_with_one_line_naming_the_option():
    parser = argparse.ArgumentParser(prog="t", exit_on_error=False)
    parser.add_argument("--margin", type=finite_float(low=0.1, high=45, unit="deg"))
    parser.add_argument("--points", type=bounded_int(low=2, high=20))
    parser.add_argument("--centre", type=number_list(count=3, low=-5000, high=5000, unit="mm"))
    parser.add_argument("--spacing", type=spacing_mm)
    parser.add_argument("--rate", type=probability)
    parser.add_argument("--seed", type=seed)
    parser.add_argument("--dir", type=direction)
    parser.add_argument("--names", type=name_list(("a", "b")))
    good = parser.parse_args(
        "--margin 3 --points 4 --centre 1,2,3 --spacing 0.19,0.2 --rate 0.5 --seed 7 --dir 0,0,2 --names b".split()
    )
    assert good.margin == 3.0 and good.points == 4 and good.centre.tolist() == [1, 2, 3]
    assert good.spacing.tolist() == [0.19, 0.2] and good.rate == 0.5 and good.seed == 7
    assert good.dir.tolist() == [0, 0, 1] and good.names == ["b"]
    for argv, words in [
        (["--margin=-20"], "argument --margin: must be in [0.1, 45] deg, got -20 deg"),
        (["--margin", "nan"], "argument --margin: must be a finite number, got nan"),
        (["--points", "1e3"], "argument --points: must be a whole number, got '1e3'"),
        (["--centre", "1,inf,3"], "argument --centre: value 2 must be a finite number, got inf"),
        (["--spacing", "0,0"], "argument --spacing: s_u must be positive"),
        (["--rate", "1.5"], "argument --rate: must be in [0, 1], got 1.5"),
        (["--seed=-1"], "argument --seed: must be in [0, 2**32), got -1"),
        (["--dir", "0,0,0"], "argument --dir: is the zero vector"),
        (["--names", "c"], "argument --names: 'c' is not one of: a, b"),
    ]:
        with pytest.raises(argparse.ArgumentError) as info:
            parser.parse_args(argv)
        assert words in str(info.value)


def test_every_bounded_option_states_its_rule_in_help():
    from brachycal.cli.main import build_parser
    from brachycal.cli.option_types import OptionType

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    checked = 0
    for command, parser in sub.choices.items():
        for action in parser._actions:
            # Options with a numeric range (names and directions have none to state).
            if isinstance(action.type, OptionType) and any(c in action.type.rule for c in "[(<>"):
                assert action.type.rule in (action.help or ""), f"{command} {action.option_strings}"
                checked += 1
    # demo 2, plan 12, calibrate 1, locate 1, study 7, design 1 today: the loop is not empty.
    assert checked >= 24


# --- library entry points refuse the same values ---------------------------------------------------
@pytest.mark.parametrize(
    "change, words",
    [
        (dict(edge_m=math.nan), "cube edge"),
        (dict(edge_m=-0.04), "cube edge"),
        (dict(points_per_axis=1000), "points per axis"),
        (dict(points_per_axis=4.5), "points per axis"),
        (dict(cube_centre_m=np.array([0.8, math.nan, 1.05])), "cube centre"),
        (dict(cube_centre_m=np.array([800.0, 100.0, 1050.0])), "cube centre"),  # millimetres as metres
        (dict(spacing_m=np.array([0.19, 0.19])), "millimetres given as metres"),
        (dict(spacing_m=np.array([0.0, 0.0])), "positive"),
        (dict(insertion_dir=np.zeros(3)), "insertion direction is the zero vector"),
        (dict(image_lateral_dir=np.array([2.0, 0.0, 0.0])), "parallel"),
        (dict(centre_px=(math.nan, 221.0)), "centre pixel"),
        (dict(fov_margin_m=math.nan), "field-of-view margin"),
        (dict(fov_margin_m=-0.002), "field-of-view margin"),
        (dict(offsets_m=np.full((4, 3), math.nan)), "offsets"),
    ],
)
def test_plan_spec_refuses_nan_negative_and_implausible_settings(change, words):
    assert words in refused(replace, PlanSpec(), **change)


def test_fields_of_view_refuse_nan_and_impossible_shapes():
    assert "sector depth" in refused(SectorFOV, radius_m=math.nan)
    assert "sector angle" in refused(SectorFOV, angle_rad=np.radians(200))
    assert "sector apex" in refused(SectorFOV, apex_px=(math.inf, 0.0))
    assert "low to high" in refused(RectFOV, u_range_px=(500.0, 100.0))
    assert "rectangle v range" in refused(RectFOV, v_range_px=(0.0, math.nan))


@pytest.mark.parametrize(
    "change",
    [
        dict(joint_margin_rad=math.nan),
        dict(joint_margin_rad=np.radians(-20)),
        dict(joint_margin_rad=MIN_JOINT_MARGIN_RAD / 2),  # below the floor that covers encoder noise
        dict(collision_margin_m=math.nan),
        dict(collision_margin_m=-0.5),
        dict(position_m=math.nan),
        dict(direction_rad=0.0),
        dict(plane_m=math.inf),
    ],
)
def test_thresholds_refuse_nan_and_negative_margins(change):
    refused(Thresholds, **change)


def test_joint_margin_floor_covers_the_readers_tolerance_and_the_encoder_noise():
    # Readers accept a reading at most 1e-3 rad past a limit; the twin's encoder noise is 2e-5 rad SD.
    assert MIN_JOINT_MARGIN_RAD > 1e-3 and MIN_JOINT_MARGIN_RAD / TwinConfig().encoder_sd_rad > 50
    assert Thresholds(joint_margin_rad=MIN_JOINT_MARGIN_RAD).joint_margin_rad == MIN_JOINT_MARGIN_RAD


@pytest.mark.parametrize(
    "change",
    [
        dict(collision_margin_m=math.nan),
        dict(joint_margin_rad=-0.1),
        dict(dt=0.0),
        dict(max_iterations=0),
        dict(max_iterations=10**9),
        dict(position_tol_m=math.nan),
        dict(angle_tol_rad=-1e-7),
        dict(posture_cost=math.inf),
        dict(finish_radius_m=math.nan),
    ],
)
def test_ik_settings_refuse_nan_negative_and_out_of_range(change):
    refused(IKSettings, **change)


@pytest.mark.parametrize(
    "change, words",
    [
        (dict(seed=-1), "seed"),
        (dict(seed=1.5), "seed"),
        (dict(encoder_sd_rad=math.nan), "encoder_sd_rad"),
        (dict(jog_sd_m=-5e-5), "jog_sd_m"),
        (dict(annotation_sd_px=math.inf), "annotation_sd_px"),
        (dict(sound_speed_m_s=0.0), "sound_speed_m_s"),
        (dict(outlier_rate=1.5), "outlier_rate"),
        (dict(outlier_px=(40.0, 15.0)), "outlier_px"),
        (dict(beam_thickness_m=math.nan), "beam_thickness_m"),
        (dict(trials=0), "trials"),
        (dict(outliers="no"), "outliers must be True or False"),
        (dict(spec="4x4x4"), "PlanSpec"),
    ],
)
def test_twin_settings_refuse_nan_negative_and_out_of_range(change, words):
    assert words in refused(TwinConfig, **change)


def test_study_parameters_are_checked_before_any_run():
    ok = dict(seeds=1, points=[4], edges_mm=[40.0], annotation_px=[1.0])
    assert len(sweep(**ok)) == 1
    assert "outlier rate" in refused(sweep, **ok, outlier_rates=[1.5])
    assert "seeds" in refused(sweep, **{**ok, "seeds": 0})
    assert "points per axis" in refused(sweep, **{**ok, "points": [4, 1000]})
    assert "annotation noise" in refused(sweep, **{**ok, "annotation_px": [math.nan]})
    assert "empty" in refused(sweep, **{**ok, "edges_mm": []})
    assert "at most 10000" in refused(sweep, **{**ok, "seeds": 1000, "points": list(range(2, 13))})
    assert "methods" in refused(RunParams, 0, 4, 40.0, 1.0, True, 0.0, ("icpp",), 30)
    assert "targets" in refused(RunParams, 0, 4, 40.0, 1.0, True, 0.0, ("kabsch",), 0)
    assert "workers" in refused(run_study, [], workers=-1)


def test_targeting_and_planning_check_their_counts_first(robot):
    # The checks come before any use of the other arguments (None here would fail later).
    calibration = Calibration(np.eye(4), np.eye(4), ImageCalibration("kabsch", np.eye(4), np.full(2, 1.9e-4)))
    assert "number of targets" in refused(targeting_error, None, calibration, 0)
    assert "speed scale" in refused(plan_poses, robot, PlanSpec(), speed_scale=math.nan)


def test_a_nan_configuration_fails_every_check_of_the_verifier(robot):
    spec = PlanSpec()
    verifier = PoseVerifier(robot, spec, ClearanceChecker(robot, collision_link_pairs(robot)), Thresholds())
    with np.errstate(invalid="ignore"):
        check = verifier.check(np.full(robot.nq, math.nan), spec.cube_centre_m)
    assert not check.ok
    assert {"reach", "direction", "plane", "fov", "limit"} <= set(check.failures)
