"""Calibration: tool tips, pivot, tool rotations, image-to-probe registration, validation."""

from brachycal.calibration.image_to_probe import METHOD_LABELS, METHODS, PAPER_METHODS, ImageCalibration
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.pivot import PivotResult, pivot_algebraic, pivot_robust
from brachycal.calibration.result_file import StoredCalibration, read_result, write_result
from brachycal.calibration.sequential import CalibrationResult, ToolCalibration, calibrate, locate

__all__ = [
    "METHODS",
    "METHOD_LABELS",
    "PAPER_METHODS",
    "CalibrationResult",
    "ErrorStats",
    "ImageCalibration",
    "PivotResult",
    "StoredCalibration",
    "ToolCalibration",
    "calibrate",
    "locate",
    "pivot_algebraic",
    "pivot_robust",
    "read_result",
    "write_result",
]
