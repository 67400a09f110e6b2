"""``brachycal pivot``: pivot calibration of a tracked tool from a pose list."""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

from brachycal.calibration import pivot_algebraic, pivot_robust
from brachycal.data.pose_list import read_pose_list
from brachycal.errors import InputError
from brachycal.files import atomic_open

HELP = "pivot calibration: tool tip and pivot point from poses rotating about a fixed tip"
DESCRIPTION = """\
Estimates the tip of a tool in its own (marker or flange) frame and the fixed pivot point in the
reference frame from poses of the tool rotating about its tip.

POSES is a CSV pose list: a header, then one row-major 4x4 homogeneous matrix per row
(m00,m01,...,m33), optionally after a first key column (e.g. timestamp_ns). Results are in the
units of the poses (--units records which). Residuals are given per axis (RMS over all 3N
coordinates, as SciKit-Surgery reports) and in 3D (RMS of the N distances).

methods: algebraic (linear least squares, Yaniv 2015) or robust (soft-L1 loss, flags outliers).

example:
  brachycal pivot tracked_pointer_pivot.csv --units mm --out pivot.json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "pivot", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("poses", metavar="POSES", help="CSV pose list")
    parser.add_argument("--out", required=True, metavar="JSON", help="result file to write")
    parser.add_argument("--method", choices=("algebraic", "robust"), default="algebraic")
    parser.add_argument(
        "--units", choices=("m", "mm"), default="m", help="units of the poses' translations (default m)"
    )
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError("already exists; pass --force to replace it", file=out)
    names, T, _ = read_pose_list(args.poses)
    result = (pivot_robust if args.method == "robust" else pivot_algebraic)(T)
    outliers = [name for name, inlier in zip(names, result.inliers, strict=True) if not inlier]
    u = args.units
    payload = {
        "format": "brachycal-pivot/1",
        "method": result.method,
        "units": u,
        "tip_in_tool": result.p_marker_tip.tolist(),
        "pivot_in_reference": result.p_ref_pivot.tolist(),
        "rms_per_axis": result.rms_per_axis,
        "rms_3d": result.rms_3d,
        "n_poses": len(names),
        "n_inliers": int(result.inliers.sum()),
        "outliers": outliers,
        "inputs": {Path(args.poses).name: hashlib.sha256(Path(args.poses).read_bytes()).hexdigest()},
    }
    with atomic_open(out, force=args.force) as handle:
        json.dump(payload, handle, indent=2)
        handle.write("\n")
    fmt = lambda v: "(" + ", ".join(f"{x:.3f}" for x in v) + ")"  # noqa: E731
    print(f"pivot calibration ({result.method}) of {len(names)} poses, {payload['n_inliers']} used")
    print(f"  tip in tool frame      {fmt(result.p_marker_tip)} {u}")
    print(f"  pivot in reference     {fmt(result.p_ref_pivot)} {u}")
    print(f"  residual RMS           {result.rms_per_axis:.3f} {u} per axis, {result.rms_3d:.3f} {u} in 3D")
    print(f"wrote {out}")
    return 0
