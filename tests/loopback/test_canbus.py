"""The PUMA's CAN bus: CiA 402 state machine, socketcand protocol, simulated drives (CANopen slaves
made from their EDS files), the loopback gateway with python-can's socketcand client, and the motion
node's CANopen master."""

from __future__ import annotations

import socket
import threading
import time

import can
import numpy as np
import pytest
from can.interfaces.socketcand.socketcand import convert_ascii_message_to_can_message
from puma_rig import ControlLoop, SimRig

from services.catching.drives import PumaDrives
from services.catching.robot import puma560 as P
from services.devices import cia402 as cf
from services.devices.devicefile import PROJECT_DEVICES, load_bus
from services.devices.drives import BusError
from sim import socketcand
from sim.canbus import SimBus
from sim.drives import POSITION_UNIT
from sim.socketcand import CanGateway
from tests.ports import free_port

PUMA_BUS = load_bus(PROJECT_DEVICES / "puma.toml")


def rpdo(rig, node: int, cw: int, q: float) -> cf.CanFrame:
    """The RPDO1 of drive ``node`` as its mapping has it now: controlword and target position, rad."""
    return cf.CanFrame(0x200 + node, rig.drives.rpdo_layout(node).pack_objects({0x6040: cw, 0x607A: round(q / POSITION_UNIT)}))


def tpdo1(rig, frame: cf.CanFrame) -> tuple[int, float]:
    """(statusword, actual position in rad) of a TPDO1 with the EDS's mapping."""
    values = rig.drives.tpdo_layout(frame.can_id - 0x180).unpack_objects(frame.data)
    return values[0x6041], values[0x6064] * POSITION_UNIT

# --- pure encoding -------------------------------------------------------------------------------


def test_wrong_payload_lengths_are_refused():
    for decode in (cf.decode_heartbeat, cf.decode_emcy):
        with pytest.raises(cf.FrameError):
            decode(b"\x00" * 7)
    with pytest.raises(cf.FrameError):
        cf.CanFrame(0x800, b"")
    with pytest.raises(cf.FrameError):
        cf.CanFrame(0x100, bytes(9))


def test_emcy_frames_have_the_cia_301_layout_and_a_text_for_each_code():
    frame = cf.encode_emcy(3, cf.EmcyCode.RPDO_TIMEOUT, 0x01)
    assert (frame.can_id, frame.data) == (0x083, bytes([0x50, 0x82, 0x01, 0, 0, 0, 0, 0]))
    assert cf.decode_emcy(frame.data) == (0x8250, 0x01)
    assert all(code.text for code in cf.EmcyCode)
    with pytest.raises(cf.FrameError):
        cf.decode_emcy(b"\x00" * 6)
    with pytest.raises(cf.FrameError):
        cf.encode_emcy(0, cf.EmcyCode.NO_ERROR)  # 0x080 is SYNC


def test_a_fault_reaction_ignores_controlwords_until_the_joint_is_at_rest():
    sm = cf.Cia402StateMachine()
    for cw in (cf.Controlword.SHUTDOWN, cf.Controlword.SWITCH_ON, cf.Controlword.ENABLE_OPERATION):
        sm.on_controlword(cw)
    sm.start_fault_reaction("no target", cf.EmcyCode.RPDO_TIMEOUT)
    assert cf.state_from_statusword(sm.statusword) is cf.DriveState.FAULT_REACTION_ACTIVE
    assert sm.statusword & 0x2000 == 0  # not a following error
    sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
    assert sm.on_controlword(cf.Controlword.FAULT_RESET) is cf.DriveState.FAULT_REACTION_ACTIVE
    sm.reaction_done()
    sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
    assert sm.on_controlword(cf.Controlword.FAULT_RESET) is cf.DriveState.SWITCH_ON_DISABLED
    assert sm.fault_code is cf.EmcyCode.NO_ERROR


def test_heartbeat_and_nmt_frames_have_the_cia_301_layout():
    hb = cf.encode_heartbeat(4, cf.NmtState.OPERATIONAL)
    assert (hb.can_id, hb.data) == (0x704, b"\x05")
    assert cf.decode_heartbeat(b"\x85") is cf.NmtState.OPERATIONAL  # toggle bit ignored
    nmt = cf.nmt_frame(cf.NmtCommand.START)
    assert (nmt.can_id, nmt.data) == (0x000, b"\x01\x00")


def test_statuswords_map_to_states_and_back():
    for state in cf.DriveState:
        assert cf.state_from_statusword(cf.statusword(state)) is state
    assert cf.state_from_statusword(0x0627) is cf.DriveState.OPERATION_ENABLED  # extra bits ignored
    assert cf.state_from_statusword(0x0060) is cf.DriveState.SWITCH_ON_DISABLED  # quick-stop bit ignored there
    with pytest.raises(cf.FrameError):
        cf.state_from_statusword(0x0001)


def test_the_state_machine_walks_to_operation_enabled_and_faults():
    sm = cf.Cia402StateMachine()
    assert sm.on_controlword(cf.Controlword.ENABLE_OPERATION) is cf.DriveState.SWITCH_ON_DISABLED
    assert sm.on_controlword(cf.Controlword.SHUTDOWN) is cf.DriveState.READY_TO_SWITCH_ON
    assert sm.on_controlword(cf.Controlword.SWITCH_ON) is cf.DriveState.SWITCHED_ON
    assert sm.on_controlword(cf.Controlword.ENABLE_OPERATION) is cf.DriveState.OPERATION_ENABLED
    assert sm.statusword == 0x0027
    sm.fault("following error")
    assert sm.statusword & 0x2008 == 0x2008
    assert sm.on_controlword(cf.Controlword.ENABLE_OPERATION) is cf.DriveState.FAULT
    assert sm.on_controlword(cf.Controlword.FAULT_RESET) is cf.DriveState.SWITCH_ON_DISABLED
    assert sm.fault_reason == ""


def test_fault_reset_needs_a_rising_edge_of_bit_7():
    sm = cf.Cia402StateMachine()
    sm.on_controlword(cf.Controlword.FAULT_RESET)
    sm.fault("x")
    assert sm.on_controlword(cf.Controlword.FAULT_RESET) is cf.DriveState.FAULT  # bit 7 still high
    sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
    assert sm.on_controlword(cf.Controlword.FAULT_RESET) is cf.DriveState.SWITCH_ON_DISABLED


# --- socketcand protocol (sans-IO) ---------------------------------------------------------------


def test_the_server_greets_opens_the_bus_and_enters_raw_mode():
    proto = socketcand.SocketcandServerProtocol(("can0",))
    assert proto.data_to_send() == b"< hi >"
    assert proto.receive_data(b"< open can0 >") == []
    assert proto.data_to_send() == b"< ok >"
    proto.frame_out(cf.CanFrame(0x80))  # not yet in raw mode: dropped
    assert proto.data_to_send() == b""
    proto.receive_data(b"< rawm")
    proto.receive_data(b"ode >")
    assert proto.data_to_send() == b"< ok >"
    assert proto.mode is socketcand.ServerMode.RAW


def test_send_commands_become_frames_even_when_split_or_batched():
    proto = socketcand.SocketcandServerProtocol()
    proto.receive_data(b"< open can0 >< rawmode >")
    proto.data_to_send()
    frames = proto.receive_data(b"< send 201 6 f 0 1 2 3 4 >< send 0 2 1 0 >< send 8")
    frames += proto.receive_data(b"0 0 >")
    assert frames == [
        cf.CanFrame(0x201, bytes([0x0F, 0, 1, 2, 3, 4])),
        cf.CanFrame(0x000, b"\x01\x00"),
        cf.CanFrame(0x080, b""),
    ]
    assert proto.data_to_send() == b""


def test_a_send_with_a_wrong_length_is_answered_with_an_error():
    proto = socketcand.SocketcandServerProtocol()
    proto.receive_data(b"< open can0 >")
    proto.data_to_send()
    assert proto.receive_data(b"< send 201 3 1 2 >") == []
    assert proto.data_to_send().startswith(b"< error ")


def test_an_unknown_bus_closes_the_connection():
    proto = socketcand.SocketcandServerProtocol(("can0",))
    proto.receive_data(b"< open can7 >< rawmode >")
    assert proto.mode is socketcand.ServerMode.CLOSED


def test_frames_are_formatted_as_python_can_parses_them():
    for frame in (cf.CanFrame(0x181, bytes([0x27, 0, 1, 2, 3, 4]), 12.5), cf.CanFrame(0x80, b"", 3.000001)):
        text = socketcand.format_frame(frame).decode()
        msg = convert_ascii_message_to_can_message(text)
        assert msg.arbitration_id == frame.can_id
        assert bytes(msg.data) == frame.data
        assert msg.timestamp == pytest.approx(frame.t, abs=1e-6)
        assert not msg.is_extended_id


def test_python_can_send_text_parses_back_to_the_same_frame():
    from can.interfaces.socketcand.socketcand import (
        convert_can_message_to_ascii_message,
    )

    msg = can.Message(arbitration_id=0x205, data=[0x0F, 0, 0xAB, 0xCD, 0xEF, 0x01], is_extended_id=False)
    proto = socketcand.SocketcandServerProtocol()
    proto.receive_data(b"< open can0 >< rawmode >")
    frames = proto.receive_data(convert_can_message_to_ascii_message(msg).encode())
    assert frames == [cf.CanFrame(0x205, bytes(msg.data))]
    assert socketcand.format_send(frames[0]) == b"< send 205 6 0F 00 AB CD EF 01 >"


def test_a_frame_another_station_sends_reaches_the_others_stamped_with_the_bus_time():
    bus = SimBus()
    master, intruder = bus.connect(), bus.connect()
    bus.transmit(cf.CanFrame(cf.SYNC_ID, b"", 5.25))  # a sim device: the bus time is now 5.25 s
    assert master.recv(timeout=30.0) == cf.CanFrame(cf.SYNC_ID, b"", 5.25)
    intruder.send(cf.nmt_frame(cf.NmtCommand.STOP, 0))  # stamped on the sender's clock (a gateway's monotonic)
    got = master.recv(timeout=30.0)
    assert got is not None and got.can_id == cf.NMT_ID and got.t == 5.25  # not 12,000 s ahead of the heartbeats


# --- simulated drives ------------------------------------------------------------------------------


@pytest.fixture
def rig(tmp_path):
    r = SimRig(tmp_path)
    yield r
    r.close()


def _enable_in_process(rig, port):
    q = rig.drives.positions()
    port.send(cf.nmt_frame(cf.NmtCommand.START))
    for cw in (cf.Controlword.SHUTDOWN, cf.Controlword.SWITCH_ON, cf.Controlword.ENABLE_OPERATION):
        for node, qi in zip(cf.DRIVE_IDS, q):
            port.send(rpdo(rig, node, cw, qi))
        rig.step(2)


def test_drives_boot_send_heartbeats_and_sync_every_two_milliseconds(rig):
    port = rig.drives.bus.connect()
    rig.step(201)
    frames = port.recv_all()
    syncs = [f for f in frames if f.can_id == cf.SYNC_ID]
    assert len(syncs) == 101
    assert np.allclose(np.diff([f.t for f in syncs]), 0.002)
    boot = [f for f in frames if f.can_id in range(0x701, 0x707) and f.data == b"\x00"]
    assert len(boot) == 6
    beats = [f for f in frames if f.can_id == 0x701]
    assert [f.data for f in beats] == [b"\x00", b"\x7f", b"\x7f"]
    assert not [f for f in frames if 0x181 <= f.can_id <= 0x186]  # pre-operational: no PDOs


def test_enabled_drives_follow_targets_and_report_them_after_each_sync(rig):
    port = rig.drives.bus.connect()
    _enable_in_process(rig, port)
    assert rig.drives.states() == [cf.DriveState.OPERATION_ENABLED] * 6
    q = np.asarray(rig.drives.positions())
    goal = q + np.array([0.05, -0.05, 0.05, 0.1, -0.1, 0.1])
    # ramp at a speed within the limits, one target per 2 ms cycle
    for k in range(1, 251):  # a CSP master sends a target every cycle, also at rest
        for node in cf.DRIVE_IDS:
            target = q[node - 1] + (goal[node - 1] - q[node - 1]) * min(k, 100) / 100
            port.send(rpdo(rig, node, cf.Controlword.ENABLE_OPERATION, target))
        rig.step(2)
    assert np.allclose(rig.drives.positions(), goal, atol=2e-3)
    port.recv_all()
    for node in cf.DRIVE_IDS:
        port.send(rpdo(rig, node, cf.Controlword.ENABLE_OPERATION, goal[node - 1]))
    rig.step(2)
    tpdos = {f.can_id: tpdo1(rig, f) for f in port.recv_all() if 0x181 <= f.can_id <= 0x186}
    assert sorted(tpdos) == list(range(0x181, 0x187))
    for node in cf.DRIVE_IDS:
        sw, qa = tpdos[0x180 + node]
        assert cf.state_from_statusword(sw) is cf.DriveState.OPERATION_ENABLED
        assert qa == pytest.approx(goal[node - 1], abs=2e-3)


def test_a_target_jump_faults_the_drive_on_following_error_and_it_holds(rig):
    port = rig.drives.bus.connect()
    _enable_in_process(rig, port)
    q = rig.drives.positions()
    port.send(rpdo(rig, 2, cf.Controlword.ENABLE_OPERATION, q[1] + 1.0))
    rig.step(400)
    states = rig.drives.states()
    assert states[1] is cf.DriveState.FAULT
    assert "following error" in rig.drives.fault_reasons()[1]
    emcy = [cf.decode_emcy(f.data) for f in port.recv_all() if f.can_id == cf.EMCY_BASE + 2]
    assert emcy and emcy[0][0] == cf.EmcyCode.FOLLOWING_ERROR
    held = rig.drives.positions()[1]
    rig.step(200)
    assert rig.drives.positions()[1] == pytest.approx(held, abs=5e-3)
    port.send(rpdo(rig, 2, cf.Controlword.FAULT_RESET, held))
    rig.step(4)
    assert rig.drives.states()[1] is cf.DriveState.SWITCH_ON_DISABLED


def _move_and_go_silent(rig, port, speed: float, cycles: int = 100) -> tuple[np.ndarray, float]:
    """Drive joint 4 at ``speed`` rad/s (targets every cycle), then stop sending; returns the
    positions and the bus time of the last target."""
    _enable_in_process(rig, port)
    q0 = np.asarray(rig.drives.positions())
    q = q0.copy()
    for k in range(1, cycles + 1):
        q[3] += speed * min(k / 50, 1.0) * cf.CYCLE_S  # up to speed over 0.1 s, within the limits
        for node in cf.DRIVE_IDS:
            port.send(rpdo(rig, node, cf.Controlword.ENABLE_OPERATION, q[node - 1]))
        rig.step(2)
    return q, rig.t


def test_a_drive_missing_a_few_targets_keeps_its_last_velocity_and_does_not_fault(rig):
    port = rig.drives.bus.connect()
    _move_and_go_silent(rig, port, speed=2.0)
    before = rig.drives.positions()[3]
    rig.step(20)  # ten cycles without a target (fewer than TARGET_TIMEOUT_CYCLES)
    moved = rig.drives.positions()[3] - before
    assert moved == pytest.approx(2.0 * 0.020, abs=0.01)  # it went on at about 2 rad/s
    assert rig.drives.states() == [cf.DriveState.OPERATION_ENABLED] * 6
    assert rig.drives.faults == []


def test_a_master_gone_silent_makes_every_enabled_drive_stop_on_its_ramp_fault_and_say_why(rig):
    port = rig.drives.bus.connect()
    _q, t_last = _move_and_go_silent(rig, port, speed=4.0)
    port.recv_all()
    rig.step(1000)
    assert rig.drives.states() == [cf.DriveState.FAULT] * 6
    faults = rig.drives.faults
    assert {f.code for f in faults} == {cf.EmcyCode.RPDO_TIMEOUT} and len(faults) == 6
    wrist = next(f for f in faults if f.node == 4)
    timeout_s = (cf.TARGET_TIMEOUT_CYCLES + 1) * cf.CYCLE_S
    assert wrist.t - t_last == pytest.approx(timeout_s, abs=2 * cf.CYCLE_S)
    # the quick stop: from about 4 rad/s at QDD_MAX = 20 rad/s^2 in about 0.2 s
    assert wrist.speed == pytest.approx(4.0, abs=0.4)
    assert wrist.t_stopped - wrist.t == pytest.approx(wrist.speed / P.QDD_MAX[3], abs=0.01)
    emcy = {f.can_id - cf.EMCY_BASE: cf.decode_emcy(f.data)[0] for f in port.recv_all()
            if cf.EMCY_BASE < f.can_id <= cf.EMCY_BASE + 6}
    assert emcy == {n: cf.EmcyCode.RPDO_TIMEOUT for n in cf.DRIVE_IDS}
    at_rest = rig.drives.positions()
    rig.step(200)
    assert np.allclose(rig.drives.positions(), at_rest, atol=2e-3)  # it holds in FAULT


def test_the_master_heartbeat_is_watched_once_it_has_been_seen(rig):
    port = rig.drives.bus.connect()
    _enable_in_process(rig, port)
    q = rig.drives.positions()

    def cycle(heartbeat: bool) -> None:
        for node in cf.DRIVE_IDS:
            port.send(rpdo(rig, node, cf.Controlword.ENABLE_OPERATION, q[node - 1]))
        if heartbeat:
            port.send(cf.encode_heartbeat(cf.MASTER_ID, cf.NmtState.OPERATIONAL))
        rig.step(2)

    for _ in range(300):  # no heartbeat yet: not watched
        cycle(False)
    assert rig.drives.faults == []
    for k in range(100):  # heartbeats every 100 ms
        cycle(k % 50 == 0)
    for _ in range(200):  # targets go on, heartbeats stop: 0.4 s > the consumer time
        cycle(False)
    assert {f.code for f in rig.drives.faults} == {cf.EmcyCode.HEARTBEAT_LOST}
    assert all(s is cf.DriveState.FAULT for s in rig.drives.states())


def test_the_sim_waits_for_a_master_in_step_and_stops_waiting_for_a_silent_one(tmp_path):
    import threading

    rig = SimRig(tmp_path, master_wait_s=0.5)
    try:
        port = rig.drives.bus.connect()
        _enable_in_process(rig, port)
        q = rig.drives.positions()
        silent = threading.Event()

        def master() -> None:  # answers each SYNC after 20 ms of wall time, until silenced
            while not silent.is_set():
                f = port.recv(timeout=0.1)
                if f is None or f.can_id != cf.SYNC_ID:
                    continue
                time.sleep(0.02)
                if not silent.is_set():
                    for node in cf.DRIVE_IDS:
                        port.send(rpdo(rig, node, cf.Controlword.ENABLE_OPERATION, q[node - 1]))

        th = threading.Thread(target=master, daemon=True)
        th.start()
        rig.step(20)  # ten SYNCs: each waits for the late master's targets
        assert rig.drives.master_misses == 0 and rig.drives.master_waits >= 9
        assert rig.drives.faults == []
        silent.set()
        th.join(timeout=5)
        port.recv_all()
        waits = rig.drives.master_waits
        t0 = time.monotonic()
        rig.step(100)  # the master is silent now: one wait runs out, then the bus keeps real time
        assert rig.drives.master_misses == 1 and rig.drives.master_waits == waits + 1
        # 0.5 s for the wait that ran out, then about 2 ms per SYNC: never faster than real time,
        # so the RPDO timeout (26 cycles) is at least 50 ms of wall time after the last answer too
        assert time.monotonic() - t0 >= 0.5 + 0.045
        assert {f.code for f in rig.drives.faults} == {cf.EmcyCode.RPDO_TIMEOUT}
    finally:
        rig.close()


@pytest.mark.timeout(60)
def test_puma_drives_recover_faulted_drives_by_fault_reset_and_enable(served):
    rig, _, port = served
    with PumaDrives("127.0.0.1", port, heartbeat_timeout=0.8, bus=PUMA_BUS) as drives:
        drives.enable()
        deadline = time.monotonic() + 10  # no targets: the drives' watchdog faults them
        while time.monotonic() < deadline and not drives.faults():
            time.sleep(0.01)
        assert drives.faults(), rig.drives.states()
        with pytest.raises(BusError, match=r"FAULT \(no target from the master \(RPDO timeout\)\)"):
            drives.check()
        drives.enable()
        assert drives.states() == [cf.DriveState.OPERATION_ENABLED] * 6
        assert drives.faults() == {}


def test_disabled_drives_hold_the_arm_against_gravity(rig):
    q0 = np.asarray(rig.drives.positions())
    rig.step(500)
    assert np.allclose(rig.drives.positions(), q0, atol=5e-3)


def test_the_crossfire_module_reports_changes_once_started(rig):
    port = rig.drives.bus.connect()
    rig.crossfire_state = True
    rig.step(10)
    assert not [f for f in port.recv_all() if f.can_id == 0x190]  # pre-operational: silent
    port.send(cf.nmt_frame(cf.NmtCommand.START, cf.CROSSFIRE_ID))
    rig.step(5)
    reports = [bool(f.data[0] & 1) for f in port.recv_all() if f.can_id == 0x190]
    assert reports == [True]
    rig.crossfire_state = False
    rig.step(5)
    rig.crossfire_state = True
    rig.step(5)
    reports = [bool(f.data[0] & 1) for f in port.recv_all() if f.can_id == 0x190]
    assert reports == [False, True]


# --- across processes: gateway, python-can, PumaDrives ---------------------------------------------


@pytest.fixture
def served(rig):
    gw = CanGateway(rig.drives.bus)
    port = gw.start()
    rig.start()
    yield rig, gw, port
    gw.stop()


@pytest.mark.timeout(30)
def test_python_can_socketcand_client_sees_sync_and_commands_the_drives(served):
    _rig, _, port = served
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
    try:
        deadline = time.monotonic() + 3
        got_sync = False
        while time.monotonic() < deadline and not got_sync:
            msg = bus.recv(timeout=0.1)
            got_sync = msg is not None and msg.arbitration_id == cf.SYNC_ID
        assert got_sync
        bus.send(can.Message(arbitration_id=0, data=[1, 0], is_extended_id=False))
        deadline = time.monotonic() + 3
        seen_tpdo = False
        while time.monotonic() < deadline and not seen_tpdo:
            msg = bus.recv(timeout=0.1)
            seen_tpdo = msg is not None and msg.arbitration_id == 0x181 and len(msg.data) == 6
        assert seen_tpdo
    finally:
        bus.shutdown()


def _sees_sync(port: int) -> bool:
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
    try:
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline:
            msg = bus.recv(timeout=0.1)
            if msg is not None and msg.arbitration_id == cf.SYNC_ID:
                return True
        return False
    finally:
        bus.shutdown()


@pytest.mark.timeout(30)
def test_the_gateway_survives_peers_that_connect_and_leave_at_once(served):
    _rig, _, port = served
    for n in range(30):  # a port probe, a scanner, a client killed at once: each closes without a word
        with socket.create_connection(("127.0.0.1", port), timeout=2) as sock:
            if n % 3 == 1:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
            elif n % 3 == 2:
                sock.sendall(b"< open can0 >< rawmode >< send 1")
    assert _sees_sync(port), "the gateway stopped serving after peers that left at once"


@pytest.mark.timeout(60)
def test_a_hundred_idle_connections_to_the_gateway_cost_bounded_threads_and_never_cut_the_master(served):
    """The gateway's port has no key (a CAN bus has none): 100 idle connections must not cost 200
    threads (two per connection) nor push out the master, which sends every SYNC cycle."""
    _rig, _, port = served
    before = threading.active_count()
    idle: list[socket.socket] = []
    most = 0
    with PumaDrives("127.0.0.1", port, bus=PUMA_BUS) as drives:
        drives.start()
        with ControlLoop(drives) as loop:
            drives.enable()
            try:
                for _ in range(100):
                    idle.append(socket.create_connection(("127.0.0.1", port), timeout=5.0))
                    most = max(most, threading.active_count())
                loop.wait(100)  # the master goes on answering every SYNC
                drives.check()
            finally:
                for sock in idle:
                    sock.close()
    # 16 connections of two threads each (one being closed at a time), whatever the master's own threads
    assert most <= before + 8 + 2 * 16 + 2, (most, before)


@pytest.mark.timeout(60)
def test_puma_drives_enable_servo_and_report_crossfire_over_the_gateway(served):
    rig, _, port = served
    events: list[tuple[bool, float]] = []
    with PumaDrives("127.0.0.1", port, bus=PUMA_BUS) as drives:
        drives.on_crossfire(lambda blocked, t: events.append((blocked, t)))
        drives.enable()
        assert drives.states() == [cf.DriveState.OPERATION_ENABLED] * 6
        q0 = drives.positions()
        assert np.allclose(q0, P.Q_HOME, atol=5e-3)
        goal = q0 + 0.05
        for k in range(1, 151):
            drives.wait_sync(timeout=10.0)
            drives.send_targets(q0 + 0.05 * min(k / 100, 1.0))
        for _ in range(300):  # bus cycles (the drives move per SYNC, whatever the wall clock does)
            if np.allclose(drives.positions(), goal, atol=3e-3):
                break
            drives.wait_sync(timeout=10.0)
            drives.send_targets(goal)
        assert np.allclose(drives.positions(), goal, atol=3e-3)
        rig.crossfire_state = True
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and drives.crossfire is not True:
            time.sleep(0.01)
        assert drives.crossfire is True
        assert events[-1][0] is True and events[-1][1] > 0
        drives.check()


@pytest.mark.timeout(30)
def test_a_silent_bus_is_reported_as_lost_heartbeat(served):
    rig, _, port = served
    with PumaDrives("127.0.0.1", port, heartbeat_timeout=0.3, silence_timeout=0.4, bus=PUMA_BUS) as drives:
        drives.enable()
        drives.check()
        rig.running.clear()  # the sim stops: no SYNC, no heartbeat
        time.sleep(0.6)
        with pytest.raises(BusError, match="no SYNC, no heartbeats"):
            drives.check()
        drives.wait_sync(timeout=0.1)  # the last SYNC before the stop, not answered yet
        with pytest.raises(BusError, match="SYNC"):
            drives.wait_sync(timeout=0.1)


@pytest.mark.timeout(30)
def test_a_simulation_that_stalls_for_a_while_is_not_a_lost_bus(served):
    rig, _, port = served
    with PumaDrives("127.0.0.1", port, heartbeat_timeout=0.3, silence_timeout=3.0, bus=PUMA_BUS) as drives:
        drives.start()
        with ControlLoop(drives) as loop:  # targets flow from the first enabled cycle on, as in the PUMA driver
            drives.enable()
            rig.running.clear()  # a loaded machine: the sim gets no CPU for longer than the heartbeat period
            time.sleep(0.8)
            assert drives.lost() is None  # heartbeats are judged on the bus clock, which stood still too
            rig.running.set()
            loop.wait(100)
        drives.check()


@pytest.mark.timeout(30)
def test_a_closed_gateway_makes_the_drives_report_a_dead_bus(served):
    _rig, gw, port = served
    drives = PumaDrives("127.0.0.1", port, heartbeat_timeout=0.3, silence_timeout=0.4, bus=PUMA_BUS).open()
    try:
        drives.enable()
        gw.stop()
        time.sleep(0.6)
        with pytest.raises(BusError):
            drives.check()
    finally:
        drives.close()


def test_opening_a_bus_where_nothing_listens_fails_fast():
    free = free_port()
    with pytest.raises(BusError, match="cannot open"):
        PumaDrives("127.0.0.1", free, bus=PUMA_BUS).open(timeout=0.3)


def test_after_a_teleport_reset_hold_keeps_the_arm_where_it_was_put(rig):
    q_new = P.Q_HOME + 0.2
    for j, q in zip(rig.drives._drives, q_new):
        rig.pb.resetJointState(rig.drives._body, j.joint, float(q))
    rig.drives.reset_hold()
    rig.step(300)
    assert np.allclose(rig.drives.positions(), q_new, atol=5e-3)
