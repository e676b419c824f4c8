"""Device files (services/devices/devicefile.py), PDO layouts (services/devices/pdo.py) and the EDS files
of the project's drives (devices/*.eds), without a bus."""

from __future__ import annotations

from pathlib import Path

import canopen
import pytest

from services.devices import cia402 as cf
from services.devices.devicefile import PROJECT_DEVICES, DeviceFileError, load_bus, object_ref, parse_bus
from services.devices.pdo import PdoLayout, PdoLayoutError, decode_mapping_entry, encode_mapping_entry

EDS = PROJECT_DEVICES / "puma_joint_drive.eds"


def test_the_project_device_files_name_the_drives_in_axis_order_with_their_eds_and_units():
    puma = load_bus(PROJECT_DEVICES / "puma.toml")
    assert puma.node_ids == cf.DRIVE_IDS
    assert {d.mode for d in puma.drives} == {"csp"} and puma.sync == "consumer"
    assert puma.io_node("crossfire").node_id == cf.CROSSFIRE_ID
    assert puma.drives[0].rpdo == (((0x6040, 0), (0x607A, 0)),)
    assert all(Path(d.eds).is_file() for d in puma.drives)
    wheels = load_bus(PROJECT_DEVICES / "wheels.toml")
    assert wheels.node_ids == cf.WHEEL_IDS and wheels.drives[0].name == "left"
    assert wheels.drives[1].mode == "pv" and wheels.drives[1].rpdo_timeout_ms == 200
    assert wheels.drives[0].tpdo == (((0x6041, 0), (0x6064, 0)), ((0x606C, 0), (0x6077, 0)))


@pytest.mark.parametrize("eds", ["puma_joint_drive.eds", "wheel_drive.eds", "crossfire_io.eds"])
def test_each_eds_file_describes_the_objects_its_device_implements(eds: str):
    od = canopen.import_od(str(PROJECT_DEVICES / eds), 5)
    for index in (0x1000, 0x1001, 0x1017, 0x1018, 0x1800, 0x1A00):
        assert index in od, f"{eds} lacks {index:#06x}"
    assert od[0x1800][1].default == 0x185  # $NODEID resolved
    if eds != "crossfire_io.eds":
        for index in (0x1016, 0x1400, 0x1600, 0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x606C, 0x6502):
            assert index in od, f"{eds} lacks {index:#06x}"
        assert (0x607A in od) == (eds == "puma_joint_drive.eds") and (0x60FF in od) == (eds == "wheel_drive.eds")
        assert od[0x1016][1].default == 0x7F << 16 | 350  # watches the master (node 0x7F) for 350 ms


def test_a_layout_packs_and_reads_a_pdo_in_mapping_order():
    od = canopen.import_od(str(EDS), 3)
    types = {(v.index, v.subindex): v.data_type for obj in od.values()
             for v in ([obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else obj.values())}
    layout = PdoLayout.compile([(0x607A, 0, 32), (0x6040, 0, 16)], types)
    assert layout.size == 6 and layout.indices == (0x607A, 0x6040) and 0x6040 in layout
    data = layout.pack_objects({0x6040: 0x0F, 0x607A: -123456})
    assert data == (-123456).to_bytes(4, "little", signed=True) + bytes([0x0F, 0x00])
    assert layout.unpack_objects(data) == {0x607A: -123456, 0x6040: 0x0F}
    with pytest.raises(PdoLayoutError):
        layout.unpack(data[:5])
    with pytest.raises(PdoLayoutError):
        layout.pack([2**31, 0])
    with pytest.raises(PdoLayoutError, match="at most 8 bytes"):
        PdoLayout.compile([(0x607A, 0, 32), (0x6064, 0, 32), (0x6040, 0, 16)], types)
    with pytest.raises(PdoLayoutError, match="only whole objects"):
        PdoLayout.compile([(0x6040, 0, 8)], types)
    with pytest.raises(PdoLayoutError, match="not in the object dictionary"):
        PdoLayout.compile([(0x2000, 0, 8)], types)
    assert decode_mapping_entry(encode_mapping_entry(0x6064, 0, 32)) == (0x6064, 0, 32)
    assert encode_mapping_entry(0x6041, 0, 16) == 0x60410010


def test_objects_are_named_by_their_cia_402_names_or_hexadecimal_indices():
    assert object_ref("statusword") == (0x6041, 0)
    assert object_ref("0x6000:01") == (0x6000, 1)
    assert object_ref("0x607a") == (0x607A, 0)
    with pytest.raises(ValueError, match="unknown object"):
        object_ref("speed")


def _bus(extra: str = "", drive: str = "node_id = 1") -> str:
    return f'[bus]\nchannel = "can0"\n{extra}\n[defaults]\neds = "{EDS}"\n\n[drives.a]\n{drive}\n'


@pytest.mark.parametrize(("text", "problem"), [
    (_bus(drive="node_id = 200"), r"<string>:\d+: node_id must be an integer in 1..127, got 200"),
    (_bus(drive='node_id = 1\nmode = "torque"'), r"<string>:\d+: mode must be one of pp, pv, csp, csv"),
    (_bus(drive='node_id = 1\nspeed = 3'), r"<string>:\d+: unknown key\(s\) speed in \[drives.a\]"),
    (_bus(drive='node_id = 1\neds = "nowhere.eds"'), r"<string>:\d+: EDS file 'nowhere.eds' not found"),
    (_bus(drive='node_id = 1\nrpdo = [["controlword", "speed"]]'), r"<string>:\d+: rpdo: unknown object 'speed'"),
    (_bus(drive='node_id = 1\nposition_unit = -1'), r"<string>:\d+: position_unit must be a positive number"),
    (_bus('sync = "master"'), r"<string>:\d+: sync must be \"consumer\" or \"producer\""),
    (_bus('master_node_id = 1'), r"master_node_id 1 is also a's node id"),
    (_bus() + '[drives.b]\nnode_id = 1\n', r"<string>:\d+: node id 1 of b is also a's"),
    ('[bus]\nchannel = "can0"\n', r"no \[drives.NAME\] table"),
    ('[bus\n', r"<string>:1:"),
])
def test_a_wrong_device_file_is_refused_with_its_line(text: str, problem: str):
    with pytest.raises(DeviceFileError, match=problem):
        parse_bus(text)


def test_eds_paths_are_relative_to_the_device_file(tmp_path: Path):
    (tmp_path / "drive.eds").write_bytes(EDS.read_bytes())
    (tmp_path / "bus.toml").write_text('[defaults]\neds = "drive.eds"\n[drives.x]\nnode_id = 4\n')
    bus = load_bus(tmp_path / "bus.toml")
    assert bus.drives[0].eds == str(tmp_path / "drive.eds")
    with pytest.raises(DeviceFileError, match="cannot read device file"):
        load_bus(tmp_path / "missing.toml")
