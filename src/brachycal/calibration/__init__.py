"""Calibration: tool tips, pivot, tool rotations, image-to-probe registration, validation."""

from brachycal.calibration.chain import MODELS, ChainFit, fit_chain, select_model
from brachycal.calibration.chain_report import ChainReport, calibrate_chain
from brachycal.calibration.image_to_probe import METHOD_LABELS, METHODS, PAPER_METHODS, ImageCalibration
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.pivot import PivotResult, pivot_algebraic, pivot_robust
from brachycal.calibration.result_file import StoredCalibration, read_result, write_result
from brachycal.calibration.sequential import CalibrationResult, ToolCalibration, calibrate, locate

__all__ = [
    "METHODS",
    "METHOD_LABELS",
    "MODELS",
    "PAPER_METHODS",
    "CalibrationResult",
    "ChainFit",
    "ChainReport",
    "ErrorStats",
    "ImageCalibration",
    "PivotResult",
    "StoredCalibration",
    "ToolCalibration",
    "calibrate",
    "calibrate_chain",
    "fit_chain",
    "locate",
    "pivot_algebraic",
    "pivot_robust",
    "read_result",
    "select_model",
    "write_result",
]
