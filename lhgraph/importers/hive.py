"""Importer for the hive ROS1 recordings (Borges et al., IROS 2018) -> lhgraph contract files.

A hive bag holds a Vive Tracker waved in front of LH1 stations: per-sweep angles
(``/loc/vive/light``), the stations' factory calibration (``/loc/vive/lighthouses``), the
tracker's photodiode geometry and IMU calibration (``/loc/vive/trackers``), the tracker IMU
(``/loc/vive/imu``) and OptiTrack poses of the tracker body (``/vrpn_client_node/*/pose``).
The message types are hive's own; their definitions travel in the bag's connection records
and are registered from there. See docs/hive.md for the conventions and their verification.

Time base of every written file: seconds since ``t0``, the earliest header stamp of the
light, IMU and OptiTrack messages (all three are stamped on the recording host's clock).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.init.pnp import PnPResult
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import interpolate_poses, make_pose, se3_exp, so3_log
from lhgraph.io.angles import Angles, save_angles
from lhgraph.io.files import check_writable, write_csv_columns
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board, make_board, save_board
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.model.lh1 import FactoryCalibration, StationModel, predict

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

OUTPUT_FILES = ("angles.csv", "board.toml", "ootx.toml", "imu.csv", "mocap.csv")


@dataclass(frozen=True)
class AxisMapping:
    """How hive's ``(axis, angle)`` becomes ours: ``our_axis[hive_axis]``, ``sign[hive_axis]``.

    Hive's axis 0 is its "horizontal" sweep, axis 1 its "vertical" one.
    """

    our_axis: tuple[int, int] = (0, 1)
    sign: tuple[float, float] = (1.0, 1.0)

    @property
    def label(self) -> str:
        """Short name, e.g. ``az=+h el=+v`` (which hive axis, with which sign, feeds ours)."""
        names = "hv"
        parts = []
        for ours, tag in ((0, "az"), (1, "el")):
            hive = self.our_axis.index(ours)
            parts.append(f"{tag}={'+' if self.sign[hive] > 0 else '-'}{names[hive]}")
        return " ".join(parts)

    def apply(self, hive_axis: NDArray, angle: Array) -> tuple[NDArray[np.int64], Array]:
        """Our ``(axis, angle)`` of hive hits."""
        hive_axis = np.asarray(hive_axis, dtype=np.int64)
        axis = np.asarray(self.our_axis, dtype=np.int64)[hive_axis]
        return axis, np.asarray(self.sign)[hive_axis] * np.asarray(angle, dtype=float)


# Verified on data8.11.bag (docs/hive.md): hive's horizontal angle is our azimuth and its
# vertical angle our elevation, signs unchanged.
HIVE_MAPPING = AxisMapping((0, 1), (1.0, 1.0))

CANDIDATE_MAPPINGS = tuple(
    AxisMapping(axes, (s0, s1))
    for axes in ((0, 1), (1, 0))
    for s0 in (1.0, -1.0)
    for s1 in (1.0, -1.0)
)


@dataclass
class HiveBag:
    """Everything lhgraph uses from a hive bag, on the ``t0`` time base (s).

    ``light`` columns (one entry per kept hit): ``time`` (header stamp of the sweep message),
    ``station`` (index into ``serials``), ``hive_axis``, ``sensor``, ``angle`` (rad, hive's
    convention), ``length_us`` (pulse length) and ``sweep`` (sweep message number).
    ``n_dropped`` hits were beyond ``MAX_ABS_ANGLE_RAD``; ``off_grid_sweeps`` (per station)
    sweeps with ``n_off_grid_hits`` hits were off their station's timing grid
    (:func:`off_grid_sweeps`); neither is in ``light``.
    ``calibrations`` are keyed by station index with the OOTX terms in *hive's* axis order
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


@dataclass
class HiveImport:
    """What :func:`import_hive` wrote and a summary of the recording."""

    paths: dict[str, Path]
    serials: list[str]
    n_hits: int
    n_dropped: int
    n_sensors: int
    duration_s: float
    sweep_rate_hz: dict[tuple[int, int], float] = field(default_factory=dict)
    imu_rate_hz: float = 0.0
    mocap_rate_hz: float = 0.0
    off_grid_sweeps: dict[int, int] = field(default_factory=dict)
    n_off_grid_hits: int = 0

    def summary(self) -> str:
        """Human-readable lines."""
        lines = [
            f"stations: {len(self.serials)} ("
            + ", ".join(f"{i}={s}" for i, s in enumerate(self.serials)) + ")",
            f"sensors: {self.n_sensors}; hits kept {self.n_hits}, dropped {self.n_dropped} "
            f"(angle beyond {np.degrees(MAX_ABS_ANGLE_RAD):.0f} deg)",
            f"dropped {sum(self.off_grid_sweeps.values())} sweeps ({self.n_off_grid_hits} hits) "
            "off their station's timing grid: " + ", ".join(
                f"station {k}: {n}" for k, n in sorted(self.off_grid_sweeps.items())),
            f"duration: {self.duration_s:.2f} s",
            "sweep rate (Hz): " + ", ".join(
                f"lh{lh}/ax{ax} {r:.1f}" for (lh, ax), r in sorted(self.sweep_rate_hz.items())),
            f"imu: {self.imu_rate_hz:.1f} Hz; mocap: {self.mocap_rate_hz:.1f} Hz",
        ]
        lines += [f"wrote {p}" for p in self.paths.values()]
        return "\n".join(lines)


def _stamp(header: object) -> float:
    return header.stamp.sec + 1e-9 * header.stamp.nanosec  # type: ignore[attr-defined]


def _station_order(serials: set[str]) -> list[str]:
    """Stable station numbering: serials sorted numerically when they are all digits."""
    if all(s.isdigit() for s in serials):
        return sorted(serials, key=int)
    return sorted(serials)


def read_hive_bag(bag_path: str | Path) -> HiveBag:
    """Read a hive bag; bad files raise InputError naming the file."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag1 import ReaderError
    from rosbags.typesys import Stores, get_typestore

    path = Path(bag_path)
    if not path.exists():
        raise InputError("file not found", path)
    if path.is_dir():
        raise InputError("is a directory, expected a ROS1 .bag file", path)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    light_rows: list[tuple[float, str, int, int, float, float, int]] = []
    lighthouses: dict[str, tuple[object, object]] = {}
    tracker = None
    imu: list[tuple[float, ...]] = []
    mocap: list[tuple[float, ...]] = []
    mocap_topic = ""
    try:
        # AnyReader registers the bag's own message definitions (hive/msg/*) in a copy of
        # the typestore, so no hive package is needed.
        with AnyReader([path], default_typestore=typestore) as reader:
            topics = {c.topic for c in reader.connections}
            mocap_topics = sorted(t for t in topics
                                  if t.startswith(MOCAP_PREFIX) and t.endswith(MOCAP_SUFFIX))
            needed = [TOPIC_LIGHT, TOPIC_LIGHTHOUSES, TOPIC_TRACKERS, TOPIC_IMU]
            missing = [t for t in needed if t not in topics] + ([] if mocap_topics else
                                                                [MOCAP_PREFIX + "*/pose"])
            if missing:
                raise InputError(f"not a hive recording: missing topic(s) {', '.join(missing)}",
                                 path)
            mocap_topic = mocap_topics[0]
            wanted = [c for c in reader.connections if c.topic in (*needed, mocap_topic)]
            sweep = 0
            for conn, _t, raw in reader.messages(connections=wanted):
                msg = reader.deserialize(raw, conn.msgtype)
                if conn.topic == TOPIC_LIGHT:
                    t = _stamp(msg.header)
                    for s in msg.samples:
                        light_rows.append((t, msg.lighthouse, int(msg.axis), int(s.sensor),
                                           float(s.angle), float(s.length), sweep))
                    sweep += 1
                elif conn.topic == TOPIC_IMU:
                    a, g = msg.linear_acceleration, msg.angular_velocity
                    imu.append((_stamp(msg.header), a.x, a.y, a.z, g.x, g.y, g.z))
                elif conn.topic == mocap_topic:
                    p, q = msg.pose.position, msg.pose.orientation
                    mocap.append((_stamp(msg.header), p.x, p.y, p.z, q.w, q.x, q.y, q.z))
                elif conn.topic == TOPIC_LIGHTHOUSES:
                    for lh in msg.lighthouses:
                        lighthouses[lh.serial] = (lh.horizontal, lh.vertical)
                elif conn.topic == TOPIC_TRACKERS and msg.trackers:
                    tracker = msg.trackers[0]
    except (AnyReaderError, ReaderError) as exc:
        raise InputError(f"not a readable ROS1 bag ({exc})", path) from None
    if not light_rows or not imu or not mocap or tracker is None:
        raise InputError("hive recording without light, IMU, mocap or tracker messages", path)
    return _assemble(path, light_rows, lighthouses, tracker, imu, mocap, mocap_topic)


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


def station_calibrations(bag: HiveBag, mapping: AxisMapping = HIVE_MAPPING
                         ) -> dict[int, StationCalibration]:
    """OOTX terms of each station in *our* axis order (hive's horizontal/vertical motor data
    goes to the axis its sweeps are mapped to). The bag carries no ``accel_dir``; it is
    written as zeros."""
    out = {}
    for index, cal in bag.hive_calibrations.items():
        order = [mapping.our_axis.index(k) for k in (0, 1)]
        values = {key: getattr(cal, key)[order] for key in
                  ("phase", "tilt", "curve", "gibphase", "gibmag")}
        out[index] = StationCalibration(FactoryCalibration(**values),
                                        int(bag.serials[index]) if bag.serials[index].isdigit()
                                        else index)
    return out


def hive_angles(bag: HiveBag, mapping: AxisMapping = HIVE_MAPPING) -> Angles:
    """The bag's sweep hits as an angles table in our convention, sorted by time.

    Extra columns: ``sweep`` (sweep message number) and ``length_us`` (pulse length).
    """
    L = bag.light
    axis, angle = mapping.apply(L["hive_axis"], L["angle"])
    order = np.lexsort((L["sensor"], L["time"]))
    return Angles(L["time"][order], L["station"][order], axis[order], L["sensor"][order],
                  angle[order], {"sweep": L["sweep"][order], "length_us": L["length_us"][order]})


def _rate_hz(t: Array) -> float:
    t = np.unique(t)
    return float((len(t) - 1) / (t[-1] - t[0])) if len(t) > 1 else 0.0


def import_hive(bag_path: str | Path, out_dir: str | Path, overwrite: bool = False
                ) -> HiveImport:
    """Convert a hive bag into ``angles.csv``, ``board.toml``, ``ootx.toml``, ``imu.csv`` and
    ``mocap.csv`` in ``out_dir`` (refuses to replace existing files unless ``overwrite``)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a directory", out)
    paths = {name.split(".")[0]: out / name for name in OUTPUT_FILES}
    bag = read_hive_bag(bag_path)
    for p in paths.values():
        check_writable(p, overwrite)
    angles = hive_angles(bag)
    save_angles(angles, paths["angles"], overwrite)
    save_board(bag.board, paths["board"], overwrite)
    save_calibration(station_calibrations(bag), paths["ootx"], overwrite)
    write_csv_columns(
        paths["imu"],
        {"time": bag.imu_time, **{f"a{k}": bag.imu_accel[:, i] for i, k in enumerate("xyz")},
         **{f"g{k}": bag.imu_gyro[:, i] for i, k in enumerate("xyz")}},
        {"time": "{:.9f}"}, overwrite)
    q = bag.mocap_quat_wxyz
    write_csv_columns(
        paths["mocap"],
        {"time": bag.mocap_time, "x": bag.mocap_position[:, 0], "y": bag.mocap_position[:, 1],
         "z": bag.mocap_position[:, 2], "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
         "qz": q[:, 3]},
        {"time": "{:.9f}"}, overwrite)
    rates = {}
    for lh in range(len(bag.serials)):
        for ax in (0, 1):
            sel = (angles.lighthouse == lh) & (angles.axis == ax)
            rates[(lh, ax)] = _rate_hz(angles.time[sel])
    t_all = np.concatenate([angles.time, bag.imu_time, bag.mocap_time])
    return HiveImport(
        paths=paths, serials=bag.serials, n_hits=len(angles), n_dropped=bag.n_dropped,
        n_sensors=len(bag.board.ids), off_grid_sweeps=bag.off_grid_sweeps,
        n_off_grid_hits=bag.n_off_grid_hits, duration_s=float(t_all.max() - t_all.min()),
        sweep_rate_hz=rates, imu_rate_hz=_rate_hz(bag.imu_time),
        mocap_rate_hz=_rate_hz(bag.mocap_time),
    )


# --- verification of the axis mapping ---------------------------------------------------------


def sweep_pairs(bag: HiveBag, max_gap_s: float = 0.015) -> list[tuple[int, int]]:
    """Sweep numbers ``(h, v)`` of a horizontal sweep followed, within ``max_gap_s``, by a
    vertical sweep of the same station (one measurement of both angles)."""
    L = bag.light
    sweeps, first = np.unique(L["sweep"], return_index=True)
    st, ax, t = L["station"][first], L["hive_axis"][first], L["time"][first]
    nxt = np.arange(1, len(sweeps))
    ok = ((st[:-1] == st[nxt]) & (ax[:-1] == 0) & (ax[nxt] == 1)
          & (t[nxt] - t[:-1] < max_gap_s))
    return [(int(sweeps[i]), int(sweeps[i + 1])) for i in np.flatnonzero(ok)]


@dataclass
class PairFit:
    """Single-station PnP fits of sweep pairs: ``station``, ``time`` (s, first sweep),
    ``T_lh_board`` (M, 4, 4), ``rms_rad`` over all hits of the pair and ``facing`` (fraction
    of the hit sensors whose normal faces the station in the fitted pose)."""

    station: NDArray[np.int64]
    time: Array
    T_lh_board: Array
    rms_rad: Array
    facing: Array


def single_station_pnp(positions: Array, normals: Array, axis: NDArray, angle: Array,
                       model: StationModel | None = None, n_starts: int = 16,
                       iterations: int = 30, seed: int = 0) -> tuple[Array, float, float]:
    """Board pose ``T_lh_board`` from one station's hits (any mix of axes, rad).

    ``positions``/``normals`` (n, 3) are the hit sensors (board frame, repeated per hit).
    Multi-start Levenberg-Marquardt over random orientations (vectorised over the starts),
    the board placed 2 m along the mean bearing; no planarity assumption, so it suits
    curved boards such as the Vive Tracker. Returns the pose with the smallest residual among
    those in front of the station, its rms residual (rad) and the fraction of hit sensors
    facing the station.
    """
    from scipy.spatial.transform import Rotation

    model = model or StationModel()
    axis = np.asarray(axis, dtype=np.int64)
    n = len(angle)
    az = angle[axis == 0].mean() if np.any(axis == 0) else 0.0
    el = angle[axis == 1].mean() if np.any(axis == 1) else 0.0
    d = np.array([1.0, np.tan(az), np.tan(el)])
    d /= np.linalg.norm(d)
    R0 = Rotation.random(n_starts, random_state=seed).as_matrix()
    T = make_pose(R0, 2.0 * d - R0 @ positions.mean(axis=0))
    s_all = np.tile(positions, (n_starts, 1))
    ax_all = np.tile(axis, n_starts)

    def residuals(T: Array, jac: bool = False):
        Tb = np.repeat(T, n, axis=0)
        if not jac:
            return (predict(np.eye(4), Tb, s_all, ax_all, model) - np.tile(angle, n_starts)
                    ).reshape(n_starts, n)
        pred, _, H = predict(np.eye(4), Tb, s_all, ax_all, model, jacobians=True)
        return (pred - np.tile(angle, n_starts)).reshape(n_starts, n), H.reshape(n_starts, n, 6)

    lam = np.full(n_starts, 1e-3)
    r, H = residuals(T, jac=True)
    cost = np.sum(r**2, axis=1)
    for _ in range(iterations):
        JtJ = np.swapaxes(H, 1, 2) @ H
        g = (np.swapaxes(H, 1, 2) @ r[..., None])[..., 0]
        A = JtJ + lam[:, None, None] * (np.eye(6) * np.diagonal(JtJ, axis1=1, axis2=2)[:, None]
                                        + 1e-12 * np.eye(6))
        delta = -np.linalg.solve(A, g[..., None])[..., 0]
        T_new = T @ se3_exp(delta)
        r_new, H_new = residuals(T_new, jac=True)
        cost_new = np.sum(r_new**2, axis=1)
        better = np.isfinite(cost_new) & (cost_new < cost)
        T = np.where(better[:, None, None], T_new, T)
        r = np.where(better[:, None], r_new, r)
        H = np.where(better[:, None, None], H_new, H)
        cost = np.where(better, cost_new, cost)
        lam = np.where(better, lam * 0.3, lam * 10.0)
    cost = np.where(T[:, 0, 3] > 0, cost, np.inf)
    best = int(np.argmin(cost))
    facing = float(facing_fraction(T[best][None], positions, normals)[0])
    return T[best], float(np.sqrt(cost[best] / n)), facing


def facing_fraction(T_lh_board: Array, positions: Array, normals: Array,
                    seen: NDArray[np.bool_] | None = None) -> Array:
    """Fraction of sensors whose normal points toward the station, per pose ``(M, 4, 4)``.

    ``positions``/``normals`` (S, 3) in the board frame; ``seen`` (M, S) restricts each pose
    to the sensors it was fitted on (default: all). A photodiode only sees a station in front
    of it, so a correct pose has every seen sensor facing (1.0); a mirror solution ~0.
    """
    R, t = T_lh_board[:, :3, :3], T_lh_board[:, :3, 3]
    p = np.einsum("mij,sj->msi", R, positions) + t[:, None]
    n = np.einsum("mij,sj->msi", R, normals)
    facing = np.sum(n * -p, axis=2) > 0
    seen = np.ones(facing.shape, dtype=bool) if seen is None else seen
    return np.sum(facing & seen, axis=1) / np.maximum(seen.sum(axis=1), 1)


def tracker_board_poses(azimuth: Array, elevation: Array, positions: Array, normals: Array,
                        model: StationModel | None = None, min_sensors: int = 5,
                        n_starts: int = 8) -> PnPResult:
    """Drop-in for :func:`lhgraph.estimation.init.pnp.board_poses` that suits curved boards
    (Vive Tracker):
    :func:`single_station_pnp` on each measurement's sensors seen on both axes.

    ``azimuth``/``elevation`` (M, S) rad (NaN = not seen) over the board's sensors
    ``positions``/``normals`` (S, 3); measurements with fewer than ``min_sensors`` get NaN.
    One pose at a time (~15 ms each): slower than the vectorised planar PnP.
    """
    mask = np.isfinite(azimuth) & np.isfinite(elevation)
    n = mask.sum(axis=1)
    M = len(azimuth)
    T, rms = np.full((M, 4, 4), np.nan), np.full(M, np.nan)
    for m in np.flatnonzero(n >= min_sensors):
        k = np.flatnonzero(mask[m])
        angle = np.stack([azimuth[m, k], elevation[m, k]], axis=1).ravel()
        T[m], rms[m], _ = single_station_pnp(
            np.repeat(positions[k], 2, axis=0), np.repeat(normals[k], 2, axis=0),
            np.tile([0, 1], len(k)), angle, model, n_starts)
    return PnPResult(T, rms, n)


def fit_sweep_pairs(bag: HiveBag, pairs: list[tuple[int, int]], mapping: AxisMapping,
                    models: dict[int, StationModel] | None = None, n_starts: int = 16
                    ) -> PairFit:
    """Tracker pose in each station's frame for each sweep pair, by
    :func:`single_station_pnp` on all the pair's hits mapped with ``mapping``."""
    L = bag.light
    board = bag.board
    axis, angle = mapping.apply(L["hive_axis"], L["angle"])
    order = np.argsort(L["sweep"], kind="stable")
    sweeps, start = np.unique(L["sweep"][order], return_index=True)
    stop = np.r_[start[1:], len(order)]
    span = {int(s): order[a:b] for s, a, b in zip(sweeps, start, stop, strict=True)}
    M = len(pairs)
    out = PairFit(np.empty(M, dtype=np.int64), np.empty(M), np.full((M, 4, 4), np.nan),
                  np.full(M, np.nan), np.full(M, np.nan))
    for i, (h, v) in enumerate(pairs):
        rows = np.concatenate([span[h], span[v]])
        lh = int(L["station"][rows[0]])
        out.station[i], out.time[i] = lh, L["time"][rows[0]]
        if len(rows) < 7:
            continue
        k = board.index_of(L["sensor"][rows])
        model = (models or {}).get(lh)
        T, rms, facing = single_station_pnp(board.positions[k], board.normals[k], axis[rows],
                                            angle[rows], model, n_starts)
        out.T_lh_board[i], out.rms_rad[i], out.facing[i] = T, rms, facing
    return out


@dataclass
class MappingCheck:
    """Per candidate mapping: median PnP rms (rad), mean facing fraction, median distance (m)
    and fraction of fits in front of the station."""

    mapping: AxisMapping
    median_rms_rad: float
    facing: float
    median_distance_m: float


def check_mappings(bag: HiveBag, n_pairs: int = 40, min_hits: int = 12, seed: int = 0,
                   mappings: tuple[AxisMapping, ...] = CANDIDATE_MAPPINGS
                   ) -> list[MappingCheck]:
    """Score candidate axis mappings by single-station PnP on ``n_pairs`` random sweep pairs
    with at least ``min_hits`` hits (ideal model, board from the bag)."""
    L = bag.light
    counts = np.bincount(L["sweep"])
    pairs = [p for p in sweep_pairs(bag) if counts[p[0]] + counts[p[1]] >= min_hits]
    rng = np.random.default_rng(seed)
    pick = sorted(rng.choice(len(pairs), min(n_pairs, len(pairs)), replace=False))
    pairs = [pairs[i] for i in pick]
    out = []
    for m in mappings:
        f = fit_sweep_pairs(bag, pairs, m)
        ok = np.isfinite(f.rms_rad)
        out.append(MappingCheck(m, float(np.median(f.rms_rad[ok])), float(np.mean(f.facing[ok])),
                                float(np.median(np.linalg.norm(f.T_lh_board[ok, :3, 3],
                                                               axis=1)))))
    return out


# --- comparison with the OptiTrack ground truth -----------------------------------------------


@dataclass
class MocapAlignment:
    """A board path aligned to OptiTrack: ``T_world_opti`` (world alignment), ``T_body_board``
    (hand-eye: marker body -> board frame), ``time_offset_s`` (mocap time = path time +
    offset), and per compared pose the position error (m) and rotation error (rad)."""

    T_world_opti: Array
    T_body_board: Array
    time_offset_s: float
    time: Array
    position_error_m: Array
    rotation_error_rad: Array

    def rmse_mm(self) -> float:
        """Root-mean-square position error (mm)."""
        return float(np.sqrt(np.mean(self.position_error_m**2)) * 1e3)

    def rmse_deg(self) -> float:
        """Root-mean-square rotation error (deg)."""
        return float(np.degrees(np.sqrt(np.mean(self.rotation_error_rad**2))))


def align_to_mocap(path: Trajectory, mocap: Trajectory, max_gap_s: float = 0.05,
                   max_offset_s: float = 0.1, rotation_scale_m: float = 0.1,
                   robust_scale_m: float = 0.005) -> MocapAlignment:
    """Fit ``T_world_board(t) ~ T_world_opti T_opti_body(t + dt) T_body_board`` by nonlinear
    least squares (scipy, soft-L1 loss of scale ``robust_scale_m``) over the 13 unknowns.

    ``path``: estimated board poses (world = reference station); ``mocap``: marker-body poses
    ``T_opti_body`` (its ``T_world_board`` field), interpolated (:func:`interpolate_poses`) at
    the path times + ``dt`` (|dt| <= ``max_offset_s``); path times without mocap samples within
    ``max_gap_s`` on both sides are skipped. Residual per pose: position error (m) and
    rotation error (rad) times ``rotation_scale_m``. Start: Kabsch on positions, chordal mean
    of the body-to-board rotations, zero lever arm and offset.
    """
    from scipy.optimize import least_squares

    t_m, T_m = mocap.time, mocap.T_world_board
    i = np.searchsorted(t_m, path.time)
    ok = (i > 0) & (i < len(t_m))
    ic = np.clip(i, 1, len(t_m) - 1)
    ok &= (path.time - t_m[ic - 1] < max_gap_s) & (t_m[ic] - path.time < max_gap_s)
    ok &= (path.time > t_m[0] + max_offset_s) & (path.time < t_m[-1] - max_offset_s)
    ok &= np.all(np.isfinite(path.T_world_board.reshape(len(path.time), -1)), axis=1)
    t, T_est = path.time[ok], path.T_world_board[ok]
    if len(t) < 10:
        raise SolverError(f"only {len(t)} path poses overlap the mocap recording")
    T_body = interpolate_poses(t_m, T_m, t)
    W0 = weighted_kabsch(T_body[:, :3, 3], T_est[:, :3, 3])
    U, _, Vt = np.linalg.svd(np.sum(np.swapaxes(W0[:3, :3] @ T_body[:, :3, :3], 1, 2)
                                    @ T_est[:, :3, :3], axis=0))
    H0 = make_pose(U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt, np.zeros(3))

    def unpack(x: Array) -> tuple[Array, Array, float]:
        return se3_exp(x[:6]) @ W0, H0 @ se3_exp(x[6:12]), float(x[12])

    def errors(x: Array) -> tuple[Array, Array]:
        W, H, dt = unpack(x)
        T_pred = W @ interpolate_poses(t_m, T_m, t + dt) @ H
        e_pos = T_pred[:, :3, 3] - T_est[:, :3, 3]
        e_rot = so3_log(np.swapaxes(T_est[:, :3, :3], 1, 2) @ T_pred[:, :3, :3])
        return e_pos, e_rot

    def residuals(x: Array) -> Array:
        e_pos, e_rot = errors(x)
        return np.concatenate([e_pos, rotation_scale_m * e_rot], axis=1).ravel()

    lim = np.r_[np.full(12, np.inf), max_offset_s]
    fit = least_squares(residuals, np.zeros(13), bounds=(-lim, lim), loss="soft_l1",
                        f_scale=robust_scale_m, x_scale=np.r_[np.full(12, 0.01), 0.01])
    W, H, dt = unpack(fit.x)
    e_pos, e_rot = errors(fit.x)
    return MocapAlignment(W, H, dt, t, np.linalg.norm(e_pos, axis=1),
                          np.linalg.norm(e_rot, axis=1))
