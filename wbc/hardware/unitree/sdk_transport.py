"""`SdkTransport`: the vendor's Go1 SDK (``unitree_legged_sdk`` 3.8, ``robot_interface.UDP``) as a `Transport`.

For a team that wants the vendor's own socket code between its host and its Go1: `UnitreeRobot` keeps its link
thread, its codec and its checks, and the SDK carries the frames. Going out, our encoded LowCmd frame is handed to
the SDK whole (``UDP.SetSend`` with the frame's bytes copies them and writes the same CRC), so what reaches the wire
is byte for byte what our codec made, clamped and checked. Coming in, the SDK checks a LowState's CRC and length and
hands back a struct; that struct is written back into the wire frame it came from (every field the SDK exposes, in
the layout's places), so `UnitreeRobot` decodes it with the same strict decoder as any other frame.

What the SDK does that the backend must not inherit, and what this class does about it (see HARDWARE-NOTES):

- A busy local port: the SDK prints an error and runs on an ephemeral port, deaf to the robot. Here the port is
  checked free before the SDK binds it, and checked held by the SDK afterwards; either failing is `PortBusyError`.
- A level other than 0xFF exits the process: this class only ever passes 0xFF.
- ``Recv`` keeps only the newest queued datagram and returns -3 for a bad CRC or a short frame: those are counted in
  `rejected` (the backend's `DecodeStats` never sees them). A datagram from another address never arrives (the SDK
  connects its socket), so `foreign` stays 0.
- The SDK gives no file descriptor to wait on, and a blocking ``Recv`` holds the GIL: `wait_readable` polls the
  non-blocking ``Recv`` every `poll_s` instead.
- Its socket is never closed (the destructor only prints): after `close` the port stays held until the process
  exits, so a second link in the same process needs another local port (0 picks one).
- It prints to standard output ("UDP Initialized ...", "Closing UDP.").
- It binds its port on every interface (``INADDR_ANY``; it takes no local address), whatever ``local`` names:
  `bound_address` says so, and `wbc hw` says it when ``--transport sdk`` is chosen. Its socket is connected to the
  target, so the kernel hands it only the target's datagrams.
"""

from __future__ import annotations

import errno
import socket
import struct
import time
from types import ModuleType
from typing import Any

import numpy as np

from wbc.errors import ConfigError, PortBusyError, RobotLinkError
from wbc.hardware.unitree.battery import Battery
from wbc.hardware.unitree.crc import frame_crc
from wbc.hardware.unitree.layout import (
    GO1_LAYOUT,
    IMU_FLOATS,
    LEVEL_LOWLEVEL,
    NUM_MOTOR_SLOTS,
    REMOTE_SIZE,
    STATE_MOTOR_DTYPE,
    TAU_EST_SCALE,
    FrameLayout,
)
from wbc.hardware.unitree.target import check_target

__all__ = ["SDK_ROBOTS", "SdkTransport", "import_robot_interface", "sdk_state_frame"]

SDK_ROBOTS = ("go1",)
"""Robots whose wire the registry's vendor SDK speaks (the A1's SDK 3.3 has no published Python bindings)."""

_HEADER = struct.Struct("<2sBB2I2IH")  # Go1: head, levelFlag, frameReserve, SN u32 x 2, version u32 x 2, bandWidth
_IMU_TEMPERATURE = struct.Struct("<b")
_TICK = struct.Struct("<I")
_FEET = struct.Struct("<4h4h")


def import_robot_interface() -> ModuleType:
    """The vendor SDK's binding module.

    Raises:
        ConfigError: the SDK is not installed; the message says how to install it.
    """
    try:
        from unitree_legged_sdk import robot_interface
    except ImportError as exc:
        raise ConfigError("the vendor transport needs Unitree's SDK: pip install --no-deps "
                          "'unitree-legged-sdk==3.8.20231105' (the `hardware` extra names it; its metadata lists "
                          f"build tools it never imports, hence --no-deps) ({exc})") from None
    return robot_interface


def sdk_state_frame(layout: FrameLayout, state: Any) -> bytes:
    """The LowState frame a vendor SDK ``LowState`` struct was decoded from, CRC included.

    Every field the SDK exposes goes back to its place on the wire, undoing the SDK's scaling (tauEst x 256, the
    battery's cell voltages in mV as counts of 32 mV); the SDK exposes no reserve bytes, which stay zero.

    Args:
        layout: the Go1's layout (`GO1_LAYOUT`).
        state: a ``robot_interface.LowState`` that ``UDP.GetRecv`` filled.
    """
    buf = bytearray(layout.state_size)
    _HEADER.pack_into(buf, 0, bytes(state.head), state.levelFlag, state.frameReserve, *state.SN, *state.version,
                      state.bandWidth)
    imu = state.imu
    floats = [*imu.quaternion, *imu.gyroscope, *imu.accelerometer, *imu.rpy]
    io = layout.state_imu_offset
    buf[io:io + 4 * IMU_FLOATS] = np.asarray(floats, dtype="<f4").tobytes()
    _IMU_TEMPERATURE.pack_into(buf, io + 4 * IMU_FLOATS, imu.temperature)
    motors = np.frombuffer(buf, STATE_MOTOR_DTYPE, count=NUM_MOTOR_SLOTS, offset=layout.state_motor_offset)
    rows = [(m.mode, m.q, m.dq, m.ddq, round(m.tauEst * TAU_EST_SCALE), m.q_raw, m.dq_raw, m.ddq_raw, m.temperature)
            for m in state.motorState]
    motors[:] = np.array(rows, dtype=STATE_MOTOR_DTYPE)
    del motors
    bms = state.bms
    Battery(version=(bms.version_h, bms.version_l), status=bms.bms_status, soc=bms.SOC, current=bms.current * 1e-3,
            cycle=bms.cycle, bq_ntc=tuple(bms.BQ_NTC), mcu_ntc=tuple(bms.MCU_NTC),
            cell_voltage=np.asarray(bms.cell_vol, dtype=np.float64) * 1e-3).pack_into(buf, layout.state_bms_offset)
    _FEET.pack_into(buf, layout.state_foot_force_offset, *state.footForce, *state.footForceEst)
    _TICK.pack_into(buf, layout.state_tick_offset, state.tick)
    buf[layout.state_remote_offset:layout.state_remote_offset + REMOTE_SIZE] = bytes(state.wirelessRemote)
    _TICK.pack_into(buf, layout.state_crc_offset, frame_crc(buf))
    return bytes(buf)


class SdkTransport:
    """Unitree's ``robot_interface.UDP`` behind the `Transport` protocol (Go1 only).

    Args:
        local: ``(host, port)``: the SDK binds every interface on ``port``; ``host`` is checked by the address
            policy only. Port 0 picks a free one (read it back from `local_address`).
        target: ``(host, port)`` that frames are sent to; the SDK accepts replies from it only.
        allow_hardware: allow addresses outside 127.0.0.0/8 (`wbc.hardware.unitree.target.check_target`).
        robot: ``go1`` (`SDK_ROBOTS`).
        poll_s: how often `wait_readable` asks the SDK for a datagram [s].
        sdk: the ``robot_interface`` module; None imports the installed one.

    Attributes:
        foreign: always 0 (the SDK's socket is connected to the target; the kernel drops other senders).
        rejected: datagrams the SDK refused (``Recv`` -3: bad CRC or short frame).

    Raises:
        TargetRefusedError: an address outside 127.0.0.0/8 without `allow_hardware`.
        ConfigError: a robot the SDK does not speak, a bad `poll_s`, or the SDK is not installed.
        PortBusyError: the local port is held (checked before the SDK binds, and again after).
    """

    def __init__(self, local: tuple[str, int], target: tuple[str, int], *, allow_hardware: bool = False,
                 robot: str = "go1", poll_s: float = 2e-4, sdk: ModuleType | None = None) -> None:
        check_target(target[0], target[1], allow_hardware=allow_hardware, what="target")
        check_target(local[0], 1, allow_hardware=allow_hardware, what="local address")
        if robot not in SDK_ROBOTS:
            raise ConfigError(f"SdkTransport: the vendor SDK in the registry speaks the wire of {', '.join(SDK_ROBOTS)}"
                              f" only, not {robot!r}; use UdpTransport (transport='udp') for it")
        if not 0 < poll_s <= 1e-3:
            raise ConfigError(f"SdkTransport.poll_s must be in (0, 0.001] s, got {poll_s}")
        ri = sdk if sdk is not None else import_robot_interface()
        self.layout = GO1_LAYOUT
        self.target = (str(target[0]), int(target[1]))
        self.poll_s = poll_s
        self.foreign = 0
        self.rejected = 0
        host, port = str(local[0]), int(local[1])
        port = _free_port(host, port)
        self._ri = ri
        self._udp: Any = ri.UDP(LEVEL_LOWLEVEL, port, self.target[0], self.target[1])
        if _port_is_free(host, port):
            self._udp = None
            raise PortBusyError(host, port, "the vendor SDK did not bind it (it fell back to another port, deaf to "
                                            "the robot)")
        self._state = ri.LowState()
        self._queued: list[bytes] = []
        self.local_address = (host, port)  # where it is reached from this machine
        self.bound_address = ("0.0.0.0", port)  # what the SDK bound: every interface (it takes no address)

    @property
    def closed(self) -> bool:
        """True once `close` ran."""
        return self._udp is None

    def _sdk(self) -> Any:
        if self._udp is None:
            raise RobotLinkError(f"SdkTransport {self.local_address}: closed")
        return self._udp

    def send(self, frame: bytes) -> None:
        """Hand `frame` (a whole LowCmd) to the SDK and send it.

        Raises:
            RobotLinkError: the transport is closed, or the frame is not a LowCmd's length.
        """
        if len(frame) != self.layout.cmd_size:
            raise RobotLinkError(f"SdkTransport.send: a Go1 LowCmd is {self.layout.cmd_size} B, got {len(frame)}")
        udp = self._sdk()
        udp.SetSend(bytes(frame))
        udp.Send()

    def _poll(self) -> None:
        result = self._sdk().Recv()
        if result == 0:
            self._udp.GetRecv(self._state)
            self._queued.append(sdk_state_frame(self.layout, self._state))
        elif result == -3:
            self.rejected += 1

    def receive(self) -> list[bytes]:
        """The state frames the SDK accepted since the last call (it keeps only the newest datagram of a burst)."""
        self._poll()
        out, self._queued = self._queued, []
        return out

    def wait_readable(self, timeout: float) -> bool:
        """Poll the SDK every `poll_s` for up to `timeout` seconds; True once a state frame is queued."""
        deadline = time.monotonic() + max(0.0, timeout)
        while True:
            if self._queued:
                return True
            self._poll()
            if self._queued:
                return True
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            time.sleep(min(self.poll_s, left))

    def close(self) -> None:
        """Stop using the SDK's socket. Idempotent. The SDK never closes it: the port stays held until exit."""
        self._udp = None
        self._queued = []


def _port_is_free(host: str, port: int) -> bool:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind((host, port))
        return True
    except OSError as exc:
        if exc.errno in (errno.EADDRINUSE, errno.EACCES):
            return False
        raise RobotLinkError(f"cannot probe UDP {host}:{port}: {exc}") from None
    finally:
        probe.close()


def _free_port(host: str, port: int) -> int:
    """`port` if it is free (else `PortBusyError`), or a free port the kernel picks when `port` is 0."""
    if port == 0:
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            probe.bind((host, 0))
            return int(probe.getsockname()[1])
        finally:
            probe.close()
    if not _port_is_free(host, port):
        raise PortBusyError(host, port, "held by another socket (the vendor SDK would silently run on another "
                                        "port, deaf to the robot)")
    return port
