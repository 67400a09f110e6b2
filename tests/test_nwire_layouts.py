"""Every PLUS device-set layout holding an N-wire phantom and its registration is read; the rest are
refused in one line naming the missing element XPath-like (never a "column" of an XML file).

Synthetic device sets are written here from strings that follow PLUS's layouts (1.x fCal
``DataCollection`` with transform names, OpenIGTLink ``TransformNames``, a registration stored as
Reference→Phantom, frame names set by ``vtkPlusProbeCalibrationAlgo``); real ones are outside data
(``conftest.reference``).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import reference

from brachycal import InputError
from brachycal.data.formats.plus_files import PlusOptimization, read_coordinate_definitions, read_plus_config
from brachycal.se3 import inverse

# fCal 1.2-like phantom: three N patterns (mm, phantom frame).
PHANTOM = """
  <PhantomDefinition>
    <Description Name="fCAL" Type="Triple-N" Version="1.2" WiringVersion="1.0" Institution="PerkLab"/>
    <Geometry>
      <Pattern Type="NWire">
        <Wire Name="1:E3_e3" EndPointFront="20.0 0.0 5.0" EndPointBack="20.0 40.0 5.0" />
        <Wire Name="2:F3_j3" EndPointFront="25.0 0.0 5.0" EndPointBack="45.0 40.0 5.0" />
        <Wire Name="3:K3_k3" EndPointFront="50.0 0.0 5.0" EndPointBack="50.0 40.0 5.0" />
      </Pattern>
      <Pattern Type="NWire">
        <Wire Name="4:E4_e4" EndPointFront="20.0 0.0 0.0" EndPointBack="20.0 40.0 0.0" />
        <Wire Name="5:J4_f4" EndPointFront="45.0 0.0 0.0" EndPointBack="25.0 40.0 0.0" />
        <Wire Name="6:K4_k4" EndPointFront="50.0 0.0 0.0" EndPointBack="50.0 40.0 0.0" />
      </Pattern>
      <Pattern Type="NWire">
        <Wire Name="7:E5_e5" EndPointFront="20.0 0.0 -5.0" EndPointBack="20.0 40.0 -5.0" />
        <Wire Name="8:F5_j5" EndPointFront="25.0 0.0 -5.0" EndPointBack="45.0 40.0 -5.0" />
        <Wire Name="9:K5_k5" EndPointFront="50.0 0.0 -5.0" EndPointBack="50.0 40.0 -5.0" />
      </Pattern>
      <Landmarks>
        <Landmark Name="#1" Position="104.3 5.0 20.0" />
      </Landmarks>
    </Geometry>
  </PhantomDefinition>"""
# Phantom->Reference as PLUS writes it (mm, row-major), and its matrix.
REGISTRATION = "0 -1 0 9.59   1 0 0 36.0   0 0 1 -40.8   0 0 0 1"
T_REFERENCE_PHANTOM_M = np.array(
    [[0.0, -1, 0, 9.59e-3], [1, 0, 0, 36.0e-3], [0, 0, 1, -40.8e-3], [0, 0, 0, 1]], dtype=float
)
SCALED_REGISTRATION = REGISTRATION.replace("0 -1 0", "0 -2 0")
# PLUS 1.x fCal: the data collection names the transforms it records.
DATA_COLLECTION_1X = """
  <DataCollection StartupDelaySec="1.0">
    <DeviceSet Name="fCal 1.x: simulation" Description="saved data" />
    <Tracker Type="SavedDataset" SequenceMetafile="fCal_Test_Calibration_3NWires.igs.mha">
      <Tool Name="Probe" PortName="0" />
      <Tool Name="Reference" PortName="1" />
    </Tracker>
    <ImageAcquisition Type="SavedDataset" />
    <TransformNames>
      <Transform Name="ProbeToTracker" />
      <Transform Name="ReferenceToTracker" />
    </TransformNames>
    <Transform Name="ProbeToReference" />
  </DataCollection>"""
SERVER = """
  <PlusOpenIGTLinkServer ListeningPort="18944" OutputChannelId="TrackedVideoStream">
    <DefaultClientInfo>
      <TransformNames>
        <Transform Name="ProbeToTracker" />
        <Transform Name="ReferenceToTracker" />
      </TransformNames>
    </DefaultClientInfo>
  </PlusOpenIGTLinkServer>"""
SEGMENTATION = '\n  <Segmentation ApproximateSpacingMmPerPixel="0.078" MorphologicalOpeningCircleRadiusMm="0.27" />'


def device_set(
    *,
    registration: str | None = f'<Transform From="Phantom" To="Reference" Matrix="{REGISTRATION}" />',
    phantom: str | None = PHANTOM,
    extra: str = DATA_COLLECTION_1X,
    algo: str = "",
) -> str:
    definitions = [
        '<Transform From="Image" To="TransducerOriginPixel" Matrix="1 0 0 -410 0 1 0 5 0 0 1 0 0 0 0 1" />',
        '<Transform From="StylusTip" To="Stylus" Matrix="1 0 0 210 0 1 0 0 0 0 1 0 0 0 0 1" />',
    ]
    if registration is not None:
        definitions.insert(1, registration)
    body = "\n    ".join(definitions)
    return (
        f'<PlusConfiguration version="2.1">{extra}\n  <CoordinateDefinitions>\n    {body}\n  </CoordinateDefinitions>'
        f"{phantom or ''}{SEGMENTATION}{algo}\n</PlusConfiguration>\n"
    )


def write(tmp_path, text: str, name: str = "PlusDeviceSet.xml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def assert_reads_the_phantom_and_registration(config):
    assert [[w.name for w in pattern] for pattern in config.patterns] == [
        ["1:E3_e3", "2:F3_j3", "3:K3_k3"],
        ["4:E4_e4", "5:J4_f4", "6:K4_k4"],
        ["7:E5_e5", "8:F5_j5", "9:K5_k5"],
    ]
    # PLUS writes mm; read in metres (exact decimal scaling: 1e-15 m guards the last bit).
    assert np.abs(config.patterns[0][1].back_m - [0.045, 0.040, 0.005]).max() < 1e-15
    assert np.abs(config.transforms["Phantom", "Reference"] - T_REFERENCE_PHANTOM_M).max() < 1e-15
    assert config.approximate_spacing_m == pytest.approx(0.078e-3, rel=1e-12)


def test_a_1x_device_set_with_transform_names_is_read(tmp_path):
    """Not the refusal ``column 'Transform ->': expected 16 finite numbers, got None``.

    PLUS 1.x device sets name the transforms their data collection records (``<Transform
    Name="ProbeToTracker"/>``): names, not coordinate definitions. The reader takes only
    the ``Transform`` elements under ``CoordinateDefinitions``.
    """
    path = write(tmp_path, device_set())
    assert_reads_the_phantom_and_registration(read_plus_config(path))
    assert set(read_coordinate_definitions(path)) == {
        ("Image", "TransducerOriginPixel"),
        ("Phantom", "Reference"),
        ("StylusTip", "Stylus"),
    }


def test_an_openigtlink_server_s_transform_names_are_not_definitions(tmp_path):
    path = write(tmp_path, device_set(extra=SERVER))
    assert_reads_the_phantom_and_registration(read_plus_config(path))


def test_a_registration_stored_as_reference_to_phantom_is_inverted(tmp_path):
    inverse_mm = inverse(T_REFERENCE_PHANTOM_M)
    inverse_mm[:3, 3] *= 1e3
    text = " ".join(repr(float(v)) for v in inverse_mm.ravel())
    path = write(tmp_path, device_set(registration=f'<Transform From="Reference" To="Phantom" Matrix="{text}" />'))
    config = read_plus_config(path)
    # An exact inverse of an exact rotation: rounding of the mm → m translation only.
    assert np.abs(config.transforms["Phantom", "Reference"] - T_REFERENCE_PHANTOM_M).max() < 1e-15


def test_frame_names_come_from_the_probe_calibration_element(tmp_path):
    algo = (
        '\n  <vtkPlusProbeCalibrationAlgo ImageCoordinateFrame="Image" ProbeCoordinateFrame="Probe" '
        'PhantomCoordinateFrame="Phantom" ReferenceCoordinateFrame="Marker" OptimizationMethod="2D" '
        'IsotropicPixelSpacing="TRUE" />'
    )
    registration = f'<Transform From="Phantom" To="Marker" Matrix="{REGISTRATION}" />'
    config = read_plus_config(write(tmp_path, device_set(registration=registration, algo=algo)))
    assert np.abs(config.transforms["Phantom", "Reference"] - T_REFERENCE_PHANTOM_M).max() < 1e-15
    assert config.optimization == PlusOptimization("2D", True)
    # The same file with the default frame names lacks its registration, and says which element.
    missing = "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='Reference']"
    with pytest.raises(InputError, match=re.escape(missing)):
        read_plus_config(write(tmp_path, device_set(registration=registration), "default_names.xml"))


REFUSALS = {
    "no-registration": (
        dict(registration=None),
        "no phantom registration: missing "
        "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='Reference'] (Phantom->Reference)",
    ),
    "no-phantom": (dict(phantom=None), "no N-wire patterns: missing PlusConfiguration/PhantomDefinition"),
    "no-nwire-pattern": (
        dict(phantom=PHANTOM.replace('Type="NWire"', 'Type="CIRS"')),
        "no N-wire patterns: missing PlusConfiguration/PhantomDefinition/Geometry/Pattern[@Type='NWire']",
    ),
    "two-wires": (
        dict(
            phantom=PHANTOM.replace(
                '<Wire Name="9:K5_k5" EndPointFront="50.0 0.0 -5.0" EndPointBack="50.0 40.0 -5.0" />', ""
            )
        ),
        "PlusConfiguration/PhantomDefinition/Geometry/Pattern[3]: an N-wire pattern has 2 wires, expected 3",
    ),
    "wire-end-not-numbers": (
        dict(phantom=PHANTOM.replace('EndPointBack="45.0 40.0 5.0"', 'EndPointBack="45.0 forty 5.0"')),
        "PlusConfiguration/PhantomDefinition/Geometry/Pattern[1]/Wire[@Name='2:F3_j3']/@EndPointBack: "
        "expected 3 finite numbers, got '45.0 forty 5.0'",
    ),
    "registration-not-16-numbers": (
        dict(registration='<Transform From="Phantom" To="Reference" />'),
        "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='Reference']/@Matrix: "
        "expected 16 finite numbers, got None",
    ),
    "registration-scaled": (
        dict(registration=f'<Transform From="Phantom" To="Reference" Matrix="{SCALED_REGISTRATION}" />'),
        "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='Reference'] (Phantom->Reference): "
        "matrix is not a rigid transform",
    ),
    "definition-without-to": (
        dict(registration=f'<Transform From="Phantom" Matrix="{REGISTRATION}" />'),
        "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='']: "
        "a coordinate definition needs both From and To attributes",
    ),
}


@pytest.mark.parametrize("case", list(REFUSALS))
def test_other_layouts_are_refused_naming_the_element(tmp_path, case):
    edit, expected = REFUSALS[case]
    path = write(tmp_path, device_set(**edit))
    with pytest.raises(InputError) as error:
        read_plus_config(path)
    message = str(error.value)
    assert message.startswith(f"{path}: {expected}"), message
    assert "\n" not in message and "column" not in message


# --- real device sets ------------------------------------------------------------------------------
def test_plus_fcal_2_0_device_set_reads_phantom_and_registration():
    config = read_plus_config(reference("plus_fcal_nwire", "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"))
    assert len(config.patterns) == 3 and ("Phantom", "Reference") in config.transforms
    assert config.optimization is None  # fCal 2.0's simulation device set asks for no refinement


@pytest.mark.parametrize(
    ("name", "setting"), [("OPEA", PlusOptimization("3D", False)), ("OPEI", PlusOptimization("3D", True))]
)
def test_plus_variant_device_sets_state_their_optimisation_setting(name, setting):
    config = read_plus_config(reference("plus_nwire_variants", f"PlusDeviceSet_{name}_OptimizationMethod.xml"))
    assert config.optimization == setting
