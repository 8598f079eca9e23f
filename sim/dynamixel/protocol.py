"""Dynamixel Protocol 2.0 packets: CRC-16, byte stuffing, encoding and incremental parsing.

This is the emulator's own, independent implementation of the wire format (the driver in
``rig/dynamixel.py`` uses the official ``dynamixel_sdk``), so the tests check one against the
other. Packet layout (all multi-byte fields little endian)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS... | CRC_L CRC_H

``LEN`` counts the bytes after itself (instruction, parameters, CRC) *as transmitted*, i.e. after
byte stuffing, and the CRC (polynomial 0x8005, initial value 0, no reflection) covers every byte
before it, also as transmitted. Stuffing inserts ``FD`` after every ``FF FF FD`` in the
instruction and parameter bytes so a header never appears inside a packet.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from enum import IntEnum

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_PACKET_LENGTH = 1024
"""The largest LEN field accepted (the SDK's own buffer limit)."""


class Instruction(IntEnum):
    """Protocol 2.0 instruction codes."""

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
    FAST_BULK_READ = 0x9A


class ResultError(IntEnum):
    """The result code in the low 7 bits of a status packet's error byte."""

    NONE = 0x00
    RESULT_FAIL = 0x01
    INSTRUCTION = 0x02
    CRC = 0x03
    DATA_RANGE = 0x04
    DATA_LENGTH = 0x05
    DATA_LIMIT = 0x06
    ACCESS = 0x07


ALERT_BIT = 0x80
"""Set in a status packet's error byte while the servo has a hardware error."""


def _crc_table() -> tuple[int, ...]:
    # The table-driven form of the MSB-first CRC-16 with polynomial 0x8005 (CRC-16/BUYPASS);
    # built here rather than pasted so the polynomial is the only magic number.
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """CRC-16 of Protocol 2.0 (polynomial 0x8005, initial value 0) over ``data``.

    >>> hex(crc16(bytes.fromhex("FFFFFD0001030001")))
    '0x4e19'
    """
    for byte in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes | bytearray) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` in ``body`` (instruction and parameters).

    The header's own ``FF FF FD`` precedes the body and is never part of the pattern, as in
    the reference implementation.
    """
    out = bytearray()
    for byte in body:
        out.append(byte)
        if byte == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes | bytearray) -> bytes:
    """Undo :func:`stuff`: drop the ``FD`` that follows each ``FF FF FD`` in ``body``."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if body[i] == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            if i + 1 < len(body) and body[i + 1] == 0xFD:
                i += 1
        i += 1
    return bytes(out)


def encode(packet_id: int, instruction: int, params: bytes | bytearray = b"") -> bytes:
    """One complete packet (header, stuffed body, CRC) ready for the wire."""
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    head = HEADER + bytes([packet_id, length & 0xFF, length >> 8])
    frame = head + body
    crc = crc16(frame)
    return frame + bytes([crc & 0xFF, crc >> 8])


def encode_status(servo_id: int, error: int, params: bytes | bytearray = b"") -> bytes:
    """A status packet: instruction 0x55, the error byte, then the parameters."""
    return encode(servo_id, Instruction.STATUS, bytes([error]) + bytes(params))


@dataclass(frozen=True)
class Packet:
    """One parsed packet: ``params`` are unstuffed; ``crc_ok`` tells whether the CRC matched."""

    packet_id: int
    instruction: int
    params: bytes
    crc_ok: bool
    raw: bytes


class PacketParser:
    """Incremental parser: feed bytes as they arrive, take whole packets out.

    Bytes before a header are skipped. A header whose length field is impossible is skipped
    (resynchronising on the next header). A packet left incomplete for longer than
    ``stale_s`` is dropped, as a servo drops a frame that stops mid-way, so that one lost byte
    cannot swallow the next packet.
    """

    def __init__(self, *, stale_s: float = 0.05) -> None:
        self._buffer = bytearray()
        self._stale_s = stale_s
        self._last_feed = time.monotonic()

    def feed(self, data: bytes, now: float | None = None) -> list[Packet]:
        """Add ``data`` and return every packet now complete, in order."""
        now = time.monotonic() if now is None else now
        if self._buffer and now - self._last_feed > self._stale_s:
            self._buffer.clear()
        self._last_feed = now
        self._buffer.extend(data)
        packets: list[Packet] = []
        while True:
            start = self._buffer.find(HEADER)
            if start < 0:
                # Keep a possible partial header at the end for the next feed.
                keep = next(
                    (k for k in (3, 2, 1) if self._buffer.endswith(HEADER[:k])),
                    0,
                )
                del self._buffer[: len(self._buffer) - keep]
                return packets
            del self._buffer[:start]
            if len(self._buffer) < 7:
                return packets
            length = self._buffer[5] | (self._buffer[6] << 8)
            if length < 3 or length > MAX_PACKET_LENGTH:
                del self._buffer[:1]
                continue
            total = 7 + length
            if len(self._buffer) < total:
                return packets
            raw = bytes(self._buffer[:total])
            del self._buffer[:total]
            packets.append(decode(raw))

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a packet."""
        return len(self._buffer)


def decode(raw: bytes) -> Packet:
    """Parse one complete packet (header to CRC); the caller has checked its length field."""
    length = raw[5] | (raw[6] << 8)
    crc_expected = raw[7 + length - 2] | (raw[7 + length - 1] << 8)
    crc_ok = crc16(raw[: 7 + length - 2]) == crc_expected
    body = unstuff(raw[7 : 7 + length - 2])
    return Packet(
        packet_id=raw[4],
        instruction=body[0],
        params=bytes(body[1:]),
        crc_ok=crc_ok,
        raw=raw,
    )


def u_le(value: int, size: int) -> bytes:
    """``value`` as ``size`` little-endian bytes (two's complement when negative)."""
    return (value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")


def from_le(data: bytes | bytearray, *, signed: bool = False) -> int:
    """The little-endian integer in ``data``."""
    return int.from_bytes(data, "little", signed=signed)
