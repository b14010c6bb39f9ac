"""Serial transport to the board: request/answer exchange with retries and re-opening.

:class:`BoardLink` sends frames (``lhgraph.device.protocol``), matches answers by sequence
number, repeats requests that were lost or arrived damaged, re-opens a vanished port (a
bounded number of times) and downloads a capture's blocks with a window of requests in
flight.
"""

from __future__ import annotations

import contextlib
import struct
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from typing import Protocol

from lhgraph.device.progress import Progress
from lhgraph.device.protocol import (
    ARM_DISCARD,
    CMD_ABORT,
    CMD_ARM,
    CMD_INFO,
    CMD_READ,
    CMD_STATUS,
    E_LENGTH,
    MAX_WIRE_FRAME,
    RESP_ERROR,
    RESP_FLAG,
    STATE_ARMED,
    STATE_CAPTURING,
    STATE_READY,
    TRANSIENT_ERRORS,
    BoardInfo,
    BoardRefused,
    BoardStatus,
    Frame,
    decode_frame,
    encode_frame,
    is_rejected_request,
)
from lhgraph.errors import DeviceError

DEFAULT_BAUDRATE = 6_000_000


class SerialLike(Protocol):
    """What the client needs from a port (``serial.Serial`` has it)."""

    def write(self, data: bytes) -> int | None: ...
    def read(self, size: int = 1) -> bytes: ...
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...

    @property
    def in_waiting(self) -> int: ...


PortOpener = Callable[[str, int], SerialLike]


class _LinkLost(Exception):
    """The port failed (unplugged, closed by the other side)."""


def open_serial(port: str, baudrate: int) -> SerialLike:
    """Open ``port`` with pyserial: 8N1, RTS/CTS flow control, exclusive access."""
    try:
        import serial  # pyserial; imported here so that the rest of lhgraph works without it
    except ImportError:
        raise DeviceError("pyserial is not installed (pip install pyserial)") from None
    try:
        return serial.Serial(port=port, baudrate=baudrate, rtscts=True, timeout=0.02,
                             write_timeout=2.0, exclusive=True)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise _LinkLost(str(exc)) from exc


class BoardLink:
    """Request/response exchange with the board over one serial port, with re-opening."""

    def __init__(self, port: str, baudrate: int = DEFAULT_BAUDRATE,
                 opener: PortOpener | None = None, *, timeout_s: float = 0.5,
                 max_reconnects: int = 5, reopen_attempts: int = 12):
        self.port = port
        self.baudrate = baudrate
        self.opener = opener or open_serial
        self.timeout_s = timeout_s
        self.max_reconnects = max_reconnects
        self.reopen_attempts = reopen_attempts
        self.reconnects = 0
        self._ser: SerialLike | None = None
        self._rx = bytearray()
        self._seq = 0

    # port handling
    def open(self) -> None:
        """Open the port (``DeviceError`` if it cannot be opened)."""
        try:
            self._ser = self.opener(self.port, self.baudrate)
        except _LinkLost as exc:
            raise DeviceError(f"cannot open {self.port}: {exc}") from None
        self._flush()

    def close(self) -> None:
        """Close the port (no error if it is gone)."""
        if self._ser is not None:
            with contextlib.suppress(Exception):
                self._ser.close()
        self._ser = None

    def __enter__(self) -> BoardLink:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _flush(self) -> None:
        self._rx.clear()
        if self._ser is not None:
            try:
                self._ser.reset_input_buffer()
                self._ser.write(b"\x00")  # ends any partial frame on the board's side
            except Exception as exc:  # noqa: BLE001 - pyserial raises several types
                raise _LinkLost(str(exc)) from exc

    def reconnect(self) -> None:
        """Re-open the port after it failed; ``DeviceError`` past the retry budget."""
        self.close()
        self.reconnects += 1
        if self.reconnects > self.max_reconnects:
            raise DeviceError(f"link to {self.port} lost {self.reconnects} times; giving up")
        delay = 0.05
        last = ""
        for _ in range(self.reopen_attempts):
            time.sleep(delay)
            delay = min(delay * 2, 1.0)
            try:
                self._ser = self.opener(self.port, self.baudrate)
                self._flush()
                return
            except _LinkLost as exc:
                self.close()
                last = str(exc)
        raise DeviceError(f"link to {self.port} lost and the port did not come back "
                          f"({self.reopen_attempts} attempts): {last}")

    # frames
    def next_seq(self) -> int:
        """Sequence numbers 1..255 (0 is what the board uses when it cannot tell)."""
        self._seq = self._seq % 255 + 1
        return self._seq

    def send(self, kind: int, payload: bytes = b"", seq: int | None = None) -> int:
        """Send one request; returns its sequence number."""
        if self._ser is None:
            raise _LinkLost("port not open")
        seq = self.next_seq() if seq is None else seq
        try:
            self._ser.write(encode_frame(kind, seq, payload))
        except Exception as exc:  # noqa: BLE001
            raise _LinkLost(str(exc)) from exc
        return seq

    def frames(self, deadline: float) -> Iterator[Frame]:
        """Yield good frames as they arrive until ``deadline`` (monotonic time)."""
        while True:
            while True:
                end = self._rx.find(0)
                if end < 0:
                    if len(self._rx) > MAX_WIRE_FRAME:
                        self._rx.clear()  # no delimiter for too long: drop and resync
                    break
                chunk = bytes(self._rx[:end])
                del self._rx[: end + 1]
                if not chunk:
                    continue
                try:
                    yield decode_frame(chunk)
                except ValueError:
                    continue
            if time.monotonic() >= deadline:
                return
            if self._ser is None:
                raise _LinkLost("port not open")
            try:
                data = self._ser.read(max(1, min(self._ser.in_waiting, 65536)))
            except Exception as exc:  # noqa: BLE001
                raise _LinkLost(str(exc)) from exc
            self._rx += data

    def request(self, kind: int, payload: bytes = b"", *, retries: int = 8) -> Frame:
        """Send a request and return the matching good answer, retrying on loss.

        A lost link is re-opened (within the reconnect budget). An ERROR answer that is not a
        transmission error raises :class:`BoardRefused`.
        """
        for _attempt in range(retries):
            try:
                seq = self.send(kind, payload)
                deadline = time.monotonic() + self.timeout_s
                for frame in self.frames(deadline):
                    if is_rejected_request(frame):
                        break  # a request arrived damaged: most likely this one, send again
                    if frame.seq != seq:
                        continue
                    if frame.kind == kind | RESP_FLAG:
                        return frame
                    if frame.kind == RESP_ERROR and len(frame.payload) >= 3:
                        code = frame.payload[0]
                        if code in TRANSIENT_ERRORS:
                            break
                        raise BoardRefused(kind, code, frame.payload[2])
            except _LinkLost:
                self.reconnect()
        raise DeviceError(f"no answer from the board on {self.port} to command 0x{kind:02x} "
                          f"after {retries} tries")

    def info(self) -> BoardInfo:
        """INFO."""
        return BoardInfo.parse(self.request(CMD_INFO).payload)

    def status(self) -> BoardStatus:
        """STATUS."""
        return BoardStatus.parse(self.request(CMD_STATUS).payload)

    def abort(self) -> BoardStatus:
        """ABORT: back to idle."""
        return BoardStatus.parse(self.request(CMD_ABORT).payload)

    def arm(self, duration_ms: int, delay_ms: int = 0, *,
            discard_previous: bool = False) -> BoardStatus:
        """ARM a capture of ``duration_ms`` starting after ``delay_ms``.

        The board refuses (:data:`E_UNREAD`) to drop a capture that was not downloaded,
        unless ``discard_previous``; firmware without that rule drops it anyway.
        """
        host_us = time.time_ns() // 1000
        payload = struct.pack("<IIQ", duration_ms, delay_ms, host_us)
        try:
            try:
                flags = struct.pack("<I", ARM_DISCARD) if discard_previous else b""
                return BoardStatus.parse(self.request(CMD_ARM, payload + flags).payload)
            except BoardRefused as exc:
                if not (discard_previous and exc.code == E_LENGTH):
                    raise  # E_LENGTH: firmware without ARM flags, which never asks
                return BoardStatus.parse(self.request(CMD_ARM, payload).payload)
        except BoardRefused as exc:
            # our first ARM may have been executed and only its answer lost
            if exc.code == 6:
                st = self.status()
                if st.state in (STATE_ARMED, STATE_CAPTURING) and st.duration_ms == duration_ms:
                    return st
            raise

    def read_blocks(self, status: BoardStatus, *, window: int = 4,
                    max_tries_per_block: int = 20,
                    progress: Progress | None = None) -> tuple[bytes, int]:
        """Download every block of a READY capture; returns (image, blocks re-requested)."""
        count, size, bsize = status.block_count, status.image_size, status.block_size
        blocks: list[bytes | None] = [None] * count
        tries = [0] * count
        queue: list[int] = list(range(count))
        outstanding: OrderedDict[int, tuple[int, float]] = OrderedDict()
        done_bytes = 0
        rerequested = 0
        wire_s = window * (bsize * 1.01 + 32) * 10 / max(self.baudrate, 1)
        timeout = self.timeout_s + wire_s

        def requeue(block: int) -> None:
            nonlocal rerequested
            if blocks[block] is None and block not in queue:
                queue.insert(0, block)
                rerequested += 1

        while done_bytes < size:
            try:
                while queue and len(outstanding) < window:
                    block = queue[0]
                    if tries[block] >= max_tries_per_block:
                        raise DeviceError(f"block {block} of {count} still bad after "
                                          f"{max_tries_per_block} tries; link too noisy")
                    seq = self.send(CMD_READ, struct.pack("<I", block))  # may lose the link
                    queue.pop(0)
                    tries[block] += 1
                    outstanding[seq] = (block, time.monotonic())
                deadline = min(t for _, t in outstanding.values()) + timeout
                for frame in self.frames(deadline):
                    if is_rejected_request(frame) and outstanding:
                        # answers come in order: the damaged request is the oldest open one
                        requeue(outstanding.popitem(last=False)[1][0])
                        continue
                    if frame.seq not in outstanding:
                        continue
                    # answers come in request order: earlier requests still open were lost
                    for s in list(outstanding):
                        if s == frame.seq:
                            break
                        requeue(outstanding.pop(s)[0])
                    block, _ = outstanding.pop(frame.seq)
                    want = min(bsize, size - block * bsize)
                    p = frame.payload
                    if (frame.kind == CMD_READ | RESP_FLAG and len(p) == 4 + want
                            and struct.unpack_from("<I", p)[0] == block):
                        if blocks[block] is None:
                            blocks[block] = p[4:]
                            done_bytes += want
                            if progress:
                                progress("download", done_bytes, size)
                    elif frame.kind == RESP_ERROR and p and p[0] not in TRANSIENT_ERRORS:
                        raise BoardRefused(CMD_READ, p[0], p[2] if len(p) > 2 else 0)
                    else:
                        requeue(block)
                    if not outstanding or (queue and len(outstanding) < window):
                        break
                now = time.monotonic()
                for s, (block, t) in list(outstanding.items()):
                    if now - t >= timeout:
                        del outstanding[s]
                        requeue(block)
            except _LinkLost:
                for block, _ in outstanding.values():
                    requeue(block)
                outstanding.clear()
                self.reconnect()
                again = self.status()
                if (again.state != STATE_READY or again.image_size != size
                        or again.image_crc != status.image_crc):
                    raise DeviceError("the capture on the board changed while the link was "
                                      f"down (now {again.state_name}); download aborted") from None
        return b"".join(b for b in blocks if b is not None), rerequested
