"""Noise rules of :func:`~brachycal.calibration.robot.arm_fit.fit_arm`'s noise rounds: a group with too few
residual degrees of freedom of its own takes the level of the group it is pooled with (or its
assumed level); no level below a group's floor.

The model is the smallest with two groups: each group's rows measure one unknown of its own
(``r = y_g − d``), so a group of ``n`` rows has ``n − 1`` residual degrees of freedom and its
unknown's posterior SD is its level over ``√n``. The robot plays no part (no free correction)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pytest

from brachycal.calibration.chain import MIN_NOISE_DOF
from brachycal.calibration.robot.arm_fit import Evaluation, NoiseRule, ParameterSelection, fit_arm
from brachycal.errors import InputError
from brachycal.model.description_file import example_robot_data_share
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

GROUPS = ("many", "few")


@dataclass(frozen=True)
class Means:
    """Rows ``y_g − d_i`` per group ``g`` (``data[g]``: its ``d``), with the noise rules ``rules``."""

    data: dict[str, FloatArray]
    rules: dict[str, NoiseRule] = field(default_factory=dict)

    @property
    def groups(self) -> tuple[str, ...]:
        return GROUPS

    @property
    def noise_rules(self) -> Mapping[str, NoiseRule]:
        return self.rules

    def y_scale(self) -> FloatArray:
        return np.ones(len(GROUPS))

    def evaluate(self, robot: Robot, y: FloatArray) -> Evaluation:
        group = np.concatenate([np.full(len(self.data[g]), k) for k, g in enumerate(GROUPS)])
        r = y[group] - np.concatenate([self.data[g] for g in GROUPS])
        J_y = np.zeros((len(r), len(GROUPS)))
        J_y[np.arange(len(r)), group] = 1.0
        return Evaluation(r, np.zeros((len(r), 6 * robot.nq)), J_y, group)


@pytest.fixture(scope="module")
def panda() -> Robot:
    return Robot.load(example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf")


def _fit(panda: Robot, model: Means, sigma: dict[str, float] | None = None):
    nothing = ParameterSelection(tuple(panda.joint_names), np.zeros((panda.nq, 6), dtype=bool))
    start = sigma or {"many": 1.0, "few": 1.0}
    return fit_arm(panda, model, np.zeros(len(GROUPS)), nothing, start, None, estimate_noise=GROUPS)


def _data(rng: np.random.Generator, n_few: int) -> dict[str, FloatArray]:
    """40 rows of SD 1e-3 about 0.2; ``n_few`` rows of SD 1e-5 about −0.1 (a level far from the other's)."""
    return {"many": 0.2 + rng.normal(0, 1e-3, 40), "few": -0.1 + rng.normal(0, 1e-5, n_few)}


def test_a_group_with_too_few_degrees_of_freedom_takes_its_partners_level(panda):
    """4 rows (3 residual dof, below MIN_NOISE_DOF): pooled, the group's level is the other group's,
    and so is the SD stated for its unknown (level/√4). Without the rule it would state its own
    3-dof scatter, 100 times smaller here."""
    data = _data(np.random.default_rng(0), 4)
    pooled = _fit(panda, Means(data, {"few": NoiseRule(pooled_with="many")}))
    alone = _fit(panda, Means(data))
    assert pooled.noise_dof["few"] == pytest.approx(3.0) and pooled.noise_dof["few"] < MIN_NOISE_DOF
    many = float(np.std(data["many"], ddof=1))  # the other group's own estimate: RSS over 39 dof
    assert pooled.sigma["many"] == pytest.approx(many, rel=1e-9)
    assert pooled.sigma["few"] == pooled.sigma["many"]
    assert np.sqrt(pooled.y_covariance()[1, 1]) == pytest.approx(many / 2, rel=1e-6)
    assert alone.sigma["few"] == pytest.approx(float(np.std(data["few"], ddof=1)), rel=1e-9)
    assert alone.sigma["few"] < 0.1 * alone.sigma["many"]
    # The estimates themselves are the groups' means either way (each unknown has its own rows).
    assert pooled.y == pytest.approx([data["many"].mean(), data["few"].mean()], abs=1e-12)


def test_a_group_with_enough_degrees_of_freedom_keeps_its_own_level(panda):
    """12 rows (11 residual dof): the rule does not apply; the group's own scatter is its level."""
    data = _data(np.random.default_rng(1), 12)
    fit = _fit(panda, Means(data, {"few": NoiseRule(pooled_with="many")}))
    assert fit.noise_dof["few"] == pytest.approx(11.0)
    assert fit.sigma["few"] == pytest.approx(float(np.std(data["few"], ddof=1)), rel=1e-9)


def test_without_a_partner_of_its_own_the_assumed_level_or_the_start(panda):
    """Both groups too few (4 and 5 rows): the pooled group cannot lean on the other, which keeps its
    assumed level, or the level it started with when none is stated."""
    rng = np.random.default_rng(2)
    data = {"many": rng.normal(0, 1e-3, 5), "few": rng.normal(0, 1e-5, 4)}
    rules = {"many": NoiseRule(assumed=2e-3), "few": NoiseRule(pooled_with="many", assumed=3e-4)}
    start = {"many": 1.0, "few": 0.5}
    fit = _fit(panda, Means(data, rules), start)
    assert fit.sigma == {"many": 2e-3, "few": 3e-4}
    fit = _fit(panda, Means(data, {"many": NoiseRule(), "few": NoiseRule(pooled_with="many")}), start)
    assert fit.sigma == start


def test_a_level_is_not_taken_below_its_floor(panda):
    """Exact rows: the level is the floor (the resolution), not the rounding of the residuals."""
    data = {"many": np.full(40, 0.2), "few": -0.1 + np.random.default_rng(3).normal(0, 1e-5, 12)}
    fit = _fit(panda, Means(data, {"many": NoiseRule(floor=1e-6)}))
    assert fit.sigma["many"] == 1e-6
    assert fit.sigma["few"] == pytest.approx(float(np.std(data["few"], ddof=1)), rel=1e-9)


@pytest.mark.parametrize(
    "rules",
    [
        {"other": NoiseRule()},
        {"few": NoiseRule(pooled_with="other")},
        {"few": NoiseRule(pooled_with="few")},
        {"few": NoiseRule(floor=-1.0)},
        {"few": NoiseRule(assumed=0.0)},
    ],
)
def test_a_rule_naming_no_group_or_with_a_bad_level_is_refused(panda, rules):
    with pytest.raises(InputError, match="noise rule"):
        _fit(panda, Means(_data(np.random.default_rng(4), 4), rules))
