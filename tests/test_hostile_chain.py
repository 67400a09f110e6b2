"""Hostile input to the whole-chain method: well-formed sessions whose image samples cannot determine
the chain. ``brachycal calibrate --solve chain`` refuses each with one line naming ``samples.csv``,
exit code 2, nothing written — before this, samples at one robot pose gave a predicted landing error
of 0.000 mm.

The sequential start checks the same data first (``test_hostile_estimators.py``); whichever check
fires, the refusal must be one line naming the file. The chain's own checks, without the sequential
in front, are specified in ``test_chain.py`` (``test_samples_*``).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from hostile import Case, check_refusal

from brachycal.data.session import Session, read_session, write_session
from brachycal.model import Robot

CHAIN = ["calibrate", "{tmp}/session", "--out", "{tmp}/result.json", "--solve", "chain", "--quiet"]


@cache
def robot() -> Robot:
    return Robot.load()


def session(edit: Callable[[Session], Session]):
    """Copy the committed twin session to ``{tmp}/session`` with its samples changed by ``edit``."""

    def setup(tmp: Path) -> None:
        shutil.copytree(ROOT / "examples" / "twin_session", tmp / "session")
        write_session(edit(read_session(tmp / "session", robot())), tmp / "session", force=True)

    return setup


def samples(rows: Callable[[Session], np.ndarray], uv: Callable[[Session], np.ndarray] | None = None):
    """Keep the sample rows ``rows(s)`` (joints and pixels), then set the pixels to ``uv(s)`` if given."""

    def edit(s: Session) -> Session:
        keep = rows(s)
        out = replace(
            s, samples_q=s.samples_q[keep], uv_px=s.uv_px[keep], sample_ids=[f"s{i + 1}" for i in range(len(keep))]
        )
        return out if uv is None else replace(out, uv_px=uv(out))

    return edit


def first_repeated(s: Session) -> np.ndarray:
    return np.zeros(len(s.uv_px), dtype=int)


def nearest_to_first(count: int):
    return lambda s: np.argsort(np.linalg.norm(s.uv_px - s.uv_px[0], axis=1))[:count]


CASES = [
    Case(
        "chain-every-sample-the-same-image",  # one pose, one pixel: the fit was "exact", 0.000 mm predicted
        CHAIN,
        ("samples.csv",),
        session(samples(first_repeated)),
    ),
    Case(
        "chain-every-sample-at-one-robot-pose",  # one pose, the recorded pixels
        CHAIN,
        ("samples.csv",),
        session(samples(first_repeated, uv=lambda s: read_session(ROOT / "examples" / "twin_session", robot()).uv_px)),
    ),
    Case(
        "chain-one-pose-pixels-scattered-by-a-pixel",
        CHAIN,
        ("samples.csv",),
        session(samples(first_repeated, uv=lambda s: s.uv_px[0] + np.random.default_rng(0).normal(size=s.uv_px.shape))),
    ),
    Case("chain-four-samples-within-a-few-pixels", CHAIN, ("samples.csv",), session(samples(nearest_to_first(4)))),
    Case("chain-two-samples", CHAIN, ("samples.csv",), session(samples(lambda s: np.array([0, 1])))),
]


def copied(tmp: Path) -> None:
    shutil.copytree(ROOT / "examples" / "twin_session", tmp / "session")


SEQUENTIAL = ["calibrate", "{tmp}/session", "--out", "{tmp}/result.json", "--quiet"]
# The stated robot accuracy: a finite SD from 0 up to the typo guards (10 mm, 1 deg), chain only.
CASES += [
    Case("robot-accuracy-mm-negative", [*CHAIN, "--robot-accuracy-mm", "-0.03"], ("--robot-accuracy-mm",), copied),
    Case("robot-accuracy-mm-nan", [*CHAIN, "--robot-accuracy-mm", "nan"], ("--robot-accuracy-mm",), copied),
    Case("robot-accuracy-mm-huge", [*CHAIN, "--robot-accuracy-mm", "50"], ("--robot-accuracy-mm", "10"), copied),
    Case("robot-accuracy-deg-inf", [*CHAIN, "--robot-accuracy-deg", "inf"], ("--robot-accuracy-deg",), copied),
    Case("robot-accuracy-deg-huge", [*CHAIN, "--robot-accuracy-deg", "5"], ("--robot-accuracy-deg", "1"), copied),
    Case(
        "robot-accuracy-without-chain",
        [*SEQUENTIAL, "--robot-accuracy-mm", "0.1"],
        ("--robot-accuracy-mm", "--solve chain"),
        copied,
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_chain_refuses_samples_that_cannot_determine_it(case: Case, tmp_path: Path) -> None:
    check_refusal(case, tmp_path)
