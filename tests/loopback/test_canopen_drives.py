"""The CANopen master (services/devices/drives.py, on canopen) configures the simulated PUMA drives
(canopen local nodes made from devices/puma_joint_drive.eds, sim/drives.py) over SDO exactly as it
would real ones, from a device file, and moves them; the simulated world serves the bus through its
socketcand gateway on 127.0.0.1, as in the demo."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from puma_rig import ControlLoop, SimRig

from services.catching.drives import PumaDrives
from services.devices import cia402 as cf
from services.devices.devicefile import PROJECT_DEVICES, parse_bus
from services.devices.drives import BusError
from sim.socketcand import CanGateway

# Not the EDS's mapping: the target before the controlword, the position before the statusword, a second
# TPDO with the velocity and the position demand; other heartbeat and deadline times too.
REMAPPED = f"""
[bus]
channel = "can0"
[defaults]
eds = "{PROJECT_DEVICES / 'puma_joint_drive.eds'}"
mode = "csp"
heartbeat_ms = 50
master_heartbeat_timeout_ms = 400
rpdo_timeout_ms = 60
rpdo = [["target_position", "controlword"]]
tpdo = [["position_actual_value", "statusword"], ["velocity_actual_value", "position_demand_value"]]
{''.join(f'''
[drives.joint{n}]
node_id = {n}
''' for n in range(1, 7))}
[io.crossfire]
node_id = 0x10
eds = "{PROJECT_DEVICES / 'crossfire_io.eds'}"
"""


@pytest.fixture
def served(tmp_path: Path):
    rig = SimRig(tmp_path, master_wait_s=0.05)
    gw = CanGateway(rig.drives.bus)
    port = gw.start()
    rig.start()
    yield rig, port
    gw.stop()
    rig.close()


@pytest.mark.timeout(60)
def test_a_simulated_drive_is_configured_over_sdo_from_a_device_file_with_another_mapping_and_moves(served):
    rig, port = served
    bus = parse_bus(REMAPPED)
    with PumaDrives("127.0.0.1", port, bus=bus) as drives:
        drives.start()
        # read back over SDO: what each drive holds now is what the device file said, not its EDS's
        for node in range(1, 7):
            assert drives.sdo_read(node, 0x1600, 0) == 2
            assert [drives.sdo_read(node, 0x1600, s) for s in (1, 2)] == [0x607A0020, 0x60400010]
            assert [drives.sdo_read(node, 0x1A00, s) for s in (0, 1, 2)] == [2, 0x60640020, 0x60410010]
            assert [drives.sdo_read(node, 0x1A01, s) for s in (0, 1, 2)] == [2, 0x606C0020, 0x60620020]
            assert drives.sdo_read(node, 0x1801, 1) == 0x280 + node  # TPDO2 valid, on its predefined COB-ID
            assert drives.sdo_read(node, 0x1017) == 50
            assert drives.sdo_read(node, 0x1016, 1) == 0x7F << 16 | 400
            assert drives.sdo_read(node, 0x1400, 5) == 60
            assert drives.sdo_read(node, 0x6061) == 8  # cyclic synchronous position
        # and the simulated drive works with what it was told
        assert rig.drives.rpdo_layout(3).indices == (0x607A, 0x6040)
        assert rig.drives.tpdo_layout(3, 2).indices == (0x606C, 0x6062)
        assert rig.drives.device(3).timeout_cycles == 30  # 60 ms over the 2 ms cycle
        assert rig.drives.device(3).consumers == {0x7F: 0.4}
        with ControlLoop(drives) as loop:
            drives.enable()
            q0 = loop.q.copy()
            goal = q0 + 0.05
            for k in range(1, 101):  # a move: 0.05 rad on every joint over 0.2 s
                loop.q = q0 + 0.05 * k / 100
                loop.wait(1)
            loop.wait(150)
            assert np.allclose(drives.positions(), goal, atol=3e-3)  # the master reads the remapped TPDO1
            assert np.allclose(rig.drives.positions(), goal, atol=3e-3)
        drives.check()
        assert rig.drives.faults == []


@pytest.mark.timeout(60)
def test_the_drives_heartbeats_come_at_the_period_written_over_sdo(tmp_path: Path):
    rig = SimRig(tmp_path)
    try:
        port = rig.drives.bus.connect()
        rig.step(300)
        beats = [f.t for f in port.recv_all() if f.can_id == 0x701]
        assert np.allclose(np.diff(beats[1:]), 0.1)  # the EDS's 0x1017 = 100 ms
        # what canopen's SDO client sends for 0x1017 = 50 ms: an expedited download of two bytes
        port.send(cf.CanFrame(0x601, bytes([0x2B, 0x17, 0x10, 0x00, 50, 0, 0, 0])))
        rig.step(2)
        answer = [f for f in port.recv_all() if f.can_id == 0x581]
        assert answer and answer[0].data[:4] == bytes([0x60, 0x17, 0x10, 0x00])  # download confirmed
        rig.step(400)
        beats = [f.t for f in port.recv_all() if f.can_id == 0x701]
        assert np.allclose(np.diff(beats), 0.05)
    finally:
        rig.close()


@pytest.mark.timeout(60)
def test_a_mapping_the_drive_cannot_take_is_refused_with_the_abort_code_and_named(served):
    rig, port = served
    bad = REMAPPED.replace('tpdo = [["position_actual_value", "statusword"], ["velocity_actual_value", '
                           '"position_demand_value"]]', 'tpdo = [["statusword", "0x1017"]]')
    with PumaDrives("127.0.0.1", port, bus=parse_bus(bad)) as drives:
        with pytest.raises(BusError, match=r"drive \d \(joint\d\): SDO configuration failed: .*0x06040041"):
            drives.start()


@pytest.mark.timeout(60)
def test_a_mode_the_drive_does_not_support_is_refused_before_anything_moves(served):
    rig, port = served
    with PumaDrives("127.0.0.1", port, bus=parse_bus(REMAPPED.replace('mode = "csp"', 'mode = "pv"'))) as drives:
        with pytest.raises(BusError, match=r"does not support mode pv \(0x6502 = 0x0080\)"):
            drives.start()
    assert rig.drives.faults == []


@pytest.mark.timeout(60)
def test_the_master_can_be_the_sync_producer(tmp_path: Path):
    rig = SimRig(tmp_path, sync_producer=False)
    gw = CanGateway(rig.drives.bus)
    port = gw.start()
    rig.start()
    try:
        bus = parse_bus(REMAPPED.replace('channel = "can0"', 'channel = "can0"\nsync = "producer"\nsync_period_ms = 4'))
        with PumaDrives("127.0.0.1", port, bus=bus) as drives:
            drives.start()
            with ControlLoop(drives) as loop:
                drives.enable()
                t0 = time.monotonic()
                loop.q = loop.q + 0.02
                loop.wait(100)
                wall = time.monotonic() - t0
            assert np.allclose(rig.drives.positions(), loop.q, atol=3e-3)
            assert wall >= 100 * 0.004 * 0.9  # the master's SYNC paces the bus: 4 ms per cycle
            drives.check()
    finally:
        gw.stop()
        rig.close()


@pytest.mark.timeout(60)
def test_a_drive_echoing_a_target_the_master_did_not_send_is_a_takeover(served):
    """Issue 22, section 3: a drive whose TPDO echoes its target (0x607A mapped) and reports one this
    master never sent (here another station writes it over SDO, which the master does not watch) is
    trouble at once, named; while only the master commands it, the echo is no trouble."""
    rig, port = served
    bus = parse_bus(REMAPPED.replace('["velocity_actual_value", "position_demand_value"]', '["target_position"]'))
    with PumaDrives("127.0.0.1", port, bus=bus) as drives:
        drives.start()
        with ControlLoop(drives) as loop:
            drives.enable()
            loop.wait(100)
            assert drives.trouble() is None  # its own targets, echoed
            intruder = rig.drives.bus.connect()
            foreign = round(loop.q[3] / 1e-5) + 12345
            # the master skips a few cycles (the drives extrapolate; 25 are allowed), so that its next
            # target does not overwrite the written one before the drive's TPDO echoes it
            drives.send_targets = lambda q: None  # type: ignore[method-assign]
            loop.wait(1)
            intruder.send(cf.CanFrame(0x604, bytes([0x23, 0x7A, 0x60, 0x00]) + foreign.to_bytes(4, "little", signed=True)))
            loop.wait(4)
            del drives.send_targets
            intruder.close()
            trouble = drives.trouble() or ""
            assert f"drive 4 reports target {foreign} (counts), which this master did not send" in trouble, trouble
            with pytest.raises(BusError, match="another master"):
                drives.check()


@pytest.mark.timeout(30)
@pytest.mark.parametrize("lost", [False, True])
def test_closing_a_lost_socketcand_connection_resets_it_so_frames_held_for_it_are_dropped(lost: bool):
    # a socketcand daemon's side of the connection (the greeting, open, rawmode), on 127.0.0.1: an
    # orderly close ends the stream (b""), which leaves the kernel retransmitting what a link that was
    # down never acknowledged; a lost bus's connection is reset instead, those frames dropped
    import socket
    import threading

    import can

    from services.devices.drives import _abort

    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    seen: list[object] = []

    def daemon() -> None:
        conn, _ = server.accept()
        conn.sendall(b"< hi >")
        for reply in (b"< ok >", b"< ok >"):  # open can0, rawmode
            conn.recv(256)
            conn.sendall(reply)
        try:
            seen.append(conn.recv(256))
        except ConnectionResetError as exc:
            seen.append(exc)
        conn.close()

    thread = threading.Thread(target=daemon)
    thread.start()
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
    if lost:
        _abort(bus)
    bus.shutdown()
    thread.join(10)
    server.close()
    assert isinstance(seen[0], ConnectionResetError) if lost else seen[0] == b"", seen
