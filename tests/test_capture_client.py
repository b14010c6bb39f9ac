"""End-to-end tests of ``lhgraph capture`` against the firmware core on a pseudo-terminal.

``virtual_board`` (firmware/host) runs the board's protocol core on a pty and serves a
synthetic capture; the client must download it byte for byte, also through dropped bytes,
flipped bits and a disconnect. Built with cmake into ``build/firmware-host`` (reused).
"""

from __future__ import annotations

import os
import random
import select
import shutil
import struct
import subprocess
import sys
import time
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from lhgraph.device.download import CaptureDownload, download_capture
from lhgraph.device.link import BoardLink
from lhgraph.device.progress import ProgressBar
from lhgraph.device.protocol import (
    CMD_INFO,
    CMD_READ,
    RESP_FLAG,
    STATE_READY,
    BoardStatus,
    cobs_decode,
    cobs_encode,
    decode_frame,
    encode_frame,
)
from lhgraph.errors import DeviceError, InputError

REPO = Path(__file__).resolve().parents[1]
BUILD = REPO / "build" / "firmware-host"


# --- helpers -----------------------------------------------------------------------------------


def write_lhcap(path: Path, n_records: int = 3000, seed: int = 1, flags: int = 0) -> bytes:
    """Write a valid synthetic .lhcap (docs/formats/lhcap.md) and return its bytes."""
    rnd = random.Random(seed)
    records = []
    index, word = 0, rnd.getrandbits(32)
    for _ in range(n_records):
        records.append((index, word))
        index += rnd.randint(1, 60)
        word ^= 1 << rnd.randrange(32)  # always a change
    samples = records[-1][0] + 1 + rnd.randint(0, 100)
    header = b"LHCP" + struct.pack("<HHIIIIQQI", 1, 108, 2_000_000, flags, 0xB0A4D, 0x000100,
                                   1_700_000_000_000_000, samples, n_records)
    header += struct.pack("<32h", *range(30), -1, -1)
    body = header + b"".join(struct.pack("<II", i, w) for i, w in records)
    data = body + struct.pack("<I", zlib.crc32(body))
    path.write_bytes(data)
    return data


@pytest.fixture(scope="module")
def virtual_board() -> Path:
    """Path of the built ``virtual_board`` (built once; skips without cmake or a C compiler)."""
    cc = os.environ.get("CC", "cc")
    if shutil.which("cmake") is None or shutil.which(cc) is None:
        pytest.skip("cmake or a C compiler is missing: cannot build firmware/ virtual_board")
    if not (BUILD / "CMakeCache.txt").exists():
        subprocess.run(["cmake", "-S", str(REPO / "firmware"), "-B", str(BUILD)], check=True,
                       stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "--build", str(BUILD), "--target", "virtual_board", "-j2"],
                   check=True, stdout=subprocess.DEVNULL)
    exe = BUILD / "virtual_board"
    assert exe.exists()
    return exe


@pytest.fixture()
def capture(tmp_path: Path) -> tuple[Path, bytes]:
    """A small synthetic capture: 3000 records, 24 kB (6 blocks of 4 KiB)."""
    path = tmp_path / "source.lhcap"
    return path, write_lhcap(path)


@contextmanager
def board(exe: Path, capture_path: Path, *args: str) -> Iterator[str]:
    """Run virtual_board; yields the port path it prints first."""
    proc = subprocess.Popen([str(exe), "--capture", str(capture_path), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], 10.0)
        assert ready, "virtual_board printed no port"
        port = proc.stdout.readline().decode().strip()
        assert port, (proc.stderr.read().decode() if proc.stderr else "") or "no port"
        yield port
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def fetch(port: str, out: Path, **kw: object) -> CaptureDownload:
    """Download with test-friendly settings (short capture)."""
    kw.setdefault("duration_s", 0.2)
    return download_capture(port, out, **kw)  # type: ignore[arg-type]


# --- framing (no board needed) -------------------------------------------------------------------


def test_cobs_known_vectors_and_roundtrip() -> None:
    assert cobs_encode(b"") == b"\x01"
    assert cobs_encode(b"\x00") == b"\x01\x01"
    assert cobs_encode(b"\x11\x00\x22") == b"\x02\x11\x02\x22"
    assert cobs_encode(b"\x01" * 254) == b"\xff" + b"\x01" * 254 + b"\x01"
    rnd = random.Random(5)
    for n in (0, 1, 253, 254, 255, 508, 1000, 4100):
        data = bytes(rnd.choice((0, rnd.randrange(256))) for _ in range(n))
        enc = cobs_encode(data)
        assert 0 not in enc
        assert cobs_decode(enc) == data
    for bad in (b"", b"\x05\x11", b"\x02\x00"):
        with pytest.raises(ValueError):
            cobs_decode(bad)


def test_frame_layout_and_crc() -> None:
    wire = encode_frame(0x04, 9, struct.pack("<I", 3))
    assert wire.endswith(b"\x00") and 0 not in wire[:-1]
    raw = cobs_decode(wire[:-1])
    assert raw[:4] == bytes([0x04, 9, 4, 0])
    assert struct.unpack("<I", raw[-4:])[0] == zlib.crc32(raw[:-4])
    frame = decode_frame(wire[:-1])
    assert (frame.kind, frame.seq, frame.payload) == (4, 9, struct.pack("<I", 3))
    for i in range(len(raw) * 8):  # every single-bit error is detected
        damaged = bytearray(raw)
        damaged[i // 8] ^= 1 << (i % 8)
        with pytest.raises(ValueError):
            decode_frame(cobs_encode(bytes(damaged)))
    assert CMD_READ | RESP_FLAG == 0x84


def test_status_parse_rejects_wrong_size() -> None:
    with pytest.raises(DeviceError):
        BoardStatus.parse(b"\x00" * 39)


def test_status_parse_first_firmware_and_health_fields() -> None:
    v1 = struct.pack("<BBHIIIIIIIII", 3, 0, 0, 200, 0, 10, 10, 5, 160, 0xABC, 4096, 1)
    st = BoardStatus.parse(v1)
    assert st.state_name == "ready" and not st.health_reported and st.problems() == ()
    health = struct.pack("<13I", 0x010 | 0x020, 7999, 0x08001234, 0xFFFFFFF9, 0x400, 0x40000000,
                         2, 51_000, 184_320, 1, 0, 1, 0x24)
    st = BoardStatus.parse(v1 + health + b"future")  # later firmware may append more
    assert (st.imu_part, st.imu_records, st.imu_missed) == (0, 0, 0)
    assert BoardStatus.parse(v1 + health + struct.pack("<3I", 1, 900, 2)).imu_records == 900
    assert st.health_reported and st.hse_khz == 7999 and st.fault_pc == 0x08001234
    assert st.isr_cycles_max == 51_000 and st.isr_cycles_budget == 184_320
    assert st.blocks_unread == 1 and st.frames_timed_out == 1
    assert st.problems() == ("SDRAM retention test failed", "the board reset after a fault",
                             "2 sample half-buffers lost since boot")
    with pytest.raises(DeviceError, match="at least 92"):
        BoardStatus.parse(v1 + health[:-4])


# --- end to end ----------------------------------------------------------------------------------


def _record_without_download(port: str) -> BoardStatus:
    """ARM a short capture and wait until it is ready, reading none of it."""
    with BoardLink(port) as link:
        link.arm(200)
        deadline = time.monotonic() + 20
        while (st := link.status()).state != STATE_READY:
            assert time.monotonic() < deadline, st
            time.sleep(0.02)
        return st


def test_arm_keeps_a_capture_not_downloaded(virtual_board: Path, capture: tuple[Path, bytes],
                                            tmp_path: Path) -> None:
    src, data = capture
    out = tmp_path / "next.lhcap"
    with board(virtual_board, src) as port:
        st = _record_without_download(port)
        assert st.health_reported and st.blocks_unread == st.block_count == 6
        assert st.self_test == 0x100 and st.problems() == ()  # virtual board: no self-test
        with pytest.raises(DeviceError, match="not downloaded.*--discard-previous"):
            fetch(port, out)
        assert not out.exists()
        cli = [sys.executable, "-m", "lhgraph", "capture", "--port", port, "--output", str(out),
               "--duration", "0.2", "--quiet"]
        proc = subprocess.run(cli, capture_output=True, text=True, cwd=REPO, timeout=60)
        assert proc.returncode == 1 and proc.stderr.count("\n") == 1
        assert "--discard-previous" in proc.stderr and "--no-arm" in proc.stderr
        assert "Traceback" not in proc.stderr and not out.exists()
        # the refused capture is still there, and can be downloaded
        fetch(port, out, arm=False)
        assert out.read_bytes() == data
        # downloaded: recording again needs no flag; an unread one is dropped when asked
        _record_without_download(port)
        proc = subprocess.run([*cli, "--force", "--discard-previous"], capture_output=True,
                              text=True, cwd=REPO, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert out.read_bytes() == data


def test_partial_frame_times_out(virtual_board: Path, capture: tuple[Path, bytes]) -> None:
    src, _ = capture
    with board(virtual_board, src) as port:
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, encode_frame(CMD_INFO, 1)[:3])  # half a frame, then silence
        finally:
            os.close(fd)
        time.sleep(0.3)  # > the board's 100 ms frame timeout
        with BoardLink(port) as link:
            st = link.status()
    assert st.frames_timed_out == 1


def test_download_api_byte_identical(virtual_board: Path, capture: tuple[Path, bytes],
                                     tmp_path: Path) -> None:
    src, data = capture
    out = tmp_path / "out.lhcap"
    seen: list[tuple[str, int, int]] = []
    with board(virtual_board, src) as port:
        result = fetch(port, out, progress=lambda *a: seen.append(a))
        assert out.read_bytes() == data
        # the capture stays on the board: download it again without recording
        again = tmp_path / "again.lhcap"
        fetch(port, again, arm=False)
        assert again.read_bytes() == data
    assert result.size_bytes == len(data) and result.n_records == 3000
    assert result.crc32 == zlib.crc32(data[:-4])
    assert result.blocks == 6 and result.reconnects == 0 and not result.overflowed
    assert seen[-1] == ("download", len(data), len(data))
    assert any(phase == "capture" for phase, _, _ in seen)
    assert not list(tmp_path.glob(".*.part"))


def test_version_2_capture_with_imu_records_byte_identical(virtual_board: Path,
                                                           tmp_path: Path) -> None:
    # the board core builds a version-2 image itself (its IMU log, header and CRC) from the
    # replayed samples and IMU records: it must equal the file the Python encoder wrote
    import numpy as np

    from lhgraph.signal.capture import Capture, encode_capture
    from lhgraph.signal.capture_imu import CaptureImu

    rng = np.random.default_rng(3)
    index = np.r_[0, np.sort(rng.choice(np.arange(1, 400_000), 2999, replace=False))]
    words = np.cumsum(rng.integers(1, 2**31, 3000)).astype(np.uint32)
    imu = CaptureImu(np.arange(700, 400_000, 2000), rng.integers(-32768, 32768, (200, 6)),
                     missed=3)
    src = tmp_path / "imu.lhcap"
    data = encode_capture(Capture(index, words, 400_001, imu=imu, board_id=9))
    src.write_bytes(data)
    out = tmp_path / "out.lhcap"
    with board(virtual_board, src) as port:
        result = fetch(port, out)
        with BoardLink(port) as link:
            st = link.status()
    assert out.read_bytes() == data
    assert (st.imu_part, st.imu_records, st.imu_missed) == (1, 200, 3)
    assert result.n_records == 3000 and result.n_imu_records == 200 and result.imu_missed == 3
    assert "3000 edge records, 200 IMU samples" in result.summary()
    assert "3 IMU samples missed" in result.summary() and "no IMU" not in result.summary()
    # a board whose IMU did not answer: a version-2 file without IMU records, said so
    none = tmp_path / "none.lhcap"
    none.write_bytes(encode_capture(Capture(index, words, 400_001,
                                            imu=CaptureImu([], [], part=0, odr_hz=0))))
    with board(virtual_board, none) as port:
        result = fetch(port, tmp_path / "none-out.lhcap")
    assert (tmp_path / "none-out.lhcap").read_bytes() == none.read_bytes()
    assert result.n_imu_records == 0 and result.imu_part == 0
    assert "no IMU answered on the board" in result.summary()


def test_cli_byte_identical(virtual_board: Path, capture: tuple[Path, bytes],
                            tmp_path: Path) -> None:
    src, data = capture
    out = tmp_path / "cli.lhcap"
    with board(virtual_board, src, "--block-size", "1000") as port:
        proc = subprocess.run([sys.executable, "-m", "lhgraph", "capture", "--port", port,
                               "--output", str(out), "--duration", "0.2", "--quiet"],
                              capture_output=True, text=True, cwd=REPO, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr == "" and proc.stdout == ""
        assert out.read_bytes() == data
        # without --quiet: a progress bar on stderr and a summary line on stdout
        proc = subprocess.run([sys.executable, "-m", "lhgraph", "capture", "--port", port,
                               "--output", str(out), "--duration", "0.1", "--force"],
                              capture_output=True, text=True, cwd=REPO, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert "download" in proc.stderr and "100.0%" in proc.stderr
        assert "3000 edge records" in proc.stdout
        assert out.read_bytes() == data


@pytest.mark.parametrize("faults", [
    ("--drop-every", "10007"),
    ("--flip-every", "9001"),
    ("--drop-every", "3001", "--flip-every", "2003", "--block-size", "512"),
    ("--rx-drop-every", "101", "--rx-flip-every", "67", "--block-size", "2048"),
], ids=["dropped-bytes", "flipped-bits", "both-small-blocks", "damaged-requests"])
def test_lossy_link_still_byte_identical(virtual_board: Path, capture: tuple[Path, bytes],
                                         tmp_path: Path, faults: tuple[str, ...]) -> None:
    src, data = capture
    out = tmp_path / "lossy.lhcap"
    with board(virtual_board, src, *faults) as port:
        result = fetch(port, out, timeout_s=0.3)
    assert out.read_bytes() == data
    assert result.blocks_rerequested > 0


def test_disconnect_mid_transfer_resumes(virtual_board: Path, capture: tuple[Path, bytes],
                                         tmp_path: Path) -> None:
    src, data = capture
    out = tmp_path / "resumed.lhcap"
    link = tmp_path / "ttyBOARD"
    with board(virtual_board, src, "--link", str(link), "--block-size", "2048",
               "--disconnect-after-blocks", "4", "--disconnects", "2",
               "--flip-every", "20011") as port:
        assert port == str(link)
        result = fetch(port, out)
    assert out.read_bytes() == data
    assert result.reconnects == 2


def test_refuses_to_overwrite(virtual_board: Path, capture: tuple[Path, bytes],
                              tmp_path: Path) -> None:
    src, data = capture
    out = tmp_path / "exists.lhcap"
    out.write_bytes(b"precious")
    # checked before the port is touched: a missing port does not matter
    with pytest.raises(InputError, match="exists"):
        download_capture("/dev/does-not-exist", out, duration_s=0.2)
    proc = subprocess.run([sys.executable, "-m", "lhgraph", "capture", "--port",
                           "/dev/does-not-exist", "--output", str(out)],
                          capture_output=True, text=True, cwd=REPO, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "--force" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert out.read_bytes() == b"precious"
    with board(virtual_board, src) as port:
        fetch(port, out, overwrite=True)
    assert out.read_bytes() == data


def test_device_failure_exit_1_and_no_partial_file(virtual_board: Path,
                                                   capture: tuple[Path, bytes],
                                                   tmp_path: Path) -> None:
    src, _ = capture
    out = tmp_path / "never.lhcap"
    proc = subprocess.run([sys.executable, "-m", "lhgraph", "capture", "--port",
                           str(tmp_path / "no-such-tty"), "--output", str(out), "--quiet"],
                          capture_output=True, text=True, cwd=REPO, timeout=60)
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    # the board vanishes for good mid-transfer: an error, no file, no temporary left over
    link = tmp_path / "ttyGONE"
    t0 = time.monotonic()
    with board(virtual_board, src, "--link", str(link), "--block-size", "1024",
               "--disconnect-after-blocks", "3", "--reconnect-delay-ms", "60000") as port:
        with pytest.raises(DeviceError, match="lost"):
            fetch(port, out, max_reconnects=3, reopen_attempts=3)
    assert time.monotonic() - t0 < 15
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [src] or not list(tmp_path.glob(".*.part"))


def test_download_reads_back_with_lhgraph_capture(virtual_board: Path, tmp_path: Path) -> None:
    """A file written by lhgraph.signal.capture goes through the board and reads back unchanged."""
    capmod = pytest.importorskip("lhgraph.signal.capture")
    np = pytest.importorskip("numpy")
    rnd = np.random.default_rng(7)
    idx = np.concatenate([[0], np.cumsum(rnd.integers(1, 400, size=1999))])
    words = np.bitwise_xor.accumulate(
        np.left_shift(np.uint32(1), rnd.integers(0, 32, size=2000)).astype(np.uint32))
    capture = capmod.Capture(sample_index=idx, port_word=words,
                             length_samples=int(idx[-1]) + 5, board_id=42,
                             firmware_version=0x000100, start_time_us=123)
    src = capmod.write_capture(capture, tmp_path / "sim.lhcap")
    out = tmp_path / "back.lhcap"
    with board(virtual_board, Path(src)) as port:
        fetch(port, out)
    assert out.read_bytes() == Path(src).read_bytes()
    back, warnings = capmod.read_capture(out)
    assert warnings == []
    assert np.array_equal(back.sample_index, capture.sample_index)
    assert np.array_equal(back.port_word, capture.port_word)
    assert back.length_samples == capture.length_samples and back.board_id == 42


def test_bad_arguments_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError):
        download_capture("/dev/null", tmp_path / "a.lhcap", duration_s=0)
    with pytest.raises(InputError):
        download_capture("/dev/null", tmp_path / "a.lhcap", duration_s=61)
    with pytest.raises(InputError):
        download_capture("/dev/null", tmp_path / "missing-dir" / "a.lhcap")
    with pytest.raises(InputError):
        download_capture("/dev/null", tmp_path)


def test_progress_bar_renders() -> None:
    import io

    stream = io.StringIO()
    bar = ProgressBar(stream, width=10)
    bar("download", 0, 100)
    bar("download", 100, 100)
    bar.close()
    assert "[##########] 100.0%" in stream.getvalue()
