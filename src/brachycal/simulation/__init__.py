"""Simulated sessions with known truth."""

from brachycal.simulation.exact import SessionTruth, default_truth, exact_session

__all__ = ["SessionTruth", "default_truth", "exact_session"]
