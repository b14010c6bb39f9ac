"""The download procedure: arm a capture, wait for it, download it, write the ``.lhcap``.

The wire protocol is described in ``docs/protocol.md``; the file format in
``docs/formats/lhcap.md``. Typical use from a notebook::

    from lhgraph.device.download import download_capture
    result = download_capture("/dev/ttyUSB0", "run1.lhcap", duration_s=8.0)

The download is robust to a lossy or flaky link (``lhgraph.device.link``): every frame
carries a CRC-32, bad or missing blocks are requested again, a vanished port is re-opened
and the transfer resumes where it stopped; the whole file is checked against the CRC-32 the
board reports before it is written (atomically, ``lhgraph.io.files.write_atomic``: never a
half file under the final name).
"""

from __future__ import annotations

import os
import struct
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

from lhgraph.device.link import DEFAULT_BAUDRATE, BoardLink, PortOpener
from lhgraph.device.progress import Progress
from lhgraph.device.protocol import (
    E_UNREAD,
    PROTOCOL_VERSION,
    STATE_ARMED,
    STATE_CAPTURING,
    STATE_IDLE,
    STATE_READY,
    BoardRefused,
    BoardStatus,
)
from lhgraph.errors import DeviceError, InputError
from lhgraph.io.files import check_writable, write_atomic
from lhgraph.signal.capture import HEADER_LEN, VERSION_IMU, file_layout, imu_header


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
    board_problems: tuple[str, ...] = ()
    n_imu_records: int = 0
    imu_missed: int = 0
    imu_part: int | None = None
    """The IMU part of a version-2 capture (0: none answered at boot); None: version 1."""

    @property
    def duration_s(self) -> float:
        """Length of the capture in seconds."""
        return self.capture_samples / self.sample_rate_hz if self.sample_rate_hz else 0.0

    def summary(self) -> str:
        """One line for humans."""
        rate = self.size_bytes / self.download_s / 1e3 if self.download_s > 0 else float("inf")
        extra = "; OVERFLOWED (capture stopped early)" if self.overflowed else ""
        if self.imu_missed:
            extra += f"; {self.imu_missed} IMU samples missed"
        if self.imu_part == 0:
            extra += "; no IMU answered on the board (light only)"
        imu = f", {self.n_imu_records} IMU samples" if self.n_imu_records else ""
        if self.board_problems:
            extra += "; BOARD: " + "; ".join(self.board_problems)
        return (f"wrote {self.path}: {self.n_records} edge records{imu}, {self.duration_s:.3f} s, "
                f"{self.size_bytes} bytes in {self.download_s:.2f} s ({rate:.0f} kB/s), "
                f"{self.blocks_rerequested} blocks re-requested, "
                f"{self.reconnects} reconnects{extra}")


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
    layout = file_layout(data)
    if layout is None:
        return "not a version-1 or version-2 .lhcap header"
    if len(data) != layout[3]:
        return "record counts disagree with the size"
    return None


def _validate_ready(status: BoardStatus) -> None:
    size, bsize = status.image_size, status.block_size
    if size < HEADER_LEN + 4 or size % 4 != 0:  # version 1: 112 + 8 N, 2: 132 + 8 N + 16 M
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
                     poll_interval_s: float = 0.05,
                     discard_previous: bool = False) -> CaptureDownload:
    """Arm the board on ``port``, wait for the capture, download it to ``output_path``.

    ``duration_s`` and ``start_delay_s`` go to the board's ARM command; ``arm=False``
    downloads the capture the board already holds (state ``ready``). The board refuses to
    record over a capture that was not downloaded; ``discard_previous`` drops it (without it
    such a refusal is a DeviceError saying what to do). ``progress`` is called
    as ``progress(phase, done, total)`` (see :data:`Progress`). A lost port is re-opened up
    to ``reopen_attempts`` times per loss (backing off to 1 s), for at most
    ``max_reconnects`` losses. Raises
    :class:`~lhgraph.errors.InputError` for bad arguments or an existing output (unless
    ``overwrite``) and :class:`~lhgraph.errors.DeviceError` for link or board failures.
    """
    output = Path(output_path)
    if not output.parent.is_dir():  # a capture goes into an existing directory
        raise InputError("directory does not exist", output.parent)
    check_writable(output, overwrite)
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
            _arm(link, port, duration_ms, delay_ms, discard_previous)
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
    write_atomic(output, data, overwrite)
    flags, board_id, fw = struct.unpack_from("<III", data, 12)
    (sample_rate,) = struct.unpack_from("<I", data, 8)
    (samples,) = struct.unpack_from("<Q", data, 32)
    version, n_records, n_imu, _ = file_layout(data) or (0, 0, 0, 0)
    _, imu_missed, imu_part, *_ = imu_header(data)
    return CaptureDownload(
        path=output, size_bytes=len(data), n_records=n_records, n_imu_records=n_imu,
        imu_missed=imu_missed, imu_part=imu_part if version == VERSION_IMU else None,
        capture_samples=samples,
        sample_rate_hz=sample_rate, board_id=board_id, firmware_version=fw,
        overflowed=bool(flags & 1), crc32=status.image_crc, blocks=status.block_count,
        blocks_rerequested=rerequested, reconnects=link.reconnects, capture_s=capture_s,
        download_s=download_s, board_problems=status.problems())


def _arm(link: BoardLink, port: str, duration_ms: int, delay_ms: int,
         discard_previous: bool) -> None:
    """ARM; a refusal to drop an undownloaded capture becomes a DeviceError that says how."""
    try:
        link.arm(duration_ms, delay_ms, discard_previous=discard_previous)
    except BoardRefused as exc:
        if exc.code != E_UNREAD:
            raise
        st = link.status()
        raise DeviceError(
            f"the board on {port} holds a capture that was not downloaded "
            f"({st.blocks_unread} of {st.block_count} blocks never read): download it with "
            f"`lhgraph capture --no-arm --port {port} --output FILE`, or record over it with "
            "--discard-previous") from None


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
