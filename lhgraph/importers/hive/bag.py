"""Reading a hive ROS1 recording (Borges et al., IROS 2018): :func:`read_hive_bag`.

A hive bag holds a Vive Tracker waved in front of LH1 stations: per-sweep angles
(``/loc/vive/light``), the stations' factory calibration (``/loc/vive/lighthouses``), the
tracker's photodiode geometry and IMU calibration (``/loc/vive/trackers``), the tracker IMU
(``/loc/vive/imu``) and OptiTrack poses of the tracker body (``/vrpn_client_node/*/pose``).
The message types are hive's own; their definitions travel in the bag's connection records
and are registered from there. Hits beyond ``MAX_ABS_ANGLE_RAD`` and sweeps off their
station's timing grid are dropped here; angles stay in hive's convention
(:mod:`lhgraph.importers.hive.conventions` maps them to ours).

Time base: seconds since ``t0``, the earliest header stamp of the light, IMU and OptiTrack
messages (all three are stamped on the recording host's clock).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.importers.hive.salvage import salvage_bag
from lhgraph.model.board import Board, make_board
from lhgraph.model.station import FactoryCalibration

Array = NDArray[np.float64]

TOPIC_LIGHT = "/loc/vive/light"
TOPIC_LIGHTHOUSES = "/loc/vive/lighthouses"
TOPIC_TRACKERS = "/loc/vive/trackers"
TOPIC_IMU = "/loc/vive/imu"
MOCAP_SUFFIX = "/pose"
MOCAP_PREFIX = "/vrpn_client_node/"

# Hive passes through decoder garbage: -pi/2 saturations, ~1.43 rad from sync pulses taken for
# sweeps (50-57 us long) and values far beyond pi. LH1 lasers are seen only within about
# -64..+56 deg, so anything beyond this bound is not a sweep hit.
MAX_ABS_ANGLE_RAD = 1.2

# A sweep of one station and axis that starts less than this fraction of the sweep period
# after the previous one is off the station's timing grid: on data8.11.bag station 0 has ~50
# such sweeps, with angles 0.16-0.65 rad off their neighbours (most likely station 1's
# sweeps labelled as station 0's: station 1 misses sweeps at those moments), station 1 four.
MIN_SWEEP_GAP_PERIODS = 0.75


@dataclass(frozen=True)
class HiveBag:
    """Everything lhgraph uses from a hive bag, on the ``t0`` time base (s).

    ``light`` columns (one entry per kept hit): ``time`` (header stamp of the sweep message),
    ``station`` (index into ``serials``), ``hive_axis``, ``sensor``, ``angle`` (rad, hive's
    convention), ``length_us`` (pulse length) and ``sweep`` (sweep message number).
    ``n_dropped`` hits were beyond ``MAX_ABS_ANGLE_RAD``; ``off_grid_sweeps`` (per station)
    sweeps with ``n_off_grid_hits`` hits were off their station's timing grid
    (:func:`off_grid_sweeps`); neither is in ``light``. ``notes``: what a damaged bag lost.
    ``hive_calibrations`` are keyed by station index with the OOTX terms in *hive's* axis order
    ``[horizontal, vertical]``.
    """

    t0: float
    serials: list[str]
    light: dict[str, NDArray]
    n_dropped: int
    off_grid_sweeps: dict[int, int]
    n_off_grid_hits: int
    board: Board
    hive_calibrations: dict[int, FactoryCalibration]
    imu_time: Array
    imu_accel: Array
    imu_gyro: Array
    mocap_topic: str
    mocap_time: Array
    mocap_position: Array
    mocap_quat_wxyz: Array
    notes: tuple[str, ...] = ()


def _stamp(header: object) -> float:
    return header.stamp.sec + 1e-9 * header.stamp.nanosec  # type: ignore[attr-defined]


def _station_order(serials: set[str]) -> list[str]:
    """Stable station numbering: serials sorted numerically when they are all digits."""
    if all(s.isdigit() for s in serials):
        return sorted(serials, key=int)
    return sorted(serials)


@dataclass
class _Collected:
    """What the messages of a hive bag give, as they are read."""

    light_rows: list[tuple[float, str, int, int, float, float, int]] = field(
        default_factory=list)
    lighthouses: dict[str, tuple[object, object]] = field(default_factory=dict)
    tracker: object = None
    imu: list[tuple[float, ...]] = field(default_factory=list)
    mocap: list[tuple[float, ...]] = field(default_factory=list)
    sweep: int = 0

    def add(self, topic: str, msg: object, mocap_topic: str) -> None:
        """Take one message of ``topic``."""
        if topic == TOPIC_LIGHT:
            t = _stamp(msg.header)
            for s in msg.samples:
                self.light_rows.append((t, msg.lighthouse, int(msg.axis), int(s.sensor),
                                        float(s.angle), float(s.length), self.sweep))
            self.sweep += 1
        elif topic == TOPIC_IMU:
            a, g = msg.linear_acceleration, msg.angular_velocity
            self.imu.append((_stamp(msg.header), a.x, a.y, a.z, g.x, g.y, g.z))
        elif topic == mocap_topic:
            p, q = msg.pose.position, msg.pose.orientation
            self.mocap.append((_stamp(msg.header), p.x, p.y, p.z, q.w, q.x, q.y, q.z))
        elif topic == TOPIC_LIGHTHOUSES:
            for lh in msg.lighthouses:
                self.lighthouses[lh.serial] = (lh.horizontal, lh.vertical)
        elif topic == TOPIC_TRACKERS and msg.trackers:
            self.tracker = msg.trackers[0]


def _mocap_topic(topics: set[str], path: Path) -> str:
    """The bag's motion-capture topic; InputError when a hive topic is missing."""
    mocap_topics = sorted(t for t in topics
                          if t.startswith(MOCAP_PREFIX) and t.endswith(MOCAP_SUFFIX))
    needed = [TOPIC_LIGHT, TOPIC_LIGHTHOUSES, TOPIC_TRACKERS, TOPIC_IMU]
    missing = [t for t in needed if t not in topics] + ([] if mocap_topics else
                                                        [MOCAP_PREFIX + "*/pose"])
    if missing:
        raise InputError(f"not a hive recording: missing topic(s) {', '.join(missing)}", path)
    return mocap_topics[0]


def read_hive_bag(bag_path: str | Path) -> HiveBag:
    """Read a hive bag; bad files raise InputError naming the file. A bag cut short (no
    index) keeps its whole messages before the cut (:mod:`lhgraph.importers.hive.salvage`)
    and says so in :attr:`HiveBag.notes`."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag1 import ReaderError
    from rosbags.typesys import Stores, get_typestore

    path = Path(bag_path)
    if not path.exists():
        raise InputError("file not found", path)
    if path.is_dir():
        raise InputError("is a directory, expected a ROS1 .bag file", path)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    got = _Collected()
    notes: tuple[str, ...] = ()
    try:
        # AnyReader registers the bag's own message definitions (hive/msg/*) in a copy of
        # the typestore, so no hive package is needed.
        with AnyReader([path], default_typestore=typestore) as reader:
            mocap_topic = _mocap_topic({c.topic for c in reader.connections}, path)
            wanted = [c for c in reader.connections if c.topic in (
                TOPIC_LIGHT, TOPIC_LIGHTHOUSES, TOPIC_TRACKERS, TOPIC_IMU, mocap_topic)]
            for conn, _t, raw in reader.messages(connections=wanted):
                got.add(conn.topic, reader.deserialize(raw, conn.msgtype), mocap_topic)
    except (AnyReaderError, ReaderError) as exc:
        salvage = salvage_bag(path, typestore)
        if not salvage.messages:
            raise InputError(f"not a readable ROS1 bag ({exc})", path) from None
        mocap_topic = _mocap_topic({topic for topic, _ in salvage.messages}, path)
        for topic, msg in salvage.messages:
            got.add(topic, msg, mocap_topic)
        notes = (f"cut short (no index): kept the {len(salvage.messages)} messages of its "
                 f"first {salvage.kept_bytes} bytes, dropped the last "
                 f"{salvage.size - salvage.kept_bytes} of {salvage.size} bytes",)
    except (UnicodeDecodeError, AssertionError, ValueError, KeyError, IndexError) as exc:
        # what rosbags raises on bytes it does not expect inside a bag's records
        raise InputError(f"not a readable ROS1 bag (corrupted: {type(exc).__name__})",
                         path) from None
    if not got.light_rows or not got.imu or not got.mocap or got.tracker is None:
        raise InputError("hive recording without light, IMU, mocap or tracker messages", path)
    bag = _assemble(path, got.light_rows, got.lighthouses, got.tracker, got.imu, got.mocap,
                    mocap_topic)
    return dataclasses.replace(bag, notes=notes)


def off_grid_sweeps(time: Array, station: NDArray, axis: NDArray, sweep: NDArray,
                    min_gap_periods: float = MIN_SWEEP_GAP_PERIODS) -> NDArray[np.bool_]:
    """Hits of sweeps off their (station, axis) timing grid.

    Per station and axis, with ``P`` the median spacing of the sweeps' times (s): a sweep
    starting less than ``min_gap_periods * P`` after the previous kept one conflicts with
    it, and of the two the one farther from the grid (one ``P`` after the kept sweep before
    them) is dropped.
    """
    off = np.zeros(len(time), dtype=bool)
    for st in np.unique(station):
        for ax in np.unique(axis):
            rows = np.flatnonzero((station == st) & (axis == ax))
            ids, first = np.unique(sweep[rows], return_index=True)
            if len(ids) < 3:
                continue
            t = time[rows][first]
            order = np.argsort(t, kind="stable")
            ids, t = ids[order], t[order]
            period = float(np.median(np.diff(t)))
            kept = [0]
            for j in range(1, len(t)):
                if t[j] - t[kept[-1]] >= min_gap_periods * period:
                    kept.append(j)
                elif len(kept) > 1:
                    expected = t[kept[-2]] + period
                    if abs(t[j] - expected) < abs(t[kept[-1]] - expected):
                        kept[-1] = j
            dropped = np.setdiff1d(ids, ids[kept])
            off[rows[np.isin(sweep[rows], dropped)]] = True
    return off


def _assemble(path: Path, light_rows: list, lighthouses: dict, tracker: object, imu: list,
              mocap: list, mocap_topic: str) -> HiveBag:
    serials = _station_order({r[1] for r in light_rows})
    unknown = [s for s in serials if s not in lighthouses]
    if unknown:
        raise InputError(f"no factory calibration for station(s) {unknown}", path)
    t = np.array([r[0] for r in light_rows])
    station = np.array([serials.index(r[1]) for r in light_rows], dtype=np.int64)
    cols = {
        "time": t,
        "station": station,
        "hive_axis": np.array([r[2] for r in light_rows], dtype=np.int64),
        "sensor": np.array([r[3] for r in light_rows], dtype=np.int64),
        "angle": np.array([r[4] for r in light_rows]),
        "length_us": np.array([r[5] for r in light_rows]),
        "sweep": np.array([r[6] for r in light_rows], dtype=np.int64),
    }
    keep = np.abs(cols["angle"]) < MAX_ABS_ANGLE_RAD
    cols = {k: v[keep] for k, v in cols.items()}
    off_grid = off_grid_sweeps(cols["time"], cols["station"], cols["hive_axis"], cols["sweep"])
    n_off_grid = {int(st): int(len(np.unique(cols["sweep"][off_grid & (cols["station"] == st)])))
                  for st in np.unique(cols["station"])}
    cols = {k: v[~off_grid] for k, v in cols.items()}
    imu_a = np.array(imu)
    mocap_a = np.array(mocap)
    t0 = float(min(t.min(), imu_a[:, 0].min(), mocap_a[:, 0].min()))
    cols["time"] = cols["time"] - t0
    ext = tracker.extrinsics  # type: ignore[attr-defined]
    board = make_board(
        [[e.position.x, e.position.y, e.position.z] for e in ext],
        [[e.normal.x, e.normal.y, e.normal.z] for e in ext],
        [int(e.id) for e in ext],
        name=f"vive-tracker-{tracker.serial}",  # type: ignore[attr-defined]
    )
    hive_cal = {}
    for i, serial in enumerate(serials):
        motors = lighthouses[serial]
        hive_cal[i] = FactoryCalibration(
            **{key: [float(getattr(m, key)) for m in motors]
               for key in ("phase", "tilt", "curve", "gibphase", "gibmag")})
    imu_order = np.argsort(imu_a[:, 0], kind="stable")
    imu_a = imu_a[imu_order]
    mocap_a = _dedupe_mocap(mocap_a)
    return HiveBag(
        t0=t0, serials=serials, light=cols, n_dropped=int(np.sum(~keep)),
        off_grid_sweeps=n_off_grid, n_off_grid_hits=int(np.sum(off_grid)), board=board,
        hive_calibrations=hive_cal,
        imu_time=imu_a[:, 0] - t0, imu_accel=imu_a[:, 1:4], imu_gyro=imu_a[:, 4:7],
        mocap_topic=mocap_topic, mocap_time=mocap_a[:, 0] - t0,
        mocap_position=mocap_a[:, 1:4], mocap_quat_wxyz=mocap_a[:, 4:8],
    )


def _dedupe_mocap(m: Array) -> Array:
    """Sort by stamp and drop repeated stamps (vrpn sometimes republishes a pose)."""
    m = m[np.argsort(m[:, 0], kind="stable")]
    keep = np.r_[True, np.diff(m[:, 0]) > 0]
    return m[keep]
