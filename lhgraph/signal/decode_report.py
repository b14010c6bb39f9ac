"""What the decoder kept, dropped and why: per-station timing and the decode report."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class StationTiming:
    """What the sync train says about one station (times in seconds of the capture)."""

    index: int
    flashes: int
    period_s: float
    offset_s: float
    residual_rms_s: float
    ootx_frames: int = 0
    ootx_bad_crc: int = 0
    ootx_bad_stuffing: int = 0


@dataclass
class DecodeReport:
    """What the decoder kept, dropped and why."""

    pulses: int = 0
    merged_gaps: int = 0
    sync_flashes: int = 0
    sweep_hits: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    stations: list[StationTiming] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def drop(self, reason: str, count: int) -> None:
        """Count ``count`` items dropped for ``reason`` (zero counts are not recorded)."""
        if count:
            self.dropped[reason] = self.dropped.get(reason, 0) + int(count)

    def lines(self) -> list[str]:
        """Human-readable summary."""
        out = [f"{self.pulses} pulses ({self.merged_gaps} carrier gaps merged), "
               f"{self.sync_flashes} sync flashes, {self.sweep_hits} sweep hits"]
        for s in self.stations:
            out.append(f"station {s.index}: {s.flashes} flashes, period {s.period_s * 1e3:.6f} ms,"
                       f" sync residual {s.residual_rms_s * 1e6:.2f} us rms, OOTX "
                       f"{s.ootx_frames} frames ok, {s.ootx_bad_crc} bad CRC, "
                       f"{s.ootx_bad_stuffing} bad stuffing")
        out += [f"dropped {n}: {reason}" for reason, n in self.dropped.items()]
        return out + self.notes
