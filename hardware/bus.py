"""A small motor bus over `dynamixel_sdk` (Protocol 2.0, X series), after lerobot's MotorsBus.

Every transaction is retried a bounded number of times on a communication failure; then it
raises an error that names the motor. Every status packet's error byte is checked: the alert
bit (0x80) means a hardware error, which is read from register 70 and decoded.

Sharp edges of the SDK this class works around (docs: shared/docs/DYNAMIXEL.md):

* No REG_WRITE/ACTION: a unicast ACTION leaves its reply to be taken as the next answer.
* A sync read shares one timeout across all motors, and the SDK's GroupSyncRead drops the
  error bytes. So `sync_read` sends SYNC_READ itself and reads each reply with `readRx`
  (keeping its error byte); when the group fails it falls back to per-motor reads, which name
  the silent motor.
* Sync writes get no reply: the state is not guaranteed changed when they return; callers
  that need it read it back.
* The SDK takes the first status packet from the right id as the answer, so a reply that
  comes after its transaction timed out (a USB or OS stall) would answer the next request.
  Here a reply must also have the request's shape (its parameter count), and after any
  failed transaction the next one to that motor is preceded by a marker: a READ of a length
  no other request uses and no earlier marker used (`_resync`). A motor answers in order, so
  once the marker's reply is in, every older reply has been read and discarded
  (`stale_replies` counts them).
* The SDK never byte-stuffs what it sends, so a payload holding FF FF FD would be mangled by
  the motor: such writes are refused here.
* A KeyboardInterrupt inside a transaction leaves the SDK's `is_using` flag set, after which
  every transaction fails as "port busy": `recover()` clears it.

The Bus Watchdog (98): with `watchdog` set, `set_torque(..., True)` arms it on each motor
before its torque goes on, and `set_torque(..., False)` and `torque_off_everywhere` disarm it
before torque goes off. Every transaction feeds it; `start_keepalive` adds a thread that
reads the motors whenever the bus has been idle for a while (the filter's update, a prompt),
so that only a dead process, a hung serial line or a pulled cable lets it expire. Every
transaction holds `lock`, so that thread and the caller's never interleave on the wire.
"""

from __future__ import annotations

import errno
import fcntl
import functools
import glob
import logging
import os
import threading
import time
from collections.abc import Iterable, Mapping, Sequence

from vlr.hardware.control_table import (
    ALERT_BIT,
    MODEL_NUMBERS,
    SDK_BAUD_RATES,
    WATCHDOG_EXPIRED,
    WATCHDOG_MAX,
    Reg,
    describe_hardware_error,
    describe_status_error,
)
from vlr.hardware.errors import HardwareError
from vlr.hardware.protocol2 import BROADCAST_ID, Instruction

from vlr.errors import MissingExtra

try:
    import serial
    from dynamixel_sdk import (
        COMM_RX_CORRUPT,
        COMM_RX_TIMEOUT,
        COMM_SUCCESS,
        GroupSyncWrite,
        PacketHandler,
        PortHandler,
    )
    from dynamixel_sdk.protocol2_packet_handler import (
        PKT_ERROR,
        PKT_ID,
        PKT_INSTRUCTION,
        PKT_LENGTH_H,
        PKT_LENGTH_L,
        PKT_PARAMETER0,
    )
except ImportError as exc:  # a core install: the sim runs, the real hand does not
    package = "pyserial" if exc.name == "serial" else "dynamixel-sdk"  # as pip names them
    raise MissingExtra(package, "hardware", "the real hand's motor bus") from exc

log = logging.getLogger(__name__)

#: Bytes of a status packet besides its parameters: header 4, id, length 2, instruction,
#: error, CRC 2.
STATUS_OVERHEAD = 11

#: The markers of `MotorBus._resync` read this many bytes from address 0, plus a counter
#: modulo MARKER_LENGTHS: lengths no other request reads, each unlike the last few markers'.
MARKER_BASE, MARKER_LENGTHS = 40, 16


class PortError(HardwareError):
    """The serial port does not exist, is busy, or cannot be opened."""


class CommError(HardwareError):
    """A motor did not answer, or its replies stayed corrupted, after bounded retries."""

    def __init__(self, message: str, ids: Sequence[int] = ()) -> None:
        super().__init__(message)
        self.ids = tuple(ids)


class MotorFaultError(HardwareError):
    """A motor reports a hardware error (register 70): it has switched its torque off."""

    def __init__(self, message: str, dxl_id: int, bits: int) -> None:
        super().__init__(message)
        self.dxl_id = dxl_id
        self.bits = bits


class MotorStatusError(HardwareError):
    """A motor refused an instruction (status error number, e.g. access error 7)."""


class _PortHandler(PortHandler):
    """The SDK's port handler with a configurable latency budget in its packet timeout.

    The SDK budgets 2 x 16 ms for the USB adapter's latency timer (FTDI default 16 ms); with
    the U2D2's latency timer set to 1 ms, or on a pseudo-terminal, a smaller budget makes a
    silent motor cost milliseconds instead of 34 ms per try.
    """

    def __init__(self, port_name: str, latency_ms: float) -> None:
        super().__init__(port_name)
        self.latency_ms = latency_ms

    def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 (SDK name)
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = (self.tx_time_per_byte * packet_length + 2.0 * self.latency_ms
                               + 2.0)


def _locked(method):
    """Run a bus method holding the bus's lock and stamp when the bus was last used."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with self.lock:
            try:
                return method(self, *args, **kwargs)
            finally:
                self.last_used = time.monotonic()
    return wrapper


def serial_ports() -> list[str]:
    """Serial ports that look like a U2D2 or another USB adapter."""
    found = []
    for pattern in ("/dev/serial/by-id/*", "/dev/ttyUSB*", "/dev/ttyACM*"):
        found.extend(sorted(glob.glob(pattern)))
    return found


class MotorBus:
    """The motors on one serial port (Protocol 2.0).

    Args:
        port: serial device, e.g. /dev/ttyUSB0.
        baud: bits per second; must match the motors' Baud Rate (8).
        labels: names for messages, e.g. {1: "thumb"}.
        latency_ms: USB latency budget in each packet timeout [ms] (see `_PortHandler`).
        retries: extra tries of a failed transaction before raising `CommError`.
        watchdog: the Bus Watchdog (98) armed on each motor while its torque is on [units of
            20 ms, 1..127]; 0 leaves register 98 alone (motor firmware before v38 has none).
    """

    def __init__(self, port: str, baud: int, *, labels: Mapping[int, str] | None = None,
                 latency_ms: float = 16.0, retries: int = 2, watchdog: int = 0) -> None:
        if not 0 <= watchdog <= WATCHDOG_MAX:
            raise ValueError(f"bus watchdog {watchdog} must be in [0, {WATCHDOG_MAX}] "
                             "(units of 20 ms)")
        self.watchdog = watchdog
        self.lock = threading.RLock()
        self.last_used = time.monotonic()
        self._keepalive: threading.Thread | None = None
        self._keepalive_stop = threading.Event()
        self.port_name = port
        self.baud = baud
        self.labels = dict(labels or {})
        self.latency_ms = latency_ms
        self.retries = retries
        self.packet = PacketHandler(2.0)
        self.port: _PortHandler | None = None
        self.stale_replies = 0  # status packets read and discarded as not the answer
        # Motors whose last transaction failed: a late reply of theirs may still come.
        self._unsynced: set[int] = set()
        self._markers = 0

    # ----------------------------------------------------------------- connection
    def connect(self) -> None:
        """Open and lock the port; raise `PortError` naming the port on failure."""
        if self.baud not in SDK_BAUD_RATES:
            raise PortError(f"baud rate {self.baud} is not one the DYNAMIXEL SDK supports; "
                            f"use one of {', '.join(map(str, SDK_BAUD_RATES))}")
        if not os.path.exists(self.port_name):
            present = serial_ports()
            hint = (f"serial ports present: {', '.join(present)}" if present else
                    "no USB serial adapter is present (is the U2D2 plugged in?)")
            raise PortError(f"serial port {self.port_name} does not exist; {hint}")
        port = _PortHandler(self.port_name, self.latency_ms)
        port.baudrate = self.baud
        try:
            port.openPort()
        except (serial.SerialException, OSError) as exc:
            raise PortError(self._open_failure(exc)) from None
        try:
            # Exclusive advisory lock: a second program using this bus would garble packets.
            fcntl.flock(port.ser.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            port.closePort()
            raise PortError(f"serial port {self.port_name} is busy: another program holds it "
                            "(close other vlr runs, the DYNAMIXEL Wizard, or screen)") from None
        self.port = port

    def _open_failure(self, exc: Exception) -> str:
        code = getattr(exc, "errno", None)
        if code in (errno.EACCES, errno.EPERM):
            return (f"no permission to open serial port {self.port_name}; add yourself to the "
                    "dialout group (sudo usermod -aG dialout $USER) and log in again")
        if code == errno.EBUSY:
            return f"serial port {self.port_name} is busy: another program holds it"
        return f"cannot open serial port {self.port_name}: {exc}"

    def close(self) -> None:
        """Stop the keep-alive thread and close the port (releases the lock). Safe to call
        twice."""
        self.stop_keepalive()
        if self.port is not None:
            self.port.is_using = False
            try:
                self.port.closePort()
            finally:
                self.port = None

    @property
    def connected(self) -> bool:
        return self.port is not None

    @_locked
    def recover(self) -> None:
        """Make the port usable after a failed or interrupted transaction: clear the SDK's
        busy flag and drop late replies (waiting a little so they have arrived)."""
        port = self._port()
        port.is_using = False
        time.sleep(0.002 + 20 * port.tx_time_per_byte / 1000.0)
        try:
            port.clearPort()
        except (serial.SerialException, OSError):
            pass

    def _port(self) -> _PortHandler:
        if self.port is None:
            raise HardwareError(f"the motor bus on {self.port_name} is not connected")
        return self.port

    def label(self, dxl_id: int) -> str:
        name = self.labels.get(dxl_id)
        return f"motor {dxl_id} ({name})" if name else f"motor {dxl_id}"

    # ----------------------------------------------------------------- error handling
    def _retry(self, what: str, ids: int | Sequence[int], attempt):
        """Run `attempt() -> (result, value)` until COMM_SUCCESS, at most 1 + retries times."""
        ids = [ids] if isinstance(ids, int) else list(ids)
        result = COMM_SUCCESS
        for _ in range(self.retries + 1):
            self._resync(ids, what)
            result, value = attempt()
            if result == COMM_SUCCESS:
                return value
            log.info("%s: %s failed (%s); trying again", self.port_name, what,
                     self.packet.getTxRxResult(result))
            self._unsynced.update(ids)
            self.recover()
        raise CommError(self._comm_message(what, ids, result), ids)

    def _resync(self, ids: Sequence[int], what: str) -> None:
        """Before talking to a motor whose last transaction failed: send it a marker READ
        and take only the marker's reply (module docstring), so that no late reply answers
        a later request. Each try uses a new length: a late marker reply is no answer to the
        next marker either."""
        for dxl_id in ids:
            if dxl_id not in self._unsynced:
                continue
            result = COMM_SUCCESS
            for _ in range(self.retries + 1):
                self._markers += 1
                n = MARKER_BASE + self._markers % MARKER_LENGTHS
                result, _, _ = self._send(dxl_id, Instruction.READ, (0, 0, n, 0), n)
                if result == COMM_SUCCESS:
                    self._unsynced.discard(dxl_id)
                    break
                self.recover()
            else:
                raise CommError(self._comm_message(what, [dxl_id], result), [dxl_id])

    def _receive(self, dxl_id: int, n_data: int) -> tuple[int, bytes, int]:
        """(result, data, error byte) of the status packet answering the request just sent
        to `dxl_id`: from that id, with `n_data` parameter bytes. Any other packet (a late
        reply to an earlier request) is discarded, until the packet timeout."""
        port = self._port()
        while True:
            rx, result = self.packet.rxPacket(port, False)
            if result != COMM_SUCCESS:
                return result, b"", 0
            n = len(rx) - STATUS_OVERHEAD
            if rx[PKT_ID] == dxl_id and n == n_data:
                start = PKT_PARAMETER0 + 1
                return result, bytes(rx[start:start + n_data]), rx[PKT_ERROR]
            self.stale_replies += 1
            log.debug("%s: discarded a status packet from id %d with %d bytes (awaiting id %d, "
                      "%d bytes)", self.port_name, rx[PKT_ID], n, dxl_id, n_data)

    def _send(self, dxl_id: int, instruction: int, params: Sequence[int] = (),
              n_reply: int = 0) -> tuple[int, bytes, int]:
        """One instruction packet to `dxl_id` and its matched reply (`_receive`)."""
        port = self._port()
        tx = [0] * (10 + len(params))
        tx[PKT_ID] = dxl_id
        tx[PKT_LENGTH_L], tx[PKT_LENGTH_H] = (len(params) + 3) & 0xFF, (len(params) + 3) >> 8
        tx[PKT_INSTRUCTION] = instruction
        tx[PKT_PARAMETER0:PKT_PARAMETER0 + len(params)] = list(params)
        result = self.packet.txPacket(port, tx)
        if result != COMM_SUCCESS:
            port.is_using = False
            return result, b"", 0
        port.setPacketTimeout(STATUS_OVERHEAD + n_reply)
        return self._receive(dxl_id, n_reply)

    def _ping_once(self, dxl_id: int) -> tuple[int, tuple[int, int]]:
        result, data, error = self._send(dxl_id, Instruction.PING, (), 3)
        model = data[0] | (data[1] << 8) if result == COMM_SUCCESS else 0
        return result, (model, error)

    def _comm_message(self, what: str, ids: Sequence[int], result: int) -> str:
        who = ", ".join(self.label(i) for i in ids)
        tries = self.retries + 1
        where = f"on {self.port_name} at {self.baud} baud"
        if result == COMM_RX_TIMEOUT:
            return (f"{who} does not answer ({what}) {where} after {tries} tries: check its "
                    "id, baud rate, power (12 V) and the daisy-chain cable")
        if result == COMM_RX_CORRUPT:
            return (f"replies from {who} are corrupted (bad CRC or truncated; {what}) "
                    f"{where} after {tries} tries: check the cable and the baud rate")
        return (f"communication with {who} failed ({what}) {where}: "
                f"{self.packet.getTxRxResult(result)}")

    def check_status(self, dxl_id: int, error: int, what: str) -> None:
        """Raise if a status packet's error byte reports a problem (alert bit: decode 70)."""
        if error & ALERT_BIT:
            bits = self.hardware_error(dxl_id)
            raise MotorFaultError(
                f"{self.label(dxl_id)} is in a hardware error state and has switched its "
                f"torque off: {describe_hardware_error(bits)} (register 70 = 0x{bits:02X}). "
                "Remove the cause (load, heat, supply), then reboot the motor or power-cycle.",
                dxl_id, bits)
        if error & 0x7F:
            raise MotorStatusError(f"{self.label(dxl_id)} refused {what}: "
                                   f"{describe_status_error(error)}")

    # ----------------------------------------------------------------- transactions
    @_locked
    def ping(self, dxl_id: int) -> int:
        """The model number of `dxl_id`; `CommError` naming the id if it does not answer."""
        model, error = self._retry("ping", dxl_id, lambda: self._ping_once(dxl_id))
        self.check_status(dxl_id, error, "ping")
        return model

    def model_name(self, model: int) -> str:
        return MODEL_NUMBERS.get(model, f"model {model}")

    @_locked
    def read_raw(self, address: int, length: int, dxl_id: int) -> tuple[bytes, int]:
        """(data, status error byte) of a READ, with retries; the error byte is NOT checked."""
        params = (address & 0xFF, address >> 8, length & 0xFF, length >> 8)

        def attempt():
            result, data, error = self._send(dxl_id, Instruction.READ, params, length)
            return result, (data, error)
        return self._retry(f"read {length} bytes at {address}", dxl_id, attempt)

    def read(self, reg: Reg, dxl_id: int) -> int:
        """Read one register of one motor."""
        data, error = self.read_raw(reg.address, reg.size, dxl_id)
        self.check_status(dxl_id, error, f"read of {reg.name.lower()}")
        return reg.decode(data)

    def hardware_error(self, dxl_id: int) -> int:
        """Hardware Error Status (70) of a motor; never raises for the alert bit itself."""
        reg = Reg.HARDWARE_ERROR_STATUS
        data, _ = self.read_raw(reg.address, reg.size, dxl_id)
        return reg.decode(data)

    @_locked
    def write(self, reg: Reg, dxl_id: int, value: int, *, check_alert: bool = True) -> None:
        """Write one register of one motor and wait for its status."""
        data = _payload(reg, value, Instruction.WRITE)

        params = (reg.address & 0xFF, reg.address >> 8, *data)

        def attempt():
            result, _, error = self._send(dxl_id, Instruction.WRITE, params)
            return result, error
        error = self._retry(f"write of {reg.name.lower()}={value}", dxl_id, attempt)
        if not check_alert:
            error &= ~ALERT_BIT
        self.check_status(dxl_id, error, f"write of {reg.name.lower()}={value}")

    @_locked
    def sync_write(self, reg: Reg, values: Mapping[int, int]) -> None:
        """One SYNC_WRITE of `reg` to several motors. No reply: read back if it matters."""
        group = GroupSyncWrite(self._port(), self.packet, reg.address, reg.size)
        for dxl_id, value in values.items():
            group.addParam(dxl_id, list(_payload(reg, value, dxl_id)))

        def attempt():
            return group.txPacket(), None
        self._retry(f"sync write of {reg.name.lower()}", list(values), attempt)

    @_locked
    def sync_read(self, regs: Sequence[Reg], ids: Sequence[int]) -> dict[int, dict[Reg, int]]:
        """Read the span covering `regs` from every motor in `ids` with one SYNC_READ.

        If the group fails after retries, per-motor reads find the motor at fault, so the
        error names it (a group timeout alone cannot tell which motor is silent).
        """
        start = min(r.address for r in regs)
        length = max(r.address + r.size for r in regs) - start
        replies: dict[int, tuple[bytes, int]] | None = None
        for _ in range(self.retries + 1):
            replies = self._sync_read_once(start, length, ids)
            if replies is not None:
                break
            self.recover()
        if replies is None:
            replies = {i: self.read_raw(start, length, i) for i in ids}
        out = {}
        for dxl_id, (data, error) in replies.items():
            self.check_status(dxl_id, error, "sync read")
            out[dxl_id] = {r: r.decode(data[r.address - start:]) for r in regs}
        return out

    def _sync_read_once(self, start: int, length: int,
                        ids: Sequence[int]) -> dict[int, tuple[bytes, int]] | None:
        port = self._port()
        self._resync(ids, "sync read")
        result = self.packet.syncReadTx(port, start, length, list(ids), len(ids), False)
        if result != COMM_SUCCESS:
            port.is_using = False
            return None
        replies = {}
        for k, dxl_id in enumerate(ids):
            result, data, error = self._receive(dxl_id, length)
            if result != COMM_SUCCESS:
                port.is_using = False
                self._unsynced.update(ids[k:])  # their replies may still be on the way
                return None
            replies[dxl_id] = (data, error)
        return replies

    def sync_read_one(self, reg: Reg, ids: Sequence[int]) -> dict[int, int]:
        """One register from several motors."""
        return {i: v[reg] for i, v in self.sync_read([reg], ids).items()}

    # ----------------------------------------------------------------- conveniences
    @_locked
    def set_torque(self, ids: Iterable[int], on: bool) -> None:
        """Switch torque on or off, motor by motor (each write is acknowledged). With a
        `watchdog`, register 98 is written 0 first (which also clears an expired watchdog,
        whose read-only goals would refuse the next move), then, switching on, armed."""
        for dxl_id in ids:
            if self.watchdog:
                self.write(Reg.BUS_WATCHDOG, dxl_id, 0)
                if on:
                    self.write(Reg.BUS_WATCHDOG, dxl_id, self.watchdog)
            self.write(Reg.TORQUE_ENABLE, dxl_id, int(on))

    def watchdog_expired(self, dxl_id: int) -> bool:
        """Whether a motor's Bus Watchdog has expired (98 reads -1; never with no
        `watchdog`, as register 98 is then not this bus's to read)."""
        return bool(self.watchdog) and self.read(Reg.BUS_WATCHDOG, dxl_id) == WATCHDOG_EXPIRED

    @_locked
    def torque_off_everywhere(self, ids: Iterable[int]) -> list[str]:
        """Best effort, for shutdown: a broadcast torque-off (reaches a motor whose replies
        are lost), then each motor acknowledged: its Bus Watchdog disarmed (with a
        `watchdog`), then its torque off. Returns problems instead of raising."""
        problems = []
        port = self.port
        if port is None:
            return [f"bus on {self.port_name} is not connected"]
        port.is_using = False
        try:
            self.packet.write1ByteTxOnly(port, BROADCAST_ID, Reg.TORQUE_ENABLE.address, 0)
        except (serial.SerialException, OSError) as exc:
            problems.append(f"broadcast torque off failed: {exc}")
        for dxl_id in ids:
            regs = ([Reg.BUS_WATCHDOG] if self.watchdog else []) + [Reg.TORQUE_ENABLE]
            for reg in regs:
                try:
                    self.write(reg, dxl_id, 0, check_alert=False)
                except HardwareError as exc:
                    problems.append(str(exc))
                except (serial.SerialException, OSError) as exc:
                    problems.append(f"{self.label(dxl_id)}: {reg.name.lower()} = 0 failed: "
                                    f"{exc}")
        return problems

    # ----------------------------------------------------------------- keep-alive
    def start_keepalive(self, ids: Sequence[int], period: float) -> None:
        """Read the Bus Watchdog of `ids` from a daemon thread whenever the bus has been idle
        for `period` [s], so that a living process's pauses (a filter update of seconds, a
        prompt) never let the motors' watchdogs expire; a killed process's thread dies with
        it. Failures are left to the caller's next transaction to find and report."""
        self.stop_keepalive()
        self._keepalive_stop.clear()
        ids = list(ids)

        def feed() -> None:
            while not self._keepalive_stop.wait(period / 4.0):
                with self.lock:
                    if self.port is None or self._keepalive_stop.is_set():
                        return
                    if time.monotonic() - self.last_used < period:
                        continue
                    try:
                        self.sync_read_one(Reg.BUS_WATCHDOG, ids)
                    except (HardwareError, serial.SerialException, OSError) as exc:
                        log.debug("%s: keep-alive read failed: %s", self.port_name, exc)
                        self.last_used = time.monotonic()

        self._keepalive = threading.Thread(target=feed, name="dxl-keepalive", daemon=True)
        self._keepalive.start()

    def stop_keepalive(self) -> None:
        """Stop the keep-alive thread (waits for its transaction, if one is under way)."""
        self._keepalive_stop.set()
        thread, self._keepalive = self._keepalive, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    @_locked
    def reboot(self, dxl_id: int) -> None:
        """REBOOT a motor (clears a hardware error; torque comes back off)."""
        def attempt():
            result, _, error = self._send(dxl_id, Instruction.REBOOT)
            return result, error
        self._retry("reboot", dxl_id, attempt)


def _payload(reg: Reg, value: int, lead: int) -> bytes:
    """The register bytes of `value`, refused if they would need byte stuffing on the wire.

    `lead` is the byte sent just before them (the instruction or the motor id), so that an
    FF FF FD spanning both is caught too.
    """
    try:
        data = reg.encode(value)
    except OverflowError:
        raise ValueError(f"{reg.name.lower()} = {value} does not fit in {reg.size} bytes") \
            from None
    if b"\xff\xff\xfd" in bytes([lead]) + data:
        raise ValueError(f"{reg.name.lower()} = {value} encodes to FF FF FD, which the SDK "
                         "does not byte-stuff; the motor would misread it")
    return data
