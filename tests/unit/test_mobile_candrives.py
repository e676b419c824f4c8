"""The mobile robot's wheel drives in CiA 402 profile velocity mode on the simulated CAN bus
(sim/mobile/candrives.py: CANopen slaves made from devices/wheel_drive.eds), driven in process (no
sockets)."""

from __future__ import annotations

import pytest

from services.devices import cia402 as cf
from sim.drives import POSITION_UNIT, VELOCITY_UNIT
from sim.mobile.candrives import CYCLE_S, TARGET_TIMEOUT_CYCLES, SimWheelCan


class FakeWheels:
    """Wheels that follow their velocity set point on a 40 rad/s² ramp (as WheelDrives does)."""

    def __init__(self) -> None:
        self.target = [0.0, 0.0]
        self.v = [0.0, 0.0]
        self.q = [0.0, 0.0]

    def set_velocity(self, left: float, right: float) -> None:
        self.target = [left, right]

    def advance(self, dt: float) -> None:
        for k in (0, 1):
            err = self.target[k] - self.v[k]
            self.v[k] += max(-40.0 * dt, min(40.0 * dt, err))
            self.q[k] += self.v[k] * dt

    def encoders(self) -> tuple[float, float]:
        return self.q[0], self.q[1]

    def velocities(self) -> tuple[float, float]:
        return self.v[0], self.v[1]

    def torques(self) -> tuple[float, float]:
        return 0.1, -0.1


class Rig:
    def __init__(self) -> None:
        self.wheels = FakeWheels()
        self.can = SimWheelCan(self.wheels)
        self.port = self.can.bus.connect()
        self.t = 0.0
        self.frames: list[cf.CanFrame] = []

    def run(self, seconds: float, each_sync: object = None) -> None:
        end = self.t + seconds
        while self.t < end - 1e-12:
            self.can.step(self.t)
            self.wheels.advance(0.004)
            for f in self.port.recv_all():
                self.frames.append(f)
                if f.can_id == cf.SYNC_ID and callable(each_sync):
                    each_sync()
            self.t += 0.004

    def send(self, frame: cf.CanFrame) -> None:
        self.port.send(frame)

    def rpdo(self, node: int, cw: int, velocity: float) -> cf.CanFrame:
        """RPDO1 as the drive's mapping has it: controlword and target velocity, rad/s."""
        data = self.can.rpdo_layout(node).pack_objects({0x6040: cw, 0x60FF: round(velocity / VELOCITY_UNIT)})
        return cf.CanFrame(0x200 + node, data)

    def report(self, frame: cf.CanFrame) -> dict[int, int]:
        """A TPDO's objects by index (counts)."""
        number = (frame.can_id - 0x180) // 0x100 + 1
        return self.can.tpdo_layout(frame.can_id & 0x7F, number).unpack_objects(frame.data)

    def enable(self) -> None:
        self.send(cf.nmt_frame(cf.NmtCommand.START))
        self.run(0.02)
        for cw in (cf.Controlword.SHUTDOWN, cf.Controlword.SWITCH_ON, cf.Controlword.ENABLE_OPERATION):
            for node in cf.WHEEL_IDS:
                self.send(self.rpdo(node, cw, 0.0))
            self.run(0.02)

    def velocity(self, left: float, right: float) -> None:
        self.send(self.rpdo(1, cf.Controlword.ENABLE_OPERATION, left))
        self.send(self.rpdo(2, cf.Controlword.ENABLE_OPERATION, right))
        self.send(cf.encode_heartbeat(cf.MASTER_ID, cf.NmtState.OPERATIONAL))


def test_the_wheel_drives_pdos_are_those_of_their_eds_in_units_of_a_tenth_of_a_milliradian_per_second():
    rig = Rig()
    assert rig.can.rpdo_layout(2).indices == (0x6040, 0x60FF)
    assert rig.can.tpdo_layout(1, 1).indices == (0x6041, 0x6064)
    assert rig.can.tpdo_layout(1, 2).indices == (0x606C, 0x6077)
    f = rig.rpdo(2, cf.Controlword.ENABLE_OPERATION, -12.3456)
    assert f.can_id == 0x202 and f.data == bytes([0x0F, 0x00]) + (-123456).to_bytes(4, "little", signed=True)


def test_enabled_wheel_drives_take_target_velocities_and_report_position_and_velocity_after_each_sync():
    rig = Rig()
    rig.enable()
    assert rig.can.states() == [cf.DriveState.OPERATION_ENABLED] * 2
    rig.run(0.5, each_sync=lambda: rig.velocity(8.0, 6.0))
    assert rig.wheels.v == pytest.approx([8.0, 6.0])
    tpdo2 = [f for f in rig.frames if f.can_id == 0x280 + 1]
    assert rig.report(tpdo2[-1])[0x606C] * VELOCITY_UNIT == pytest.approx(8.0, abs=0.2)
    tpdo1 = [f for f in rig.frames if f.can_id == cf.TPDO1_BASE + 2]
    values = rig.report(tpdo1[-1])
    assert cf.state_from_statusword(values[0x6041]) is cf.DriveState.OPERATION_ENABLED
    assert values[0x6064] * POSITION_UNIT > 1.0
    syncs = [f.t for f in rig.frames if f.can_id == cf.SYNC_ID]
    assert syncs[-1] - syncs[-2] == pytest.approx(CYCLE_S, abs=0.0041)


def test_a_drive_that_is_not_enabled_holds_its_wheel_and_ignores_targets():
    rig = Rig()
    rig.send(cf.nmt_frame(cf.NmtCommand.START))
    rig.run(0.2, each_sync=lambda: rig.velocity(8.0, 8.0))
    assert rig.wheels.v == [0.0, 0.0]
    assert rig.can.states() == [cf.DriveState.SWITCH_ON_DISABLED] * 2


def test_a_silent_master_makes_both_drives_fault_with_rpdo_timeout_and_brake_the_wheels_to_rest():
    rig = Rig()
    rig.enable()
    rig.run(0.6, each_sync=lambda: rig.velocity(16.0, 16.0))
    assert rig.wheels.v == pytest.approx([16.0, 16.0])
    rig.run(0.8)  # the master goes silent
    assert [f.code for f in rig.can.faults] == [cf.EmcyCode.RPDO_TIMEOUT] * 2
    fault = rig.can.faults[0]
    assert fault.speed == pytest.approx(16.0)
    # noticed after the timeout, then on the 40 rad/s² ramp: 16 / 40 = 0.4 s
    assert fault.t_stopped - fault.t == pytest.approx(0.4, abs=0.02)
    assert rig.wheels.v == [0.0, 0.0]
    assert rig.can.states() == [cf.DriveState.FAULT] * 2
    emcy = [f for f in rig.frames if f.can_id == cf.EMCY_BASE + 1]
    assert cf.decode_emcy(emcy[-1].data)[0] == cf.EmcyCode.RPDO_TIMEOUT
    assert TARGET_TIMEOUT_CYCLES * CYCLE_S <= 0.2


def test_a_faulted_wheel_drive_is_reset_by_the_rising_edge_of_bit_7_and_enabled_again():
    rig = Rig()
    rig.enable()
    rig.run(0.3)  # no targets: RPDO timeout
    assert rig.can.states() == [cf.DriveState.FAULT] * 2
    for cw in (cf.Controlword.DISABLE_VOLTAGE, cf.Controlword.FAULT_RESET):
        for node in cf.WHEEL_IDS:
            rig.send(rig.rpdo(node, cw, 0.0))
        rig.run(0.02)
    assert rig.can.states() == [cf.DriveState.SWITCH_ON_DISABLED] * 2
    rig.enable()
    rig.run(0.3, each_sync=lambda: rig.velocity(4.0, 4.0))
    assert rig.can.states() == [cf.DriveState.OPERATION_ENABLED] * 2
    assert rig.wheels.v == pytest.approx([4.0, 4.0])


def test_the_masters_heartbeat_lost_faults_the_enabled_drives():
    rig = Rig()
    rig.enable()

    def targets_without_heartbeat() -> None:
        rig.send(rig.rpdo(1, cf.Controlword.ENABLE_OPERATION, 2.0))
        rig.send(rig.rpdo(2, cf.Controlword.ENABLE_OPERATION, 2.0))

    rig.run(0.1, each_sync=lambda: rig.velocity(2.0, 2.0))
    rig.run(0.6, each_sync=targets_without_heartbeat)
    assert rig.can.faults and rig.can.faults[0].code is cf.EmcyCode.HEARTBEAT_LOST


def test_the_world_waits_for_a_master_in_step_at_each_sync_but_not_again_for_one_that_missed():
    rig = Rig()
    rig.can.master_wait_s = 0.05
    rig.enable()
    rig.run(0.05, each_sync=lambda: rig.velocity(4.0, 4.0))
    misses = rig.can.master_misses
    rig.run(0.2, each_sync=lambda: rig.velocity(4.0, 4.0))
    assert rig.can.master_misses == misses
    rig.run(0.5)  # the master goes silent: one wait runs out, then no more waiting
    assert rig.can.master_misses == misses + 1
    waits = rig.can.master_waits
    rig.run(0.1)
    assert rig.can.master_waits == waits
    assert [f.code for f in rig.can.faults] == [cf.EmcyCode.RPDO_TIMEOUT] * 2
