"""Calibration sessions, format ``brachycal-session/1`` (a folder; ``docs/conventions.md``).

- ``session.toml``: format, image spacing and size (and, optionally, the probe's imaging sector),
  the top-model tip on the needle flange (the SDA10F's right flange).
- ``touches.csv``: ``tool,reference,trial,<joints>``; tools ``top_model``, ``needle``,
  ``probe``; references ``rtip1`` (calibration) and ``rtip2`` (validation).
- ``axes.csv``: ``tool,point,<joints>``; tools ``needle``, ``probe``; points ``p1``–``p3``.
- ``samples.csv``: ``sample,<joints>,u_px,v_px``.

``<joints>`` are the robot's configuration columns (the SDA10F's 15 joints; another robot's from
its description, ``--robot``), radians, in any order. :func:`read_session` validates everything
before anything is computed and refuses with one line naming the file, row and column; a file
whose joint columns are another robot's is refused naming the missing and the unknown columns.
Values are converted to SI on reading (mm → m).
"""

from __future__ import annotations

import os
import tomllib
import warnings
from collections.abc import Collection, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.formats.csv_log import read_table, table_configurations, to_float, unique_names
from brachycal.data.json_files import shown
from brachycal.errors import BrachycalWarning, InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_text
from brachycal.io import OutputSet, atomic_open, output_set, sha256_file
from brachycal.se3 import FloatArray
from brachycal.validate import (
    MAX_IMAGE_PX,
    TOOL_LENGTH_M_RANGE,
    check_positions,
    check_range,
    check_spacing_mm,
    check_token,
)

if TYPE_CHECKING:  # annotations only: reading a file needs no Pinocchio
    from brachycal.model.robot import Robot

FORMAT = "brachycal-session/1"
FILES = ("session.toml", "touches.csv", "axes.csv", "samples.csv")
#: The files of a check session folder (``brachycal verify``'s CHECK_SESSION): the set-up, the
#: samples at the check's poses and the check's touches (header only when it has none).
CHECK_FILES = ("session.toml", "samples.csv", "touches.csv")
#: The tools a check's touches are by (the top-model is not: the result located the reference tips).
CHECK_TOOLS = ("needle", "probe")
#: Fewest samples a check reads: 3 points fix the image's 6 degrees of freedom; a check of fewer
#: has no redundancy against one mislabelled frame. ``plan check`` plans 5 or more.
MIN_CHECK_SAMPLES = 3
TOUCH_TOOLS = ("top_model", "needle", "probe")
REFERENCES = ("rtip1", "rtip2")
AXES_TOOLS = ("needle", "probe")
AXES_POINTS = ("p1", "p2", "p3")


@dataclass(frozen=True)
class Touches:
    """Touches of one tool on one reference tip: ``trials (T,)`` and configurations ``(T, nq)``."""

    trials: np.ndarray
    q: FloatArray


#: Deepest imaging sector, metres: ultrasound images reach about 0.3 m at most.
MAX_SECTOR_DEPTH_M = 0.5


@dataclass(frozen=True)
class ImageSector:
    """The imaging sector of a convex probe as ``session.toml`` states it (``[image.sector]``): the
    pixels that show tissue; the rest of the image is the scanner's black.

    Attributes:
        apex_px: ``(u, v)`` pixel of the sector's apex, the transducer's centre (it may lie above
            the image, ``v < 0``).
        depth_m: the sector's radius from the apex, metres.
        angle_rad: full opening angle, radians, symmetric about the image's +v (depth) direction.

    The planner's view of it (outline, fields of view) is :class:`~brachycal.planning.SectorFOV`.
    """

    apex_px: tuple[float, float]
    depth_m: float
    angle_rad: float

    def margin_to_edge(self, uv_px: ArrayLike, spacing_m: ArrayLike) -> FloatArray:
        """``(N,)`` distance in metres from each pixel ``(N, 2)`` to the sector's edge (pixel
        spacing ``spacing_m``, metres per pixel); negative outside."""
        d = (np.atleast_2d(np.asarray(uv_px, float)) - self.apex_px) * np.asarray(spacing_m)
        r = np.linalg.norm(d, axis=1)
        half = self.angle_rad / 2
        phi = np.arctan2(np.abs(d[:, 0]), d[:, 1])  # angle from the depth axis
        # The straight edges' distance holds for phi < half + 90 deg (the angle is at most 180 deg).
        return np.minimum(self.depth_m - r, r * np.sin(half - phi))


@dataclass(frozen=True, repr=False)
class Session:
    """A validated calibration session, SI units.

    Attributes:
        spacing_m: ``(2,)`` nominal pixel spacing ``(s_u, s_v)``, metres per pixel.
        size_px: ``(2,)`` image ``(width, height)`` in pixels.
        p_ER_Mtip: ``(3,)`` top-model tip on the needle flange (the SDA10F's right), metres.
        touches: ``(tool, reference)`` → :class:`Touches`, trials sorted.
        axes: tool → point (``p1``…``p3``) → configuration ``(nq,)``.
        sample_ids: ``(N,)`` sample names.
        samples_q: ``(N, nq)`` configurations of the image samples.
        uv_px: ``(N, 2)`` annotated needle-tip pixels.
        joint_names: names of the configuration columns.
        inputs: file name → SHA-256 of its bytes (empty for an in-memory session).
        sector: the probe's imaging sector, if ``session.toml`` states it (None: not stated).
    """

    spacing_m: FloatArray
    size_px: np.ndarray
    p_ER_Mtip: FloatArray
    touches: Mapping[tuple[str, str], Touches]
    axes: Mapping[str, Mapping[str, FloatArray]]
    sample_ids: list[str]
    samples_q: FloatArray
    uv_px: FloatArray
    joint_names: tuple[str, ...]
    inputs: dict[str, str] = field(default_factory=dict)
    sector: ImageSector | None = None

    def __repr__(self) -> str:
        """A few lines: what it holds, its image and its joints (the arrays themselves: the attributes)."""
        s_u, s_v = np.asarray(self.spacing_m) * 1e3
        trials = sum(len(t.q) for t in self.touches.values())
        return "\n".join(
            [
                f"Session: {len(self.sample_ids)} image samples, {trials} touches "
                f"({len(self.touches)} tool and tip pairs), axes moves of {len(self.axes)} tools",
                f"  images {int(self.size_px[0])} x {int(self.size_px[1])} px, "
                f"nominal spacing {s_u:.4f} x {s_v:.4f} mm/px",
                f"  {len(self.joint_names)} joints (radians); files: {', '.join(self.inputs) or 'none (in memory)'}",
            ]
        )


#: Largest trial number of a touch: a tip touched ten thousand times is a typo (and a trial near
#: the float limit would not fit a whole number).
MAX_TRIAL = 10_000


def _read_toml(
    path: Path, blank_ok: Collection[str] = ()
) -> tuple[FloatArray, np.ndarray, FloatArray, ImageSector | None]:
    try:
        config = tomllib.loads(read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"not valid TOML ({exc})", file=path) from None
    if config.get("format") != FORMAT:
        raise InputError(f"format is {shown(config.get('format'))}, expected {FORMAT!r}", file=path, key="format")

    def numbers(table: str, key: str, count: int, positive: bool) -> FloatArray:
        value = config.get(table, {}).get(key) if isinstance(config.get(table), dict) else None
        name = f"{table}.{key}"
        if value == [] and name in blank_ok:  # a template's blank, given by the caller instead
            return np.full(count, np.nan)
        if not isinstance(value, list) or len(value) != count:
            raise InputError(f"expected a list of {count} numbers", file=path, key=name)
        array = _floats(value, path, name)
        if not np.all(np.isfinite(array)) or (positive and np.any(array <= 0)):
            raise InputError(
                f"expected {'positive ' if positive else ''}finite numbers, got {shown(value)}", file=path, key=name
            )
        return array

    spacing_mm = numbers("image", "spacing_mm", 2, True)
    # Plausible for ultrasound (0.005..2 mm/px): a spacing in metres typed as mm is named so.
    if not np.isnan(spacing_mm).all():
        with _at_key(path, "image.spacing_mm"):
            spacing_mm = check_spacing_mm(spacing_mm, "pixel spacing")
    spacing_m = spacing_mm * 1e-3
    size = numbers("image", "size_px", 2, True)
    if np.isnan(size).all():
        size = np.zeros(2)  # blank, given by the caller
    elif np.any(size != np.round(size)):
        raise InputError("image size must be whole pixels", file=path, key="image.size_px")
    if np.any(size > MAX_IMAGE_PX):
        raise InputError(
            f"image size {size.tolist()!r} px: at most {MAX_IMAGE_PX} px a side", file=path, key="image.size_px"
        )
    image = config.get("image")
    sector = _read_sector(image.get("sector") if isinstance(image, dict) else None, path)
    tip_mm = numbers("top_model", "tip_in_flange_mm", 3, False)
    if np.isnan(tip_mm).all():
        return spacing_m, size.astype(int), tip_mm, sector  # blank, given by the caller
    with _at_key(path, "top_model.tip_in_flange_mm"):
        tip_m = check_positions(tip_mm * 1e-3, "the tip", limit=TOOL_LENGTH_M_RANGE[1], unit="m")
    return spacing_m, size.astype(int), tip_m, sector


@contextmanager
def _at_key(path: Path, key: str) -> Iterator[None]:
    """A check's refusal placed at ``key`` of the settings file ``path``."""
    try:
        yield
    except InputError as exc:
        raise InputError(exc.problem, file=path, key=key) from None


def _floats(value: list, path: Path, key: str) -> FloatArray:
    """A TOML list's numbers as floats; an integer beyond the float range is infinite (refused as not
    finite by the caller), anything else than a number refused here."""
    out = []
    for v in value:
        if not isinstance(v, int | float) or isinstance(v, bool):
            raise InputError(f"expected numbers, got {shown(value)}", file=path, key=key)
        try:
            out.append(float(v))
        except OverflowError:  # TOML's integers are unbounded: 10**400
            out.append(float(np.sign(v)) * np.inf)
    return np.array(out)


def _read_sector(table: object, path: Path) -> ImageSector | None:
    """``[image.sector]`` (``apex_px``, ``depth_mm``, ``angle_deg``) in SI units; None if absent."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise InputError("expected a table (apex_px, depth_mm, angle_deg)", file=path, key="image.sector")
    values: dict[str, FloatArray] = {}
    for key, count in (("apex_px", 2), ("depth_mm", 1), ("angle_deg", 1)):
        value = table.get(key)
        items = value if isinstance(value, list) else [value]
        if len(items) != count or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in items):
            what = "a list of 2 numbers" if count == 2 else "a number"
            raise InputError(f"expected {what}, got {shown(value)}", file=path, key=f"image.sector.{key}")
        numbers = _floats(items, path, f"image.sector.{key}")
        if not all(np.isfinite(numbers)):
            raise InputError(f"expected finite numbers, got {shown(value)}", file=path, key=f"image.sector.{key}")
        values[key] = numbers
    rules = (
        ("apex_px", -MAX_IMAGE_PX, MAX_IMAGE_PX, False, "px"),
        ("depth_mm", 0.0, MAX_SECTOR_DEPTH_M * 1e3, True, "mm"),
        ("angle_deg", 0.0, 180.0, True, "deg"),
    )
    for key, low, high, low_open, unit in rules:
        for v in values[key]:
            with _at_key(path, f"image.sector.{key}"):
                check_range(v, "", low=low, high=high, low_open=low_open, unit=unit)
    u, v = (float(x) for x in values["apex_px"])
    return ImageSector((u, v), float(values["depth_mm"][0]) * 1e-3, float(np.radians(values["angle_deg"][0])))


#: How far outside the stated imaging sector an annotated needle tip may lie, metres: annotation
#: noise of a few pixels and a sector's figures rounded to the millimetre and degree put a tip at the
#: sector's edge up to about this far out; beyond it the pixel shows the scanner's black, not tissue.
SECTOR_TOLERANCE_M = 1e-3


def check_sector_holds_samples(
    sector: ImageSector, spacing_m: ArrayLike, sample_ids: list[str], uv_px: ArrayLike, path: Path
) -> None:
    """Refuse an imaging sector (of ``session.toml`` at ``path``) that holds none of the annotated
    needle tips ``uv_px (N, 2)``: its apex, depth or angle is misstated (pixels outside a sector show
    no tissue, so no needle). Some tips outside it (by more than :data:`SECTOR_TOLERANCE_M`) give a
    :class:`~brachycal.errors.BrachycalWarning` naming the farthest: a misstated sector or a
    mis-annotated tip (the whole chain's outlier rule judges the tips; the sector only bounds the
    predicted landing error's map).

    Raises:
        InputError: no tip inside the sector (naming ``path`` and the key ``image.sector``).
    """
    margin = sector.margin_to_edge(uv_px, spacing_m)
    outside = margin < -SECTOR_TOLERANCE_M
    if not outside.any():
        return
    far = int(np.argmin(margin))
    u, v = (float(x) for x in np.asarray(uv_px, float)[far])
    nearest = float(-margin.max()) * 1e3
    if outside.all():
        raise InputError(
            f"the imaging sector holds none of the {len(margin)} annotated needle tips (the nearest "
            f"{nearest:.1f} mm outside it): its apex_px, depth_mm or angle_deg is misstated",
            file=path,
            key="image.sector",
        )
    warnings.warn(
        f"{path}: {int(outside.sum())} of {len(margin)} annotated needle tips lie outside the imaging sector "
        f"[image.sector] (farthest: sample {sample_ids[far]!r} at ({u:.0f}, {v:.0f}) px, "
        f"{-float(margin[far]) * 1e3:.1f} mm out): the sector or those annotations are misstated",
        BrachycalWarning,
        stacklevel=3,
    )


def read_session_toml(
    path: str | os.PathLike[str], *, blank_ok: Collection[str] = ()
) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """Read and validate a ``session.toml`` alone (e.g. a template for ``brachycal session build``).

    Args:
        blank_ok: keys (``"image.spacing_mm"``, ``"image.size_px"``, ``"top_model.tip_in_flange_mm"``)
            that may be left blank (``[]``, as ``brachycal session template`` writes them) because the
            caller gives their values; a blank comes back as NaN (spacing, tip) or zeros (size).

    Returns:
        ``spacing_m (2,)`` metres per pixel, ``size_px (2,)`` whole pixels, ``p_ER_Mtip (3,)`` metres.
    """
    return _read_toml(Path(path), frozenset(blank_ok))[:3]


def read_image_sector(path: str | os.PathLike[str]) -> ImageSector | None:
    """The imaging sector a ``session.toml`` states (``[image.sector]``), None if it states none.

    The file is validated as :func:`read_session_toml` does, its blank lists allowed (a template's).
    """
    blanks = ("image.spacing_mm", "image.size_px", "top_model.tip_in_flange_mm")
    return _read_toml(Path(path), frozenset(blanks))[3]


def _labels(
    path: Path, header: list[str], rows: list[int], records: list[list[str]], column: str, allowed: tuple[str, ...]
) -> list[str]:
    k = header.index(column)
    out = []
    for row, fields in zip(rows, records, strict=True):
        value = fields[k].strip()
        if value not in allowed:
            raise InputError(
                f"unknown {column} {value!r} (expected {', '.join(allowed)})", file=path, row=row, column=column
            )
        out.append(value)
    return out


#: Columns of each session CSV file besides the joints.
OWN_COLUMNS = {
    "touches.csv": ("tool", "reference", "trial"),
    "axes.csv": ("tool", "point"),
    "samples.csv": ("sample", "u_px", "v_px"),
}


def _listed(names: list[str], most: int = 4) -> str:
    shown = ", ".join(names[:most])
    return shown if len(names) <= most else f"{shown} and {len(names) - most} more"


def check_robot_columns(path: Path, header: list[str], robot: Robot) -> None:
    """Refuse a session file recorded on another robot: a joint of ``robot`` missing from ``header``.

    The refusal names the robot (its description's name when it has one), the missing joint columns
    and the columns that are neither the file's own (:data:`OWN_COLUMNS`) nor the robot's joints
    nor the mimic joints its controller publishes: another robot's joints, most likely.

    Raises:
        InputError: one line naming the file.
    """
    missing = [name for name in robot.joint_names if name not in header]
    if not missing:
        return  # extra columns are ignored, as in a joint log
    try:
        rig = robot.rig
        who, mimic = f"robot {rig.name!r}", set(rig.mimic_joints)
    except InputError:  # a model without a description: name its URDF
        who, mimic = f"the robot of {robot.source}", set()
    own = OWN_COLUMNS.get(path.name, ())
    extra = [h for h in header if h not in own and h not in robot.joint_names and h not in mimic]
    unknown = f"; unknown column(s) {_listed(extra)}" if extra else ""
    hint = ": recorded on another robot? pass its --robot" if extra else ""
    raise InputError(
        f"the joint columns are not those of {who}: missing {_listed(missing)} "
        f"({len(missing)} of {robot.nq}){unknown}{hint}",
        file=path,
    )


def _read_touches(path: Path, robot: Robot) -> dict[tuple[str, str], Touches]:
    header, rows, records = read_table(path, ["tool", "reference", "trial"])
    check_robot_columns(path, header, robot)
    tools = _labels(path, header, rows, records, "tool", TOUCH_TOOLS)
    references = _labels(path, header, rows, records, "reference", REFERENCES)
    trials = to_float(path, header, rows, records, ["trial"])[:, 0]
    for row, trial in zip(rows, trials, strict=True):
        if not (1 <= trial <= MAX_TRIAL and trial == round(trial)):
            raise InputError(
                f"trial must be a whole number from 1 to {MAX_TRIAL}, got {trial:g}", file=path, row=row, column="trial"
            )
    q = table_configurations(path, robot, header, rows, records)
    seen: dict[tuple[str, str, int], int] = {}
    for row, key in zip(rows, zip(tools, references, trials.astype(int), strict=True), strict=True):
        if key in seen:
            raise InputError(
                f"{key[0]} at {key[1]} trial {key[2]} appears twice (also row {seen[key]})", file=path, row=row
            )
        seen[key] = row
    touches: dict[tuple[str, str], Touches] = {}
    for tool in TOUCH_TOOLS:
        for reference in REFERENCES:
            mask = np.array([t == tool and r == reference for t, r in zip(tools, references, strict=True)])
            if not mask.any():
                raise InputError(f"no touches of {tool} at {reference}", file=path)
            order = np.argsort(trials[mask])
            touches[tool, reference] = Touches(trials[mask][order].astype(int), q[mask][order])
    for reference in REFERENCES:
        expected = touches["top_model", reference].trials
        for tool in ("needle", "probe"):
            got = touches[tool, reference].trials
            if not np.array_equal(got, expected):
                raise InputError(
                    f"unequal trials at {reference}: {tool} has {_list(got)}, top_model has {_list(expected)}; "
                    "validation pairs them trial by trial",
                    file=path,
                )
    return touches


def _list(values: np.ndarray) -> str:
    return "[" + ", ".join(str(int(v)) for v in values) + "]"


def _read_axes(path: Path, robot: Robot) -> dict[str, dict[str, FloatArray]]:
    header, rows, records = read_table(path, ["tool", "point"])
    check_robot_columns(path, header, robot)
    tools = _labels(path, header, rows, records, "tool", AXES_TOOLS)
    points = _labels(path, header, rows, records, "point", AXES_POINTS)
    q = table_configurations(path, robot, header, rows, records)
    axes: dict[str, dict[str, FloatArray]] = {tool: {} for tool in AXES_TOOLS}
    for row, tool, point, config in zip(rows, tools, points, q, strict=True):
        if point in axes[tool]:
            raise InputError(f"{tool} {point} appears twice", file=path, row=row)
        axes[tool][point] = config
    for tool in AXES_TOOLS:
        for point in AXES_POINTS:
            if point not in axes[tool]:
                raise InputError(f"missing axes point {point} for {tool}", file=path)
    return axes


def read_sample_table(path: Path, robot: Robot, size_px: np.ndarray) -> tuple[list[str], FloatArray, FloatArray]:
    """``(ids, q (N, nq) radians, uv (N, 2) px)`` of a ``samples.csv``: unique sample names, the robot's
    joint columns, annotated tips inside the ``size_px`` image; one-line refusals naming row and column.
    How many samples are enough is the caller's to say (a session's, a check's)."""
    header, rows, records = read_table(path, ["sample", "u_px", "v_px"])
    check_robot_columns(path, header, robot)
    ids = unique_names(path, header, rows, records, "sample")
    uv = to_float(path, header, rows, records, ["u_px", "v_px"])
    for axis, name in enumerate(("u_px", "v_px")):
        bad = ~np.isfinite(uv[:, axis]) | (uv[:, axis] < -0.5) | (uv[:, axis] > size_px[axis] - 0.5)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(
                f"{uv[i, axis]:g} is outside the image (0..{size_px[axis] - 1} px)", file=path, row=rows[i], column=name
            )
    q = table_configurations(path, robot, header, rows, records)
    refuse_repeated_rows(path, rows, np.hstack([q, uv]), [f"sample {name!r}" for name in ids], "joints and pixel")
    return ids, q, uv


def refuse_repeated_rows(path: Path, rows: list[int], values: FloatArray, names: list[str], what: str) -> None:
    """Refuse a row whose numbers ``values[i]`` are exactly an earlier row's: a row copied under
    another name (a sample) would count twice in a fit. Two real holds of a robot differ at least
    by encoder noise, so only a copy repeats every number. (Touches copied as another trial are
    refused by the estimator, :func:`~brachycal.calibration.sequential.tool_tips.check_distinct_touches`.)

    Raises:
        InputError: naming the repeating row, both names and the row it repeats.
    """
    if len(values) < 2:
        return
    _, first, inverse = np.unique(values, axis=0, return_index=True, return_inverse=True)
    earliest = first[inverse.ravel()]
    repeats = np.flatnonzero(earliest != np.arange(len(values)))
    if repeats.size:
        i = int(repeats[0])
        j = int(earliest[i])
        raise InputError(
            f"{names[i]} has the {what} of {names[j]} (row {rows[j]}): a copied row would count twice; remove it",
            file=path,
            row=rows[i],
        )


def _read_samples(path: Path, robot: Robot, size_px: np.ndarray) -> tuple[list[str], FloatArray, FloatArray]:
    ids, q, uv = read_sample_table(path, robot, size_px)
    if len(ids) < 3:
        raise InputError(f"{len(ids)} samples: at least 3 with non-collinear image points are needed", file=path)
    centred = uv - uv.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if s[0] == 0 or s[1] / s[0] < 1e-6:
        raise InputError("the annotated image points are collinear: the image rotation is undetermined", file=path)
    return ids, q, uv


def read_session(folder: str | os.PathLike[str], robot: Robot) -> Session:
    """Read and validate a session folder; nothing is computed from a half-valid session."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("not a session folder (expected a folder with session.toml)", file=folder)
    for name in FILES:
        if not os.path.lexists(folder / name):  # anything else there is refused by its reader
            raise InputError("missing session file", file=folder / name)
    spacing_m, size_px, p_ER_Mtip, sector = _read_toml(folder / "session.toml")
    touches = _read_touches(folder / "touches.csv", robot)
    axes = _read_axes(folder / "axes.csv", robot)
    ids, samples_q, uv = _read_samples(folder / "samples.csv", robot, size_px)
    if sector is not None:
        check_sector_holds_samples(sector, spacing_m, ids, uv, folder / "session.toml")
    return Session(
        spacing_m=spacing_m,
        size_px=size_px,
        p_ER_Mtip=p_ER_Mtip,
        touches=touches,
        axes=axes,
        sample_ids=ids,
        samples_q=samples_q,
        uv_px=uv,
        joint_names=robot.joint_names,
        inputs={name: sha256_file(folder / name) for name in FILES},
        sector=sector,
    )


def _q_fields(q: FloatArray) -> str:
    return ",".join(repr(float(x)) for x in q)


def _sector_toml(sector: ImageSector | None) -> str:
    """``[image.sector]`` as :func:`write_session` writes it ("" when the session states none)."""
    if sector is None:
        return ""
    u, v = (float(x) for x in sector.apex_px)
    # 12 significant digits: a sector's figures are a scanner's settings (70 mm, 120 deg), not a
    # round trip's last bits (120 deg comes back from radians as 119.99999999999999)
    return (
        "[image.sector]                # the probe's imaging sector (pixels outside it show no tissue)\n"
        f"apex_px = [{u:.12g}, {v:.12g}]        # (u, v) of the apex, the transducer's centre\n"
        f"depth_mm = {sector.depth_m * 1e3:.12g}\n"
        f"angle_deg = {np.degrees(sector.angle_rad):.12g}               # full opening, symmetric about +v\n\n"
    )


def _write_toml(out: OutputSet, folder: Path, session: Session, force: bool) -> None:
    su, sv = (float(v) for v in session.spacing_m * 1e3)
    tip = ", ".join(repr(float(v)) for v in session.p_ER_Mtip * 1e3)
    with atomic_open(out.path(folder / "session.toml", make_parents=True), force=force) as f:
        f.write(
            f'format = "{FORMAT}"\n\n[image]\nspacing_mm = [{su!r}, {sv!r}]     # (s_u, s_v)\n'
            f"size_px = [{int(session.size_px[0])}, {int(session.size_px[1])}]         # (width, height)\n\n"
            f"{_sector_toml(session.sector)}"
            f"[top_model]\ntip_in_flange_mm = [{tip}]   # p_ER_Mtip\n"
        )


def _write_touches(out: OutputSet, folder: Path, session: Session, force: bool) -> None:
    with atomic_open(out.path(folder / "touches.csv", make_parents=True), force=force) as f:
        f.write(f"tool,reference,trial,{','.join(session.joint_names)}\n")
        for (tool, reference), touches in session.touches.items():
            for trial, q in zip(touches.trials, touches.q, strict=True):
                f.write(f"{tool},{reference},{int(trial)},{_q_fields(q)}\n")


def _write_samples(out: OutputSet, folder: Path, session: Session, force: bool) -> None:
    for sample in session.sample_ids:  # written as they are: a comma or a quote would break the row
        check_token(sample, "sample")
    with atomic_open(out.path(folder / "samples.csv", make_parents=True), force=force) as f:
        f.write(f"sample,{','.join(session.joint_names)},u_px,v_px\n")
        for sample, q, (u, v) in zip(session.sample_ids, session.samples_q, session.uv_px, strict=True):
            f.write(f"{sample},{_q_fields(q)},{float(u)!r},{float(v)!r}\n")


def write_session(
    session: Session, folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None
) -> Path:
    """Write a session folder (:data:`FILES`, all or nothing); the folder is created if needed.

    With ``outputs`` (a command's :class:`~brachycal.io.OutputSet`) the files join that set.
    """
    folder = Path(folder)
    with output_set(outputs, force=force) as out:
        _write_samples(out, folder, session, force)
        _write_toml(out, folder, session, force)
        _write_touches(out, folder, session, force)
        with atomic_open(out.path(folder / "axes.csv", make_parents=True), force=force) as f:
            f.write(f"tool,point,{','.join(session.joint_names)}\n")
            for tool, points in session.axes.items():
                for point, q in points.items():
                    f.write(f"{tool},{point},{_q_fields(q)}\n")
    return folder


def write_check_session(
    session: Session, folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None
) -> Path:
    """Write a check session folder (:data:`CHECK_FILES`, all or nothing): ``session``'s set-up,
    samples and touches (its axes, if any, are not part of a check). ``touches.csv`` is written even
    without touches (its header alone), so that a rewritten check never keeps an earlier one's."""
    folder = Path(folder)
    with output_set(outputs, force=force) as out:
        _write_samples(out, folder, session, force)
        _write_toml(out, folder, session, force)
        _write_touches(out, folder, session, force)
    return folder
