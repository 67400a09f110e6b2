"""brachycal's N-wire models against PLUS fCal's figures on every PLUS recording with segmented frames.

Run: ``.venv/bin/python benchmarks/nwire_variants.py [--pluslibdata DIR]`` (a few seconds a recording).

Each recording is calibrated by ``calibrate_nwire_files`` (every model: PLUS's linear fit, brachycal's
rotation + u/v spacings, PLUS's four refinements) and every model is reported as PLUS reports its
result: the mean (± SD) 3D error of the best 95 % of the validation middle-wire points, mm. PLUS's
figure beside it is the ``ValidationMeanMm`` of PLUS's own results file for that recording and setting.
The default model is the one with the lowest of these figures (``calibrate_nwire_files``'s choice); the
goal is that it is at or below PLUS's best setting, to PLUS's printed digits (6 significant: 5e-6 mm).

Recordings: from ``../shared/reference`` (fCal 2.0; the 3-N-wire recording PLUS calibrated with its
OPEA and OPEI settings), and, with ``--pluslibdata``, the rest of PLUS's public test data: a checkout
of https://github.com/PlusToolkit/PlusLibData (BSD-3-Clause; ``ConfigFiles/`` and ``TestImages/``):
the same 3-N-wire recording calibrated with PLUS's IPEA and IPEI settings, and the fCal 1.2
phantom's recording (its 1.x-style device set). Figures are recorded in ``benchmarks/results.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from timing import record

from brachycal.calibration.phantom.nwire_file import NWIRE_MODELS, calibrate_nwire_files
from brachycal.calibration.phantom.nwire_refine import PLUS_NAMES
from brachycal.data.formats.plus_files import parse_xml

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference"
#: PLUS's digits: it writes 6 significant figures, so ~1.25 mm is known to 5e-6 mm.
PLUS_DIGITS_MM = 5e-6
#: fCal 2.0's stripped frames file has no error report; PLUS's figure is in PlusLibData's
#: TestImages/FreehandCalibration3NWires_fCal2.0.results.xml (ValidationMeanMm), linear fit.
FCAL2_PLUS_MM = 0.539932


@dataclass
class Recording:
    name: str
    config: Path
    frames: Path
    plus: dict[str, float] = field(default_factory=dict)  # PLUS setting -> its ValidationMeanMm


def plus_figure(results: Path) -> float:
    """PLUS's ``ReprojectionError3DStatistics/@ValidationMeanMm`` in one of its results files, mm."""
    element = parse_xml(results).find("ErrorReport/ReprojectionError3DStatistics")
    if element is None or element.get("ValidationMeanMm") is None:
        sys.exit(f"{results}: no ErrorReport/ReprojectionError3DStatistics/@ValidationMeanMm")
    return float(element.get("ValidationMeanMm", "nan"))


def recordings(pluslibdata: Path | None) -> list[Recording]:
    out = []
    fcal = REFERENCE / "plus_fcal_nwire"
    if fcal.exists():
        out.append(
            Recording(
                "fCal 2.0 (fCal_Test_*_3NWires_fCal2.0)",
                fcal / "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml",
                fcal / "fCal_3NWires_segmented_frames.xml",
                {"linear": FCAL2_PLUS_MM},
            )
        )
    variants = REFERENCE / "plus_nwire_variants"
    three_n = Recording(
        "3-N-wire, PLUS's OptimizationMethod tests",
        variants / "PlusDeviceSet_OPEA_OptimizationMethod.xml",
        variants / "OPEA_OptimizationMethod_Calibration.results.xml",
    )
    for setting in ("OPEA", "OPEI"):
        results = variants / f"{setting}_OptimizationMethod_Calibration.results.xml"
        if results.exists():
            three_n.plus[setting] = plus_figure(results)
    if pluslibdata is not None:
        images, configs = pluslibdata / "TestImages", pluslibdata / "ConfigFiles"
        for setting in ("IPEA", "IPEI"):
            results = images / f"{setting}_OptimizationMethod_Calibration.results.xml"
            if results.exists():
                three_n.plus[setting] = plus_figure(results)
        fcal12 = images / "FreehandCalibration3NWires.results.xml"
        if fcal12.exists():
            out.append(
                Recording(
                    "fCal 1.2 (FreehandCalibration3NWires, 1.x device set)",
                    configs / "Testing" / "PlusDeviceSet_fCal_Sim_SpatialCalibration_1.2.xml",
                    fcal12,
                    {"linear": plus_figure(fcal12)},
                )
            )
    if three_n.plus:
        out.insert(1 if out else 0, three_n)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pluslibdata", type=Path, help="a PlusLibData checkout (ConfigFiles/, TestImages/)")
    args = parser.parse_args()
    found = recordings(args.pluslibdata)
    if not found:
        sys.exit(f"no PLUS recordings under {REFERENCE} (see its README) and no --pluslibdata")
    print("best-95% validation 3D error, mean ± SD (mm); * = brachycal's choice")
    print("| recording | PLUS (setting: mm) | " + " | ".join(NWIRE_MODELS) + " | choice − PLUS best |")
    print("|---|---|" + "---|" * len(NWIRE_MODELS) + "---|")
    for rec in found:
        start = time.perf_counter()
        run = calibrate_nwire_files(rec.config, rec.frames)
        seconds = time.perf_counter() - start
        best = {name: v.validation_best95 for name, v in run.models.items()}
        cells = [
            f"{'*' if name == run.model else ''}{best[name].mae_mm:.3f} ± {best[name].sd_mm:.3f}"
            for name in NWIRE_MODELS
        ]
        plus_best = min(rec.plus.values())
        chosen = best[run.model].mae_mm
        plus = ", ".join(f"{setting} {value:.3f}" for setting, value in rec.plus.items())
        print(f"| {rec.name} | {plus} | " + " | ".join(cells) + f" | {chosen - plus_best:+.5f} |")
        print(
            f"  ({run.model}: PLUS's {PLUS_NAMES.get(run.model, 'linear' if run.model == 'affine' else 'none')}; "
            f"{run.calibration_points} calibration and {run.validation_points} validation points; {seconds:.1f} s)"
        )
        record(
            f"nwire validation best-95% mean, {rec.name}",
            chosen,
            "mm",
            goal=f"<= PLUS's best setting ({min(rec.plus, key=rec.plus.__getitem__)}) + {PLUS_DIGITS_MM} mm",
            met=chosen <= plus_best + PLUS_DIGITS_MM,
            peer="PLUS fCal",
            peer_value=plus_best,
        )


if __name__ == "__main__":
    main()
