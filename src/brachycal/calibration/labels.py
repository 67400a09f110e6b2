"""Names of the image-to-probe calibration methods, with the paper's labels (no estimator loaded).

The one home of these names: :mod:`brachycal.calibration.sequential.image_to_probe` fits them, the reports
label them, and the command line offers them as choices, which it does before (or without)
loading SciPy's optimisers.
"""

from __future__ import annotations

#: Methods in the order of Table II, with the paper's names.
METHOD_LABELS: dict[str, str] = {
    "icp": "ICP",
    "kabsch": "Kabsch",
    "horn": "Landmark (Horn)",
    "similarity": "Similarity (1 scale)",
    "scaled_uv": "Scaled u/v (2 scales)",
}
#: Labels of every image calibration a result can hold (the whole-chain method's included), and
#: of the whole chain with the robot identified (a study method).
ALL_LABELS: dict[str, str] = {**METHOD_LABELS, "chain": "Whole chain", "chain+robot": "Whole chain + robot"}
METHODS: tuple[str, ...] = tuple(METHOD_LABELS)
#: The paper's three rigid methods.
PAPER_METHODS: tuple[str, ...] = ("icp", "kabsch", "horn")

#: Pivot calibration methods (:mod:`brachycal.calibration.phantom.pivot_file`) and the units a pose list's
#: translations may be in: the command line's choices, without loading the estimators.
PIVOT_METHODS: tuple[str, ...] = ("algebraic", "robust")
POSE_UNITS: tuple[str, ...] = ("m", "mm")
