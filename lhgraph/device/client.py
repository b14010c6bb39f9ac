"""PC side of the board link: arm a capture, download it, write the ``.lhcap`` file.

The wire protocol is described in ``docs/protocol.md``; the file format in
``docs/formats/lhcap.md``. Typical use from a notebook::

    from lhgraph.device.client import download_capture
    result = download_capture("/dev/ttyUSB0", "run1.lhcap", duration_s=8.0)

The download is robust to a lossy or flaky link: every frame carries a CRC-32, bad or
missing blocks are requested again, a vanished port is re-opened (a bounded number of
times) and the transfer resumes where it stopped; the whole file is checked against the
CRC-32 the board reports before it is written (atomically: a temporary file in the same
directory, then a rename; never a half file under the final name).
"""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
import time
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from lhgraph.errors import DeviceError, InputError

PROTOCOL_VERSION = 1
DEFAULT_BAUDRATE = 6_000_000

CMD_INFO = 0x01
CMD_ARM = 0x02
CMD_STATUS = 0x03
CMD_READ = 0x04
CMD_ABORT = 0x05
RESP_FLAG = 0x80
RESP_ERROR = 0xFF

STATE_IDLE, STATE_ARMED, STATE_CAPTURING, STATE_READY = 0, 1, 2, 3
STATE_NAMES = {0: "idle", 1: "armed", 2: "capturing", 3: "ready"}

E_CRC, E_FRAMING, E_TOO_LONG = 1, 2, 3
ERROR_NAMES = {
    1: "bad frame CRC",
    2: "bad framing",
    3: "frame too long",
    4: "bad length",
    5: "unknown command",
    6: "not allowed in this state",
    7: "argument out of range",
    8: "block index out of range",
    9: "hardware error",
}
TRANSIENT_ERRORS = frozenset({E_CRC, E_FRAMING, E_TOO_LONG})

HEADER_LEN = 108
FRAME_OVERHEAD = 8
MAX_BLOCK = 4096
MAX_WIRE_FRAME = 2 * (4 + MAX_BLOCK + FRAME_OVERHEAD) + 64  # generous resync limit

Progress = Callable[[str, int, int], None]
"""``progress(phase, done, total)``; phase is ``"capture"`` (samples) or ``"download"``
(bytes)."""


class SerialLike(Protocol):
    """What the client needs from a port (``serial.Serial`` has it)."""

    def write(self, data: bytes) -> int | None: ...
    def read(self, size: int = 1) -> bytes: ...
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...

    @property
    def in_waiting(self) -> int: ...


PortOpener = Callable[[str, int], SerialLike]


# --- framing ------------------------------------------------------------------------------


def cobs_encode(data: bytes) -> bytes:
    """COBS-encode ``data`` (result has no zero byte; the 0x00 delimiter is not added)."""
    out = bytearray()
    for chunk in data.split(b"\x00"):
        while len(chunk) >= 254:
            out.append(0xFF)
            out += chunk[:254]
            chunk = chunk[254:]
        out.append(len(chunk) + 1)
        out += chunk
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises ``ValueError`` on a malformed encoding."""
    if not data:
        raise ValueError("empty COBS frame")
    if 0 in data:
        raise ValueError("zero byte inside a COBS frame")
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        end = i + code
        if end > n:
            raise ValueError("truncated COBS group")
        out += data[i + 1 : end]
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


@dataclass(frozen=True)
class Frame:
    """One decoded link frame."""

    kind: int
    seq: int
    payload: bytes


def encode_frame(kind: int, seq: int, payload: bytes = b"") -> bytes:
    """Wire form of a frame: COBS(type, seq, len, payload, CRC-32) + 0x00."""
    raw = struct.pack("<BBH", kind, seq, len(payload)) + payload
    return cobs_encode(raw + struct.pack("<I", zlib.crc32(raw))) + b"\x00"


def decode_frame(encoded: bytes) -> Frame:
    """Decode one frame (without its delimiter); ``ValueError`` if it is damaged."""
    raw = cobs_decode(encoded)
    if len(raw) < FRAME_OVERHEAD:
        raise ValueError("frame too short")
    (crc,) = struct.unpack_from("<I", raw, len(raw) - 4)
    if zlib.crc32(raw[:-4]) != crc:
        raise ValueError("frame CRC mismatch")
    kind, seq, length = struct.unpack_from("<BBH", raw)
    if length != len(raw) - FRAME_OVERHEAD:
        raise ValueError("frame length field mismatch")
    return Frame(kind, seq, raw[4:-4])


# --- messages -------------------------------------------------------------------------------


@dataclass(frozen=True)
class BoardInfo:
    """Answer to INFO."""

    protocol_version: int
    block_size: int
    firmware_version: int
    board_id: int
    sample_rate: int
    max_duration_ms: int
    max_delay_ms: int
    max_records: int

    @classmethod
    def parse(cls, payload: bytes) -> BoardInfo:
        """Decode an INFO payload (28 bytes)."""
        if len(payload) != 28:
            raise DeviceError(f"INFO answer has {len(payload)} bytes, expected 28")
        return cls(*struct.unpack("<HHIIIIII", payload))


@dataclass(frozen=True)
class BoardStatus:
    """Answer to STATUS (also to ARM and ABORT)."""

    state: int
    hw_error: int
    flags: int
    duration_ms: int
    delay_left_ms: int
    samples_done: int
    samples_target: int
    records: int
    image_size: int
    image_crc: int
    block_size: int
    block_count: int

    @classmethod
    def parse(cls, payload: bytes) -> BoardStatus:
        """Decode a STATUS payload (40 bytes)."""
        if len(payload) != 40:
            raise DeviceError(f"STATUS answer has {len(payload)} bytes, expected 40")
        return cls(*struct.unpack("<BBHIIIIIIIII", payload))

    @property
    def state_name(self) -> str:
        """``idle``, ``armed``, ``capturing`` or ``ready``."""
        return STATE_NAMES.get(self.state, f"state {self.state}")


@dataclass(frozen=True)
class CaptureDownload:
    """What :func:`download_capture` wrote."""

    path: Path
    size_bytes: int
    n_records: int
    capture_samples: int
    sample_rate_hz: int
    board_id: int
    firmware_version: int
    overflowed: bool
    crc32: int
    blocks: int
    blocks_rerequested: int
    reconnects: int
    capture_s: float
    download_s: float

    @property
    def duration_s(self) -> float:
        """Length of the capture in seconds."""
        return self.capture_samples / self.sample_rate_hz if self.sample_rate_hz else 0.0

    def summary(self) -> str:
        """One line for humans."""
        rate = self.size_bytes / self.download_s / 1e3 if self.download_s > 0 else float("inf")
        extra = "; OVERFLOWED (capture stopped early)" if self.overflowed else ""
        return (f"wrote {self.path}: {self.n_records} edge records, {self.duration_s:.3f} s, "
                f"{self.size_bytes} bytes in {self.download_s:.2f} s ({rate:.0f} kB/s), "
                f"{self.blocks_rerequested} blocks re-requested, "
                f"{self.reconnects} reconnects{extra}")


def _is_rejected_request(frame: Frame) -> bool:
    """An ERROR the board sends for a request it received damaged (seq unknown: 0)."""
    return (frame.kind == RESP_ERROR and frame.seq == 0 and len(frame.payload) >= 1
            and frame.payload[0] in TRANSIENT_ERRORS)


class _LinkLost(Exception):
    """The port failed (unplugged, closed by the other side)."""


class BoardRefused(DeviceError):
    """The board answered a request with an ERROR frame."""

    def __init__(self, command: int, code: int, state: int):
        self.command, self.code, self.state = command, code, state
        name = ERROR_NAMES.get(code, f"error {code}")
        super().__init__(f"board refused command 0x{command:02x}: {name} "
                         f"(board state: {STATE_NAMES.get(state, state)})")


# --- the link ---------------------------------------------------------------------------------


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
                    if _is_rejected_request(frame):
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

    def arm(self, duration_ms: int, delay_ms: int = 0) -> BoardStatus:
        """ARM a capture of ``duration_ms`` starting after ``delay_ms``."""
        host_us = time.time_ns() // 1000
        payload = struct.pack("<IIQ", duration_ms, delay_ms, host_us)
        try:
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
                    if _is_rejected_request(frame) and outstanding:
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


# --- the whole job ----------------------------------------------------------------------------


def _check_output(output: Path, overwrite: bool) -> None:
    if output.is_dir():
        raise InputError("is a directory", output)
    if output.exists() and not overwrite:
        raise InputError("exists already (use --force to overwrite)", output)
    if not output.parent.is_dir():
        raise InputError("directory does not exist", output.parent)
    if not os.access(output.parent, os.W_OK):
        raise InputError("directory is not writable", output.parent)


def _write_atomically(data: bytes, output: Path, overwrite: bool) -> None:
    """Temp file in the target directory, fsync, then rename (no-clobber unless overwrite)."""
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{output.name}.", suffix=".part",
                                        dir=output.parent)
    except OSError as exc:
        raise InputError(f"cannot write here: {exc.strerror}", output.parent) from None
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        if overwrite:
            os.replace(tmp, output)
        else:
            try:
                os.link(tmp, output)  # atomic and fails if the name exists
            except FileExistsError:
                raise InputError("exists already (use --force to overwrite)", output) from None
            except OSError:
                if output.exists():
                    raise InputError("exists already (use --force to overwrite)",
                                     output) from None
                os.replace(tmp, output)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", output) from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def _check_image(data: bytes, status: BoardStatus) -> str | None:
    """Why the downloaded image is not the board's capture, or None if it is."""
    if len(data) != status.image_size:
        return f"{len(data)} bytes received, board announced {status.image_size}"
    if data[:4] != b"LHCP":
        return "no LHCP magic at the start"
    (trailer,) = struct.unpack_from("<I", data, len(data) - 4)
    crc = zlib.crc32(data[:-4])
    if crc != trailer or crc != status.image_crc:
        return (f"whole-capture CRC mismatch (computed 0x{crc:08x}, file 0x{trailer:08x}, "
                f"board 0x{status.image_crc:08x})")
    (n_records,) = struct.unpack_from("<I", data, 40)
    if len(data) != HEADER_LEN + 8 * n_records + 4:
        return "record count disagrees with the size"
    return None


def _validate_ready(status: BoardStatus) -> None:
    size, bsize = status.image_size, status.block_size
    if size < HEADER_LEN + 4 or (size - HEADER_LEN - 4) % 8 != 0:
        raise DeviceError(f"board announces an impossible capture size ({size} bytes)")
    if not 1 <= bsize <= 65531 or status.block_count != -(-size // bsize):
        raise DeviceError(f"board announces inconsistent blocks ({status.block_count} x "
                          f"{bsize} bytes for {size} bytes)")


def download_capture(port: str, output_path: str | os.PathLike[str], duration_s: float = 8.0,
                     overwrite: bool = False, progress: Progress | None = None, *,
                     baudrate: int = DEFAULT_BAUDRATE, start_delay_s: float = 0.0,
                     arm: bool = True, timeout_s: float = 0.5, window: int = 4,
                     max_reconnects: int = 5, reopen_attempts: int = 12,
                     opener: PortOpener | None = None,
                     poll_interval_s: float = 0.05) -> CaptureDownload:
    """Arm the board on ``port``, wait for the capture, download it to ``output_path``.

    ``duration_s`` and ``start_delay_s`` go to the board's ARM command; ``arm=False``
    downloads the capture the board already holds (state ``ready``). ``progress`` is called
    as ``progress(phase, done, total)`` (see :data:`Progress`). A lost port is re-opened up
    to ``reopen_attempts`` times per loss (backing off to 1 s), for at most
    ``max_reconnects`` losses. Raises
    :class:`~lhgraph.errors.InputError` for bad arguments or an existing output (unless
    ``overwrite``) and :class:`~lhgraph.errors.DeviceError` for link or board failures.
    """
    output = Path(output_path)
    _check_output(output, overwrite)
    if arm and not 0 < duration_s <= 60:
        raise InputError(f"capture duration must be in (0, 60] s, got {duration_s}")
    if not 0 <= start_delay_s <= 60:
        raise InputError(f"start delay must be in [0, 60] s, got {start_delay_s}")
    if baudrate <= 0 or window < 1:
        raise InputError("baud rate and window must be positive")

    link = BoardLink(port, baudrate, opener, timeout_s=timeout_s, max_reconnects=max_reconnects,
                     reopen_attempts=reopen_attempts)
    with link:
        info = link.info()
        if info.protocol_version != PROTOCOL_VERSION:
            raise DeviceError(f"board speaks protocol {info.protocol_version}, this client "
                              f"{PROTOCOL_VERSION}: update one of them")
        t0 = time.monotonic()
        if arm:
            duration_ms = max(1, round(duration_s * 1000))
            delay_ms = round(start_delay_s * 1000)
            if duration_ms > info.max_duration_ms:
                raise InputError(f"the board captures at most {info.max_duration_ms / 1000} s")
            st = link.status()
            if st.state in (STATE_ARMED, STATE_CAPTURING):
                link.abort()
            link.arm(duration_ms, delay_ms)
            status = _wait_ready(link, duration_s + start_delay_s, progress, poll_interval_s)
        else:
            status = link.status()
            if status.state != STATE_READY:
                raise DeviceError(f"no capture to download: the board is {status.state_name}")
        capture_s = time.monotonic() - t0
        _validate_ready(status)
        t1 = time.monotonic()
        data, rerequested = link.read_blocks(status, window=window, progress=progress)
        problem = _check_image(data, status)
        if problem is not None:  # every frame was CRC-checked: retry once, whole
            data, again = link.read_blocks(status, window=window, progress=progress)
            rerequested += again + status.block_count
            problem = _check_image(data, status)
            if problem is not None:
                raise DeviceError(f"downloaded capture is damaged: {problem}")
        download_s = time.monotonic() - t1
    _write_atomically(data, output, overwrite)
    flags, board_id, fw = struct.unpack_from("<III", data, 12)
    (sample_rate,) = struct.unpack_from("<I", data, 8)
    (samples,) = struct.unpack_from("<Q", data, 32)
    (n_records,) = struct.unpack_from("<I", data, 40)
    return CaptureDownload(
        path=output, size_bytes=len(data), n_records=n_records, capture_samples=samples,
        sample_rate_hz=sample_rate, board_id=board_id, firmware_version=fw,
        overflowed=bool(flags & 1), crc32=status.image_crc, blocks=status.block_count,
        blocks_rerequested=rerequested, reconnects=link.reconnects, capture_s=capture_s,
        download_s=download_s)


def _wait_ready(link: BoardLink, expected_s: float, progress: Progress | None,
                poll_interval_s: float) -> BoardStatus:
    """Poll STATUS until the capture is ready (or failed, or clearly overdue)."""
    deadline = time.monotonic() + expected_s * 1.5 + 10.0
    while True:
        st = link.status()
        if st.state == STATE_READY:
            if progress:
                progress("capture", st.samples_target, st.samples_target)
            return st
        if st.state == STATE_IDLE:
            why = "the board could not start sampling (hardware error)" if st.hw_error else \
                "the capture was aborted on the board"
            raise DeviceError(why)
        if progress and st.samples_target:
            progress("capture", st.samples_done, st.samples_target)
        if time.monotonic() > deadline:
            raise DeviceError(f"capture not ready after {expected_s * 1.5 + 10:.0f} s "
                              f"(board {st.state_name}, {st.samples_done}/{st.samples_target} "
                              "samples)")
        time.sleep(poll_interval_s)


class ProgressBar:
    """A one-line text progress bar on a stream (stderr by default)."""

    def __init__(self, stream: Any = None, width: int = 30):
        import sys

        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self._phase = ""
        self._last = (-1.0, "")
        self._t0 = time.monotonic()
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, phase: str, done: int, total: int) -> None:
        """Draw the bar (a new line per phase)."""
        if phase != self._phase:
            if self._phase:
                self.stream.write("\n")
            self._phase = phase
            self._t0 = time.monotonic()
        frac = done / total if total else 1.0
        now = time.monotonic()
        step = 0.01 if self._tty else 0.25
        if frac < 1.0 and (frac - self._last[0] < step and self._last[1] == phase):
            return
        self._last = (frac, phase)
        filled = int(self.width * frac)
        unit = "samples" if phase == "capture" else "bytes"
        line = (f"{phase:8s} [{'#' * filled}{'.' * (self.width - filled)}] {frac * 100:5.1f}% "
                f"{done}/{total} {unit} {now - self._t0:5.1f} s")
        self.stream.write(("\r" if self._tty else "") + line + ("" if self._tty else "\n"))
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self._phase and self._tty:
            self.stream.write("\n")
            self.stream.flush()
