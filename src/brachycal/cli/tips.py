"""``brachycal tips``: propose the needle-tip annotation of each B-mode frame (images.csv for the session build)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import command_inputs, output_file, progress_bar

if TYPE_CHECKING:
    import numpy as np

HELP = "propose the needle tip in each B-mode frame of a MetaImage sequence: images.csv for session build"
DESCRIPTION = """\
Finds the needle tip in each frame of FRAMES (a MetaImage sequence, .mha, of 8-bit B-mode frames
with a Timestamp per frame, as PLUS and `brachycal demo --recording --images` write them) and
writes --out in the images.csv format `brachycal session build --images` reads:

  time,u_px,v_px,confidence,proposed_u_px,proposed_v_px

one row per frame, in the sequence's order; time is the frame's Timestamp (seconds); u_px, v_px
the tip in pixels (the centre of pixel (0, 0) is the origin, u along columns, v along rows). A
frame whose confidence is below --min-confidence is left for a person: its u_px, v_px are empty
(session build skips it and reports it as not annotated) and its proposal is in proposed_u_px,
proposed_v_px; the frames are also listed on the screen. Fill in u_px, v_px after checking.

The detector (brachycal.imaging.needle_tip): the strongest echo over the local speckle, the shaft
as its bright streak, the tip as the end of the echo along the shaft; confidence in [0, 1] from
the echo's contrast over speckle, the streak's straightness and the agreement of the peak with
the echo's end. --direction gives the expected shaft direction in the image (towards the tip),
e.g. from the plan; without it the streak's own axis is used.

--sheet writes a contact sheet (PNG): every frame around its proposed tip, red where a person
must annotate. --truth CSV (time,sample,u_px,v_px,...: the twin's frames_truth.csv) adds the
true tips to the sheet and prints the detection error.

The outputs are written together or not at all; existing ones are replaced only with --force.

examples:
  brachycal demo --recording --images --out run
  brachycal tips run/recording/frames.mha --out run/images_detected.csv --sheet run/tips.png \\
      --truth run/recording/frames_truth.csv
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.cli.option_types import finite_float, number_list  # lazy: start-up (the command's run only)

    parser = sub.add_parser(
        "tips", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("frames", metavar="FRAMES", help="MetaImage sequence (.mha) of 8-bit B-mode frames")
    parser.add_argument("--out", required=True, type=output_file, metavar="CSV", help="images.csv to write")
    parser.add_argument(
        "--sheet", type=output_file, metavar="PNG", help="also write a contact sheet of the frames and their tips"
    )
    confidence = finite_float(low=0.0, high=1.0)
    parser.add_argument(
        "--min-confidence",
        type=confidence,
        default=None,
        metavar="C",
        help="frames below this confidence are left for a person, in [0, 1] (default: the detector's "
        "MIN_CONFIDENCE, see the documentation's Validation page)",
    )
    parser.add_argument(
        "--direction",
        type=number_list(count=2),
        metavar="DU,DV",
        help="expected shaft direction in the image, towards the tip, in pixel axes (e.g. 0,1: straight down)",
    )
    parser.add_argument("--truth", metavar="CSV", help="true tips per frame (the twin's frames_truth.csv)")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.data.formats.metaimage import read_image_sequence  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.imaging.needle_tip import MIN_CONFIDENCE, detect_tips  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    min_confidence = MIN_CONFIDENCE if args.min_confidence is None else args.min_confidence
    with OutputSet(force=args.force, inputs=command_inputs(args, "frames", "truth")) as outputs:
        out = outputs.claim(args.out, label="--out")
        sheet = outputs.claim(args.sheet, label="--sheet") if args.sheet else None
        sequence = read_image_sequence(args.frames)
        if len(sequence) == 0:
            raise InputError("holds no frames", file=args.frames)
        if 0 in sequence.pixels.shape[1:]:
            height, width = sequence.pixels.shape[1:]
            raise InputError(f"its frames are {width}x{height} pixels: no image to find a tip in", file=args.frames)
        if sequence.pixels.dtype != np.uint8:
            raise InputError(
                f"expected 8-bit B-mode frames (MET_UCHAR), got {sequence.pixels.dtype}",
                file=args.frames,
                column="ElementType",
            )
        missing = np.flatnonzero(~np.isfinite(sequence.timestamps_s))
        if len(missing):
            raise InputError(
                "has no Timestamp (needed to pair the frame with the joint log)",
                file=args.frames,
                row=int(missing[0]),
                row_label="frame",
            )
        truth = _read_truth(args.truth, sequence.timestamps_s) if args.truth else None
        with progress_bar(len(sequence), "tips", args.quiet, unit="frame") as bar:
            detections = detect_tips(sequence.pixels, args.direction, progress=bar.update)
        uv = np.array([d.uv_px for d in detections])
        confidence = np.array([d.confidence for d in detections])
        low = confidence < min_confidence
        _write_images(out, sequence.timestamps_s, uv, confidence, low)
        if sheet is not None:
            from brachycal.reporting.contact_sheet import contact_sheet  # lazy: start-up (the command's run only)

            contact_sheet(sheet, sequence.pixels, uv, confidence, min_confidence=min_confidence, true_px=truth)
    n = len(detections)
    print(f"{n} frames: {n - int(low.sum())} tips proposed at confidence >= {min_confidence:g}, {int(low.sum())} below")
    if low.any():
        listed = ", ".join(f"{k} ({confidence[k]:.2f})" for k in np.flatnonzero(low))
        print(f"annotate by hand (frame number from 0, confidence): {listed}")
    if truth is not None:
        error = np.linalg.norm(uv - truth, axis=1)
        kept = ~low & np.isfinite(error)
        if kept.any():
            e = error[kept]
            print(
                f"error against the true tips (frames kept): median {np.median(e):.2f} px, "
                f"95th percentile {np.percentile(e, 95):.2f} px, max {e.max():.2f} px"
            )
    print(f"wrote {args.out}" + (f" and {args.sheet}" if args.sheet else ""))
    return 0


def _write_images(path: Path, times: np.ndarray, uv: np.ndarray, confidence: np.ndarray, low: np.ndarray) -> None:
    import numpy as np  # lazy: start-up (the command's run only)

    with open(path, "w", encoding="utf-8") as f:
        f.write("time,u_px,v_px,confidence,proposed_u_px,proposed_v_px\n")
        for t, (u, v), c, flagged in zip(times, uv, confidence, low, strict=True):
            proposed = f"{u:.3f},{v:.3f}" if np.isfinite(u) and np.isfinite(v) else ","
            kept = "," if flagged or not np.isfinite(u) else proposed
            f.write(f"{t:.6f},{kept},{c:.4f},{proposed}\n")


def _read_truth(path: str, times: np.ndarray) -> np.ndarray:
    """``(N, 2)`` true tips of the frames, paired by time (to the microsecond the truth file keeps)."""
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.data.formats.csv_log import read_table, to_float  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    file = Path(path)
    header, rows, records = read_table(file, ["time", "u_px", "v_px"])
    table = to_float(file, header, rows, records, ["time", "u_px", "v_px"])
    out = np.full((len(times), 2), np.nan)
    for k, t in enumerate(times):
        match = np.flatnonzero(np.abs(table[:, 0] - t) < 1e-5)
        if len(match) != 1:
            raise InputError(f"no single row for frame {k}'s time {t:.6f} s", file=file)
        out[k] = table[match[0], 1:]
    return out
