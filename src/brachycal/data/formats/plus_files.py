"""PLUS toolkit files: device-set configuration, calibration results XML, tracker readings of sequence files.

Read with ``defusedxml`` (no entity expansion, no external entities): these files come from
other machines. Every refusal is one :class:`~brachycal.errors.InputError` naming the file and,
where it applies, the frame and the element or field. PLUS works in millimetres; these readers
convert to metres (brachycal's unit inside) and say so in the field names of what they return.

Every tracker reading and the phantom registration are checked to be rigid
(:func:`brachycal.validate.check_transform`): a scaled or sheared matrix read as a pose would
give a wrong calibration with a normal-looking error report.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree.ElementTree import Element

import defusedxml.ElementTree as SafeET
import numpy as np

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_bytes
from brachycal.se3 import FloatArray, inverse
from brachycal.validate import MAX_POSITION_M, check_transform, number_from_text, numbers_from_text, whole_from_text

MM = 1e-3

#: Largest deviation from orthonormality (max entry of ``RᵀR − I``, and ``|det R − 1|``) accepted
#: in the matrices the N-wire calibration uses: ProbeToTracker, ReferenceToTracker, Phantom→Reference.
#: PLUS writes 6 significant digits, which alone leaves up to ~2.6e-6 (1.5e-6 measured on PLUS's
#: fCal recording). A deviation ε distorts a point at distance r from the marker by at most ~1.5·ε·r;
#: the wire points lie within 0.09 m of the reference marker and 0.055 m of the probe marker on the
#: fCal 2.0 phantom, so 1e-4 bounds the distortion at ~0.02 mm — under 5 % of the 0.54 mm validation
#: error PLUS reports on that recording — while any real scaling or shear (×1.5 is off by 1.25) is refused.
NWIRE_RIGID_TOLERANCE = 1e-4
#: The same bound for tracker readings in a sequence-file header (:func:`sequence_transform`).
#: Trackers that filter or interpolate their poses write matrices a little off orthonormal: up to
#: 5e-4 in PLUS's own temporal-calibration recording (WaterTankBottomTranslationTrackerBuffer).
#: 1e-3 accepts those and still refuses a scale or shear of more than ~0.1 %.
TRACKER_RIGID_TOLERANCE = 1e-3

_Fail = Callable[[str], InputError]


@dataclass(frozen=True)
class Wire:
    """A phantom wire: name and its end points in the phantom frame, metres ``(3,)``."""

    name: str
    front_m: FloatArray
    back_m: FloatArray


#: PLUS's default names of the frames its probe calibration joins (``vtkPlusProbeCalibrationAlgo``'s
#: ``PhantomCoordinateFrame`` and ``ReferenceCoordinateFrame`` attributes, when the device set has none).
DEFAULT_PHANTOM_FRAME = "Phantom"
DEFAULT_REFERENCE_FRAME = "Reference"
#: The elements that hold coordinate definitions: a device set's, and a results file's calibration.
_DEFINITION_PARENTS = ("CoordinateDefinitions", "CalibrationResults")


@dataclass(frozen=True)
class PlusOptimization:
    """PLUS fCal's refinement setting in a device set (``vtkPlusProbeCalibrationAlgo`` attributes).

    Attributes:
        method: ``"NONE"``, ``"2D"`` (all wires' in-plane distance) or ``"3D"`` (middle wires' 3D distance).
        isotropic: ``IsotropicPixelSpacing`` (one pixel size for u and v).
    """

    method: str
    isotropic: bool


@dataclass(frozen=True)
class PlusConfig:
    """What the N-wire calibration needs from a PLUS device-set configuration.

    Attributes:
        patterns: the N-wire patterns, each three wires (side, diagonal, side) in file order.
        transforms: ``(From, To)`` → ``T_To_From (4, 4)`` from ``CoordinateDefinitions``
            (translations in metres; a scaling transform such as Image→Probe keeps its matrix).
            The phantom registration is always under ``("Phantom", "Reference")`` (whatever the
            device set names those frames, and inverted if the file holds Reference→Phantom), checked
            to be rigid.
        approximate_spacing_m: the segmentation's approximate pixel spacing (metres per pixel).
        source: the file it was read from (for messages), None if built in code.
        optimization: PLUS's ``OptimizationMethod`` setting in the file, None if it states none.
    """

    patterns: list[tuple[Wire, Wire, Wire]]
    transforms: dict[tuple[str, str], FloatArray]
    approximate_spacing_m: float | None
    source: str | None = None
    optimization: PlusOptimization | None = None


def _parse(path: Path) -> Element:
    try:
        return SafeET.fromstring(read_input_bytes(path, max_bytes=MAX_DOCUMENT_BYTES))
    except InputError:
        raise
    except SafeET.ParseError as exc:
        raise InputError(f"not valid XML ({exc})", file=path) from None
    except Exception as exc:  # defusedxml's refusals of entities and DTDs
        raise InputError(f"refused unsafe XML ({type(exc).__name__})", file=path) from None


def find_section(root: Element, tag: str) -> tuple[Element | None, str]:
    """The ``tag`` element under ``root`` — a child, else the first anywhere below (device sets nest
    sections differently) — and where it is, XPath-like (``PlusConfiguration/Segmentation`` or
    ``PlusConfiguration//Segmentation``) for a refusal that names it."""
    element = root.find(tag)
    if element is not None:
        return element, f"{root.tag}/{tag}"
    return next(root.iter(tag), None), f"{root.tag}//{tag}"


def parse_xml(path: str | os.PathLike[str]) -> Element:
    """The root element of an XML file read safely (no entities, no DTDs).

    Raises:
        InputError: naming the file, when it cannot be read, is not XML or is refused as unsafe.
    """
    return _parse(Path(path))


#: Largest magnitude of any number of a PLUS file: its lengths are millimetres (positions within
#: :data:`~brachycal.validate.MAX_POSITION_M`), its other numbers pixels, rotations or spacings.
_LARGEST = MAX_POSITION_M / MM


def _numbers(text: str | None, count: int, fail: _Fail) -> FloatArray:
    numbers = f"{count} finite number{'s' if count > 1 else ''}"
    parsed = numbers_from_text(text or "")
    if parsed is None:
        raise fail(f"expected {numbers}, got {text!r}")
    values = np.array(parsed, dtype=float)
    if values.size != count or not np.all(np.isfinite(values)):
        raise fail(f"expected {numbers}, got {text!r}")
    if not np.all(np.abs(values) <= _LARGEST):  # 1e308 as a wire's end would overflow in the fits
        raise fail(f"expected {numbers} within ±{_LARGEST:g} (millimetres, pixels), got {text!r}")
    return values


def _check_rigid(T: FloatArray, fail: _Fail, tolerance: float) -> FloatArray:
    try:
        return check_transform(T, "matrix", tolerance=tolerance)
    except InputError as exc:  # re-raised with the file's own place (frame, field)
        raise fail(exc.problem) from None


def _rigid_mm(text: str | None, fail: _Fail, tolerance: float) -> FloatArray:
    """A rigid 4×4 written row-major in millimetres, returned with its translation in metres."""
    T = _check_rigid(_numbers(text, 16, fail).reshape(4, 4), fail, tolerance)
    T = T.copy()
    T[:3, 3] *= MM
    return T


def _metres(M: FloatArray) -> FloatArray:
    M = M.copy()
    M[:3, 3] *= MM
    return M


def _in_element(path: Path, place: str) -> _Fail:
    """A function making the InputError for one XML element (or attribute) of ``path``, named XPath-like."""

    def fail(message: str) -> InputError:
        return InputError(f"{place}: {message}", file=path)

    return fail


def _transform_place(parent: str, key: tuple[str, str]) -> str:
    return f"{parent}/Transform[@From='{key[0]}'][@To='{key[1]}']"


def _coordinate_definitions(root: Element, path: Path) -> dict[tuple[str, str], FloatArray]:
    """Every ``Transform`` defined under ``CoordinateDefinitions`` or ``CalibrationResults``, mm.

    Only those: a ``<Transform Name="ProbeToTracker"/>`` elsewhere (PLUS 1.x ``DataCollection``,
    an OpenIGTLink server's ``TransformNames``) names a transform to send or record, not a matrix.
    """
    out: dict[tuple[str, str], FloatArray] = {}
    parents = [(root.tag, root)] if root.tag in _DEFINITION_PARENTS else []
    parents += [(f"{root.tag}/{e.tag}", e) for e in root if e.tag in _DEFINITION_PARENTS]
    if not parents:  # nested deeper in a layout we have not seen: still only these parents
        parents = [(f"{root.tag}//{e.tag}", e) for tag in _DEFINITION_PARENTS for e in root.iter(tag)]
    for parent_place, parent in parents:
        for element in parent.findall("Transform"):
            key = (element.get("From", ""), element.get("To", ""))
            fail = _in_element(path, _transform_place(parent_place, key))
            if not all(key):
                raise fail("a coordinate definition needs both From and To attributes")
            if key in out:
                raise fail("defined twice")
            M = _numbers(element.get("Matrix"), 16, _in_element(path, _transform_place(parent_place, key) + "/@Matrix"))
            M = M.reshape(4, 4)
            if np.abs(M[3] - [0, 0, 0, 1]).max() > 1e-9:
                raise fail("bottom row of the matrix must be 0 0 0 1")
            out[key] = M
    return out


def read_coordinate_definitions(path: str | os.PathLike[str]) -> dict[tuple[str, str], FloatArray]:
    """``(From, To)`` → matrix ``(4, 4)`` of every coordinate definition in a PLUS XML, in the file's units (mm).

    Reads device sets (``CoordinateDefinitions``) and calibration results (``CalibrationResults``)
    alike; matrices are returned as written (Image→Probe carries the pixel scales). ``Transform``
    elements elsewhere (transform names to record or send) are not definitions and are skipped.
    """
    path = Path(path)
    return _coordinate_definitions(_parse(path), path)


def _calibration_settings(root: Element) -> tuple[str, str, PlusOptimization | None]:
    """Phantom and reference frame names and PLUS's refinement setting of the probe calibration element."""
    element = next(
        (e for tag in ("vtkPlusProbeCalibrationAlgo", "vtkProbeCalibrationAlgo") for e in root.iter(tag)), None
    )
    if element is None:
        return DEFAULT_PHANTOM_FRAME, DEFAULT_REFERENCE_FRAME, None
    method = element.get("OptimizationMethod")
    optimization = None
    if method is not None and method.upper() in {"NONE", "2D", "3D"}:
        isotropic = (element.get("IsotropicPixelSpacing") or "FALSE").strip().upper() == "TRUE"
        optimization = PlusOptimization(method.upper(), isotropic)
    return (
        element.get("PhantomCoordinateFrame") or DEFAULT_PHANTOM_FRAME,
        element.get("ReferenceCoordinateFrame") or DEFAULT_REFERENCE_FRAME,
        optimization,
    )


def read_plus_config(path: str | os.PathLike[str], *, require_registration: bool = True) -> PlusConfig:
    """Read the phantom definition and coordinate definitions of a PLUS device-set XML.

    Every layout PLUS has shipped keeps the phantom's wires in ``PhantomDefinition/Geometry/Pattern``
    and the phantom registration in ``CoordinateDefinitions`` (the frames it joins named by the
    ``vtkPlusProbeCalibrationAlgo`` element, ``Phantom`` → ``Reference`` by default; a
    Reference → Phantom definition is inverted). ``Transform`` elements outside
    ``CoordinateDefinitions`` (PLUS 1.x ``DataCollection`` and OpenIGTLink ``TransformNames``) only
    name transforms and are not read.

    Args:
        path: the device set.
        require_registration: refuse a file without the phantom registration (the N-wire method
            needs it); False reads the phantom alone (e.g. a temporal-calibration device set).

    Raises:
        InputError: unreadable or unsafe XML, no ``PhantomDefinition`` or no N-wire ``Pattern`` in
            it, an N-wire pattern without exactly three named wires, a wire name used twice, a
            phantom registration that is missing (with ``require_registration``) or not rigid
            (:data:`NWIRE_RIGID_TOLERANCE`), a pixel spacing that is not a positive number — each
            naming the element XPath-like (``PlusConfiguration/PhantomDefinition/Geometry/Pattern[1]``).
    """
    path = Path(path)
    root = _parse(path)
    top = root.tag
    phantom, phantom_place = find_section(root, "PhantomDefinition")
    if phantom is None:
        raise InputError(f"no N-wire patterns: missing {top}/PhantomDefinition (the phantom's wires)", file=path)
    pattern_elements = phantom.findall("Geometry/Pattern") or list(phantom.iter("Pattern"))
    nwire_elements = [p for p in pattern_elements if p.get("Type") == "NWire"]
    if not nwire_elements:
        raise InputError(
            f"no N-wire patterns: missing {phantom_place}/Geometry/Pattern[@Type='NWire']",
            file=path,
        )
    patterns: list[tuple[Wire, Wire, Wire]] = []
    seen: set[str] = set()
    for k, pattern in enumerate(nwire_elements):
        place = f"{phantom_place}/Geometry/Pattern[{k + 1}]"
        wires: list[Wire] = []
        for wire in pattern.iter("Wire"):
            name = wire.get("Name")
            wire_place = f"{place}/Wire[@Name='{name}']" if name else f"{place}/Wire[{len(wires) + 1}]"
            fail = _in_element(path, wire_place)
            if not name:
                raise fail("a wire needs a Name (the segmented points refer to it)")
            if name in seen:
                raise fail("wire name used twice in the phantom definition")
            seen.add(name)
            wires.append(
                Wire(
                    name,
                    _numbers(wire.get("EndPointFront"), 3, _in_element(path, wire_place + "/@EndPointFront")) * MM,
                    _numbers(wire.get("EndPointBack"), 3, _in_element(path, wire_place + "/@EndPointBack")) * MM,
                )
            )
        if len(wires) != 3:
            raise InputError(f"{place}: an N-wire pattern has {len(wires)} wires, expected 3", file=path)
        _check_n_shape(wires, _in_element(path, place))
        patterns.append((wires[0], wires[1], wires[2]))
    definitions = _coordinate_definitions(root, path)
    phantom_frame, reference_frame, optimization = _calibration_settings(root)
    transforms = {key: _metres(M) for key, M in definitions.items()}
    forward, backward = (phantom_frame, reference_frame), (reference_frame, phantom_frame)
    registration_place = _transform_place(f"{top}/CoordinateDefinitions", forward)
    if forward in definitions or backward in definitions:
        key = forward if forward in definitions else backward
        place = _transform_place(f"{top}/CoordinateDefinitions", key) + f" ({key[0]}->{key[1]})"
        T = _check_rigid(transforms[key], _in_element(path, place), NWIRE_RIGID_TOLERANCE)
        transforms["Phantom", "Reference"] = T if key == forward else inverse(T)
    elif require_registration:
        stepper = next(root.iter("iCal"), None) is not None
        hint = " (a stepper's phantom is registered by `brachycal stepper image`)" if stepper else ""
        raise InputError(
            f"no phantom registration: missing {registration_place} ({phantom_frame}->{reference_frame}){hint}",
            file=path,
        )
    spacing_m = None
    segmentation = root.find("Segmentation")
    if segmentation is None:
        segmentation = next((e for e in root.iter("Segmentation") if "ApproximateSpacingMmPerPixel" in e.attrib), None)
    spacing = segmentation.get("ApproximateSpacingMmPerPixel") if segmentation is not None else None
    if spacing is not None:
        place = f"{top}/Segmentation/@ApproximateSpacingMmPerPixel"
        value = _numbers(spacing, 1, _in_element(path, place))[0]
        if value <= 0:
            raise InputError(f"{place}: must be a positive spacing, got {spacing!r}", file=path)
        spacing_m = float(value) * MM
    return PlusConfig(patterns, transforms, spacing_m, str(path), optimization)


def _check_n_shape(wires: list[Wire], fail: _Fail) -> None:
    """Three wires of non-zero length whose sides are not parallel to the diagonal (an N, not a ||)."""
    directions = [w.back_m - w.front_m for w in wires]
    for wire, d in zip(wires, directions, strict=True):
        if not np.linalg.norm(d) > 0.0:
            raise fail(f"wire {wire.name!r} has the same front and back end points")
    diagonal = directions[1] / np.linalg.norm(directions[1])
    for side in (0, 2):
        # sine of the angle between side and diagonal; PLUS's phantoms have ~0.45 (27°)
        if np.linalg.norm(np.cross(directions[side] / np.linalg.norm(directions[side]), diagonal)) < 1e-6:
            raise fail(f"side wire {wires[side].name!r} is parallel to the diagonal {wires[1].name!r}: not an N")


def _at(
    path: Path,
    *,
    row: int | None = None,
    row_label: str = "row",
    column: str | None = None,
    element: str | None = None,
) -> _Fail:
    """A function making the InputError for one place of ``path`` (``element``: an XML child, XPath-like)."""

    def fail(message: str) -> InputError:
        text = f"{element}: {message}" if element is not None else message
        return InputError(text, file=path, row=row, row_label=row_label, column=column)

    return fail


@dataclass(frozen=True)
class SegmentedFrame:
    """One tracked ultrasound frame with its segmented wire intersections.

    Attributes:
        index: frame index in its set.
        ok: PLUS's segmentation status (the image alone: a frame is segmented whatever its poses).
        points_px: wire name → ``(u, v)`` pixel of the segmented intersection.
        T_tracker_probe, T_tracker_reference: ``(4, 4)`` the probe's and the reference's poses in
            the pose source's base frame (a tracker's, or a stepper's ``StepperHome``), metres,
            rigid; None where the recording has no OK pose for the frame.
        plus_middle_probe_m: PLUS's own middle-wire points in the probe frame (if the file has
            them), ``(K, 3)`` metres — used only to check our geometry against PLUS's.
        source: file it was read from (None if built in code), for messages.
        label: what ``index`` counts in that file (``"CalibrationData Frame"``), for messages.
        pose_status: the recording's status of each pose (``OK``; ``MISSING`` where the frame has
            no reading; PLUS's ``INVALID``, ``OUT_OF_VIEW``… as recorded).
        pose_names: the frame fields the poses came from (PLUS's ``<From>To<To>Transform``).
    """

    index: int
    ok: bool
    points_px: dict[str, FloatArray] = field(default_factory=dict)
    T_tracker_probe: FloatArray | None = None
    T_tracker_reference: FloatArray | None = None
    plus_middle_probe_m: FloatArray | None = None
    source: str | None = None
    label: str = "frame"
    pose_status: tuple[str, str] = ("OK", "OK")
    pose_names: tuple[str, str] = ("ProbeToTrackerTransform", "ReferenceToTrackerTransform")

    @property
    def usable(self) -> bool:
        """Segmented, and neither pose recorded as missing: a frame a calibration uses (one whose
        status is OK but whose pose is None is refused there, naming it)."""
        return self.ok and all(status == "OK" for status in self.pose_status)


def _frames(
    parent: Element | None, path: Path, which: str, tolerance: float, names: tuple[str, str]
) -> list[SegmentedFrame]:
    if parent is None:
        raise InputError(f"no <{which}> element", file=path)
    label = f"{which} Frame"  # the XML element: <ValidationData><Frame Index=…>
    frames: list[SegmentedFrame] = []
    seen: set[int] = set()
    for element in parent.findall("Frame"):
        text = element.get("Index", str(len(frames)))
        index = whole_from_text(text.strip())
        if index is None:
            raise InputError(
                f"Frame Index must be a whole number, got {text!r}", file=path, row=len(frames), row_label=label
            )
        fail = _at(path, row=index, row_label=label)
        if index in seen:
            raise fail("frame index appears twice")
        seen.add(index)
        if element.get("SegmentationStatus") != "OK":
            frames.append(SegmentedFrame(index, False, source=str(path), label=label))
            continue
        points: dict[str, FloatArray] = {}
        segmented = element.find("SegmentedPoints")
        for point in segmented if segmented is not None else []:
            name = point.get("WireName")
            if not name:
                raise fail("a segmented <Point> has no WireName")
            if name in points:
                raise fail(f"wire {name!r} segmented twice")
            points[name] = _numbers(
                point.get("Position"), 3, _at(path, row=index, row_label=label, element=f"Point[@WireName='{name}']")
            )[:2]
        fields = {f.get("Name"): f.get("Value") for f in element.iter("CustomFrameField")}
        tracked: dict[str, FloatArray | None] = {}
        status: dict[str, str] = {}
        for name in names:
            status[name] = (fields.get(name + "Status") or "OK").strip()
            if status[name] != "OK":  # segmented, but no pose: kept, not used by a calibration
                tracked[name] = None
                continue
            if name not in fields:
                raise fail(f"missing {name} (TrackedFrame/CustomFrameField[@Name='{name}'])")
            where = _at(path, row=index, row_label=label, element=f"CustomFrameField[@Name='{name}']")
            tracked[name] = _rigid_mm(fields[name], where, tolerance)
        middle = [_numbers(m.get("PositionInProbeFrame"), 4, fail)[:3] * MM for m in element.iter("MiddleWire")]
        frames.append(
            SegmentedFrame(
                index,
                True,
                points,
                tracked[names[0]],
                tracked[names[1]],
                np.array(middle) if middle else None,
                source=str(path),
                label=label,
                pose_status=(status[names[0]], status[names[1]]),
                pose_names=names,
            )
        )
    return frames


def read_segmented_frames(
    path: str | os.PathLike[str],
    *,
    tolerance: float = NWIRE_RIGID_TOLERANCE,
    poses: tuple[str, str] = ("ProbeToTrackerTransform", "ReferenceToTrackerTransform"),
) -> tuple[list[SegmentedFrame], list[SegmentedFrame]]:
    """``(calibration frames, validation frames)`` of a PLUS probe-calibration results XML.

    Reads PLUS's whole results file (frames under ``<ErrorReport>``) and the stripped form that
    keeps only the inputs (frames under ``<Data>``). Frames whose segmentation failed are kept with
    ``ok=False``; the others must carry named wire points and, for each tracker reading, either a
    rigid matrix or a status other than ``OK`` (a frame segmented without its pose, kept with that
    pose None: not :attr:`SegmentedFrame.usable`).

    Args:
        path: the results file.
        tolerance: rigidity demanded of the tracker readings (:data:`NWIRE_RIGID_TOLERANCE`).
        poses: the frame fields of the probe's and the reference's poses (a tracker's by default;
            :attr:`PoseStreams.fields` of a stepper's: ``ProbeToStepperHomeTransform``,
            ``TemplateToStepperHomeTransform``).

    Raises:
        InputError: one line naming the file, the frame and the field of the first problem.
    """
    path = Path(path)
    root = _parse(path)
    data = next(
        (
            e
            for e in (root.find("Data"), root.find("ErrorReport"))
            if e is not None and e.find("CalibrationData") is not None
        ),
        None,
    )
    if data is None:
        raise InputError(
            "no <Data> or <ErrorReport> element with <CalibrationData> (not a PLUS calibration results file)",
            file=path,
        )
    return (
        _frames(data.find("CalibrationData"), path, "CalibrationData", tolerance, poses),
        _frames(data.find("ValidationData"), path, "ValidationData", tolerance, poses),
    )


def sequence_transform(
    fields: dict[str, str],
    name: str,
    path: str | os.PathLike[str],
    frame: int,
    *,
    tolerance: float = TRACKER_RIGID_TOLERANCE,
) -> FloatArray | None:
    """``(4, 4)`` rigid transform ``name`` of one sequence frame in metres, or None if its status is not OK.

    Raises:
        InputError: naming the file, the frame and the transform, if it is not 16 finite numbers
            or not rigid within ``tolerance`` (:data:`TRACKER_RIGID_TOLERANCE`).
    """
    if fields.get(name + "Status", "OK") != "OK" or name not in fields:
        return None
    return _rigid_mm(fields[name], _at(Path(path), row=frame, row_label="frame", column=name), tolerance)


def pose_status(fields: dict[str, str], name: str) -> str:
    """The recording's status of transform ``name`` in one frame: its ``<name>Status`` field
    (``OK`` if it has none), ``MISSING`` if the frame has no such transform."""
    status = (fields.get(name + "Status") or "OK").strip()
    return "MISSING" if status == "OK" and name not in fields else status


#: PLUS's name of a transform, ``<From>To<To>`` (its frame field is the name + ``Transform``).
TRANSFORM_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*To[A-Z][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class PoseStreams:
    """Which frame fields of a recording are the probe's and the reference's poses.

    Attributes:
        probe: the probe's pose, PLUS's transform name (``ProbeToTracker``, ``ProbeToStepperHome``).
        reference: the reference body's pose in the same base frame (``ReferenceToTracker``; on a
            brachytherapy stepper the template's, ``TemplateToStepperHome``).
        source: ``"tracker"`` or ``"stepper"`` (the device set's pose source), or ``"options"``.
    """

    probe: str = "ProbeToTracker"
    reference: str = "ReferenceToTracker"
    source: str = "tracker"

    @property
    def fields(self) -> tuple[str, str]:
        """The sequence's frame fields: ``(probe + "Transform", reference + "Transform")``."""
        return self.probe + "Transform", self.reference + "Transform"


def _attribute(element: Element | None, name: str, default: str | None) -> str | None:
    value = element.get(name) if element is not None else None
    return value.strip() if value is not None and value.strip() else default


def read_pose_streams(path: str | os.PathLike[str]) -> PoseStreams:
    """The pose streams a PLUS device set records: a tracker's or a brachytherapy stepper's.

    A stepper device set (a ``BrachyTracker`` device or an ``iCal`` element: PLUS's TRUS-on-stepper
    set-up) records ``<Probe>To<Base>`` and ``<Template>To<Base>`` from the stepper's encoders, the
    frame names from its ``iCal`` element (``ProbeCoordinateFrame``, ``TemplateCoordinateFrame``)
    and the probe calibration's ``ReferenceCoordinateFrame`` (``StepperHome``). Any other device set
    records a tracker's ``<Probe>ToTracker`` and ``<Reference>ToTracker`` (the probe calibration
    element's frame names, ``Probe`` and ``Reference`` by default; the tracker device's
    ``ToolReferenceFrame``, ``Tracker`` by default).

    Raises:
        InputError: unreadable XML, or a stepper device set that does not name the probe's,
            the template's or the base frame (naming the element and attribute).
    """
    path = Path(path)
    root = _parse(path)
    algorithm = next(
        (e for tag in ("vtkPlusProbeCalibrationAlgo", "vtkProbeCalibrationAlgo") for e in root.iter(tag)), None
    )
    ical = next(root.iter("iCal"), None)
    stepper = ical is not None or any(d.get("Type") == "BrachyTracker" for d in root.iter("Device"))
    if not stepper:
        devices = [d for d in root.iter("Device") if d.get("ToolReferenceFrame")]
        tracker = _attribute(devices[0] if devices else None, "ToolReferenceFrame", "Tracker")
        probe = _attribute(algorithm, "ProbeCoordinateFrame", "Probe")
        reference = _attribute(algorithm, "ReferenceCoordinateFrame", DEFAULT_REFERENCE_FRAME)
        return PoseStreams(f"{probe}To{tracker}", f"{reference}To{tracker}", "tracker")
    needed = (
        (ical, "iCal", "ProbeCoordinateFrame"),
        (ical, "iCal", "TemplateCoordinateFrame"),
        (algorithm, "vtkPlusProbeCalibrationAlgo", "ReferenceCoordinateFrame"),
    )
    names = []
    for element, tag, attribute in needed:
        value = _attribute(element, attribute, None)
        if value is None or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", value):
            raise InputError(
                f"{root.tag}//{tag}/@{attribute}: a stepper device set must name this frame "
                f"(the stepper's poses are <Frame>To<Base>), got {value!r}",
                file=path,
            )
        names.append(value)
    probe, template, base = names
    return PoseStreams(f"{probe}To{base}", f"{template}To{base}", "stepper")


#: A brachytherapy stepper's encoder fields of a PLUS frame, in order: probe translation (mm),
#: probe rotation (degrees), template translation (mm).
STEPPER_ENCODER_FIELDS = ("ProbePosition", "ProbeRotation", "TemplatePosition")


def stepper_encoder_values(frame_fields: list[dict[str, str]], path: str | os.PathLike[str]) -> FloatArray:
    """``(N, 3)`` a stepper recording's encoder values per frame: probe position (m), probe rotation
    (rad), template position (m), from PLUS's ``ProbePosition`` (mm), ``ProbeRotation`` (degrees)
    and ``TemplatePosition`` (mm) frame fields (:data:`STEPPER_ENCODER_FIELDS`).

    Raises:
        InputError: naming the file, the frame and the field, when a frame lacks one of the
            fields or it is not a finite number.
    """
    values = np.empty((len(frame_fields), 3))
    scale = (1e-3, np.pi / 180.0, 1e-3)
    for k, fields in enumerate(frame_fields):
        for j, name in enumerate(STEPPER_ENCODER_FIELDS):
            fail = _at(Path(path), row=k, row_label="frame", column=name)
            text = fields.get(name)
            if text is None:
                raise fail("missing: a stepper recording has ProbePosition, ProbeRotation and TemplatePosition")
            value = number_from_text(text.strip())
            if value is None or not np.isfinite(value):
                raise fail(f"not a finite number: {text!r}")
            values[k, j] = value * scale[j]
    check_encoder_units(values, frame_fields, path)
    return values


#: PLUS's stepper poses each encoder drives (``vtkPlusBrachyTracker``'s frames), by encoder index:
#: the probe's translation along its z and turn about it, the template's translation along z.
STEPPER_POSE_FIELDS = ("ProbeToStepperHomeTransform", "ProbeToStepperHomeTransform", "TemplateToStepperHomeTransform")
#: Accepted ratio of a pose's travel to its translation encoder's (PLUS's poses move by ``(Tx, Ty, 1) · d``:
#: exactly 1 along z), and of a pose's turn to the rotation encoder's (PLUS's encoder scale, 0.5-2).
ENCODER_RATIO_RANGE = ((0.8, 1.25), (0.5, 2.0), (0.8, 1.25))
#: Units an encoder may have been written in instead of the field's, and their size in the field's unit.
OTHER_ENCODER_UNITS = (
    {"cm": 10.0, "m": 1e3, "inches": 25.4, "µm": 1e-3},
    {"radians": 180.0 / np.pi, "turns": 360.0},
    {"cm": 10.0, "m": 1e3, "inches": 25.4, "µm": 1e-3},
)
#: Smallest travel (m, rad) of an encoder or its pose for their ratio to be measured.
MIN_ENCODER_TRAVEL = (1e-4, 1e-3, 1e-4)


def _pose_travel(frame_fields: list[dict[str, str]], name: str, j: int) -> tuple[np.ndarray, FloatArray] | None:
    """Frames carrying pose ``name`` (status OK), and what encoder ``j`` moves in each: its z
    translation (m, from PLUS's mm) or its turn about z (rad, unwrapped); None if no frame has it."""
    keep, travel = [], []
    for k, fields in enumerate(frame_fields):
        values = numbers_from_text(fields.get(name, ""))
        if values is None or len(values) != 16 or fields.get(f"{name}Status", "OK").strip() != "OK":
            continue
        T = np.array(values).reshape(4, 4)
        if not np.all(np.isfinite(T)):
            continue
        keep.append(k)
        travel.append(float(np.arctan2(T[1, 0], T[0, 0])) if j == 1 else T[2, 3] * 1e-3)
    if len(keep) < 2:
        return None
    moved = np.unwrap(np.array(travel)) if j == 1 else np.array(travel)
    return np.array(keep), moved


def check_encoder_units(values: FloatArray, frame_fields: list[dict[str, str]], path: str | os.PathLike[str]) -> None:
    """Refuse encoder values (``(N, 3)``, m, rad, m: :func:`stepper_encoder_values`) in another unit
    than their field's, found from the data: where the frames also carry PLUS's stepper poses
    (:data:`STEPPER_POSE_FIELDS`, millimetres), each encoder's travel must be the pose's
    (:data:`ENCODER_RATIO_RANGE`: an encoder written in cm moves a tenth of its pose).

    Raises:
        InputError: naming the file and the encoder field, the two travels and the likely unit.
    """
    for j, (name, pose) in enumerate(zip(STEPPER_ENCODER_FIELDS, STEPPER_POSE_FIELDS, strict=True)):
        found = _pose_travel(frame_fields, pose, j)
        if found is None:
            continue
        keep, moved = found
        readings = values[keep, j]
        spread, pose_spread = float(np.ptp(readings)), float(np.ptp(moved))
        if max(spread, pose_spread) < MIN_ENCODER_TRAVEL[j]:
            continue
        ratio = float(np.polyfit(readings, moved, 1)[0]) if spread > 0 else np.inf
        low, high = ENCODER_RATIO_RANGE[j]
        if low <= abs(ratio) <= high:
            continue
        unit, show = ("degrees", np.degrees) if j == 1 else ("mm", lambda x: x * 1e3)
        likely = [
            other
            for other, size in OTHER_ENCODER_UNITS[j].items()
            if ratio != np.inf and abs(np.log(abs(ratio) / size)) < 0.1
        ]
        guess = f"{name} looks like {likely[0]} ({unit} expected)" if likely else f"{name} is not in {unit}"
        raise InputError(
            f"{name} moves {show(spread):.4g} {unit} where the frames' {pose} moves {show(pose_spread):.4g} "
            f"{unit} (ratio {abs(ratio):.3g}, 1 expected): {guess}",
            file=path,
            column=name,
        )
