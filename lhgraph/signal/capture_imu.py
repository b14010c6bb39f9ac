"""The board IMU's samples in a version-2 ``.lhcap`` (docs/formats/lhcap.md, "Version 2"):
:class:`CaptureImu`, raw counts stamped with board-clock sample indices, and their record
layout."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream

IMU_RECORD = np.dtype([("sample_index", "<u4"), ("raw", "<i2", (6,))])
"""One IMU record: u32 sample index, i16 ax ay az gx gy gz (16 bytes)."""
assert IMU_RECORD.itemsize == 16
IMU_PARTS = {1: "ICM-42688-P"}
"""IMU part codes of a version-2 header (0 = no IMU answered)."""


@dataclass
class CaptureImu:
    """The board IMU's samples in a capture: ``sample_index`` (M,) strictly increasing, the
    board-clock sample at which each data-ready arrived; ``raw`` (M, 6) int16 counts
    ``ax ay az gx gy gz`` in the IMU's axes; ``part`` (:data:`IMU_PARTS`), output data rate,
    full scales (32768 counts = ``gyro_full_scale_dps`` deg/s, ``accel_full_scale_g`` g) and
    the samples the board could not record (``missed``)."""

    sample_index: NDArray[np.int64]
    raw: NDArray[np.int16]
    part: int = 1
    odr_hz: int = 1000
    gyro_full_scale_dps: int = 2000
    accel_full_scale_g: int = 16
    missed: int = 0

    def __post_init__(self) -> None:
        self.sample_index = np.asarray(self.sample_index, dtype=np.int64).reshape(-1)
        self.raw = np.asarray(self.raw, dtype=np.int16).reshape(-1, 6)

    def __len__(self) -> int:
        return len(self.sample_index)

    @property
    def part_name(self) -> str:
        """The part's name (``"none"`` for code 0)."""
        return IMU_PARTS.get(self.part, "none" if self.part == 0 else f"part {self.part}")

    def stream(self, sample_rate_hz: float) -> ImuStream:
        """The samples in ``imu.csv``'s units: time s (sample index / rate, the angles'
        clock), specific force m/s^2, angular rate rad/s, in the IMU's axes."""
        accel_lsb = self.accel_full_scale_g * STANDARD_GRAVITY_MPS2 / 32768.0
        gyro_lsb = np.radians(self.gyro_full_scale_dps) / 32768.0
        raw = self.raw.astype(float)
        return ImuStream(self.sample_index / float(sample_rate_hz), raw[:, :3] * accel_lsb,
                         raw[:, 3:] * gyro_lsb)

    @classmethod
    def from_stream(cls, stream: ImuStream, sample_rate_hz: float, **fields: int
                    ) -> CaptureImu:
        """Quantise a stream (s, m/s^2, rad/s) into counts stamped on a ``sample_rate_hz``
        clock, as the board would record it (saturating at the full scales; samples before
        0 s left out). ``fields`` are the other :class:`CaptureImu` fields."""
        imu = cls(np.zeros(0, np.int64), np.zeros((0, 6), np.int16), **fields)
        index = np.ceil(np.asarray(stream.time) * sample_rate_hz - 1e-9).astype(np.int64)
        gyro = (stream.gyro_rad_s if stream.gyro_rad_s is not None
                else np.zeros_like(stream.accel_mps2))
        counts = np.concatenate([
            stream.accel_mps2 / (imu.accel_full_scale_g * STANDARD_GRAVITY_MPS2),
            gyro / np.radians(imu.gyro_full_scale_dps)], axis=1) * 32768.0
        keep = index >= 0
        imu.sample_index = index[keep]
        imu.raw = np.clip(np.round(counts[keep]), -32768, 32767).astype(np.int16)
        return imu


def read_imu_records(data: bytes, offset: int, count: int, length: int,
                      warnings: list[str]) -> CaptureImu:
    """The longest valid prefix of ``count`` IMU records at ``offset`` (indices strictly
    increasing and inside the capture); what breaks the rules is reported and dropped."""
    rec = (np.frombuffer(data, dtype=IMU_RECORD, count=count, offset=offset) if count
           else np.zeros(0, IMU_RECORD))
    index = rec["sample_index"].astype(np.int64)
    bad = np.flatnonzero(np.r_[False, np.diff(index) <= 0] | (index >= length))
    valid = int(bad[0]) if len(bad) else count
    if valid < count:
        warnings.append(f"IMU record {valid} breaks the ordering rules (index not increasing "
                        f"or past the capture); dropped it and the {count - valid - 1} after it")
    return CaptureImu(index[:valid], rec["raw"][:valid].astype(np.int16))
