"""DYNAMIXEL Protocol 2.0 packets: CRC-16, byte stuffing, encoding and stream parsing.

The bus talks through `dynamixel_sdk`; this module is the device side, used by the emulator
(and by tests that check our CRC against the SDK's). Reference:
https://emanual.robotis.com/docs/en/dxl/protocol2/

Packet layout: FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS... | CRC_L CRC_H, where LEN counts
INST, PARAMS and CRC after stuffing, and the CRC covers every byte before it, stuffed.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

HEADER = bytes([0xFF, 0xFF, 0xFD, 0x00])
BROADCAST_ID = 0xFE
MAX_ID = 0xFC


class Instruction(IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93


def _crc_table(poly: int = 0x8005) -> tuple[int, ...]:
    """CRC-16 lookup table, MSB first, for the DYNAMIXEL polynomial x^16+x^15+x^2+1 (0x8005)."""
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ poly) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """CRC-16/BUYPASS as Protocol 2.0 uses it (initial value 0, no reflection)."""
    for b in data:
        crc = ((crc << 8) ^ CRC_TABLE[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert FD after every FF FF FD in the instruction/parameter part (the header can't
    then appear inside a packet)."""
    out = bytearray()
    for b in body:
        out.append(b)
        if b == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Drop the FD that follows every FF FF FD (the inverse of `stuff`)."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if (body[i] == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF
                and i + 1 < len(body) and body[i + 1] == 0xFD):
            i += 1  # skip the stuffing byte
        i += 1
    return bytes(out)


def encode(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete packet (stuffed, with CRC)."""
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    packet = HEADER + bytes([dxl_id, length & 0xFF, length >> 8]) + body
    crc = crc16(packet)
    return packet + bytes([crc & 0xFF, crc >> 8])


def encode_status(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet: instruction 0x55, then the error byte, then the parameters."""
    return encode(dxl_id, Instruction.STATUS, bytes([error]) + bytes(params))


@dataclass(frozen=True)
class Packet:
    """A parsed, unstuffed packet. `crc_ok` is False when the CRC did not match."""

    dxl_id: int
    instruction: int
    params: bytes
    crc_ok: bool = True


class PacketParser:
    """Splits a byte stream into packets: resynchronizes on the header, waits for the whole
    packet, checks the CRC. Feed bytes in any chunking; `packets()` yields what is complete."""

    #: A length above this is a corrupted header, not a packet (the SDK's own limit).
    MAX_LENGTH = 1024

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Packet]:
        self._buf.extend(data)
        out = []
        while True:
            packet = self._next()
            if packet is None:
                return out
            out.append(packet)

    def _next(self) -> Packet | None:
        buf = self._buf
        while True:  # a loop, not recursion: a long run of false headers is just skipped
            start = buf.find(HEADER[:3])
            if start < 0:
                # Keep a possible partial header at the end.
                del buf[: max(0, len(buf) - 2)]
                return None
            del buf[:start]
            if len(buf) < 7:
                return None
            length = buf[5] | (buf[6] << 8)
            if buf[3] == 0x00 and 3 <= length <= self.MAX_LENGTH:
                break
            del buf[:1]
        total = 7 + length
        if len(buf) < total:
            return None
        raw = bytes(buf[:total])
        del buf[:total]
        crc_ok = crc16(raw[:-2]) == (raw[-2] | (raw[-1] << 8))
        body = unstuff(raw[7:-2])
        return Packet(dxl_id=raw[4], instruction=body[0], params=body[1:], crc_ok=crc_ok)
