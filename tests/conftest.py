"""Shared fixtures: the bundled robot, the vendor's model, random configurations."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import settings

from brachycal.model import Robot

# On CI, property-based tests draw the same examples every run (a failure found there can be
# replayed); locally they explore new ones each time.
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

DATA = Path(__file__).parent / "data"
ROOT = Path(__file__).parents[1]
VENDOR_URDF = DATA / "vendor" / "sda10f_expanded.urdf"


@pytest.fixture(scope="session")
def robot() -> Robot:
    return Robot.load()


@pytest.fixture(scope="session")
def vendor_model() -> pin.Model:
    """The vendor URDF as Pinocchio reads it: 16 axes, ``torso_joint_b2`` independent."""
    return pin.buildModelFromUrdf(str(VENDOR_URDF))


def random_configurations(robot: Robot, n: int, seed: int = 0) -> np.ndarray:
    """``(n, nq)`` configurations drawn uniformly inside the joint limits."""
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.lower, robot.upper, size=(n, robot.nq))


@pytest.fixture(scope="session")
def truth(robot):
    from brachycal.simulation import default_truth

    return default_truth(robot)


@pytest.fixture(scope="session")
def exact(robot, truth):
    """A noise-free 64-sample session hiding ``truth``."""
    from brachycal.simulation import exact_session

    return exact_session(robot, truth)


@pytest.fixture
def session_dir(tmp_path, exact):
    """The exact session written to a folder (a fresh copy per test)."""
    from brachycal.data.session import write_session

    return write_session(exact, tmp_path / "session")
