"""Simulated sessions with known truth: exact sessions, the digital twin, and how to judge them."""

from brachycal.simulation.exact import SessionTruth, default_truth, exact_session
from brachycal.simulation.targeting import TargetingResult, targeting_error
from brachycal.simulation.twin import Twin, TwinConfig, simulate
from brachycal.simulation.twin_files import read_twin, write_twin

__all__ = [
    "SessionTruth",
    "TargetingResult",
    "Twin",
    "TwinConfig",
    "default_truth",
    "exact_session",
    "read_twin",
    "simulate",
    "targeting_error",
    "write_twin",
]
