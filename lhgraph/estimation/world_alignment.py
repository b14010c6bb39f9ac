"""A world a Crazyflie user expects: z up from gravity, origin and x axis chosen by name.

The stations come in some world ``w`` (the reference station's frame, a gravity world, ...);
:func:`align_world` gives ``T_new_w``, the rigid motion into the new world ``n``:

- **up** (``WorldOptions.up``): ``imu`` = the receiver's accelerometer carried into ``w`` by
  the receiver's poses (:func:`up_from_imu`); ``ootx`` = the stations' OOTX accelerometer
  vectors carried by their poses (:mod:`lhgraph.estimation.gravity`); ``none`` = keep ``w``'s
  z axis.
- **origin**: ``receiver-start`` = the receiver's position at ``at_s`` (default: the first
  trajectory state); ``reference-station`` = the reference station's centre; ``world`` = ``w``'s
  origin.
- **x**: the named axis made horizontal (perpendicular to up): ``receiver-start`` = the
  receiver's body +x at ``at_s``, ``reference-station`` = the reference station's forward axis,
  ``world`` = ``w``'s +x.

``receiver-start`` for both is what cfclient's own wizard does with its origin sample: the
Crazyflie sitting at the origin with its +x along the world's +x.

The accelerometer (SI, m/s^2, in the board frame: for the Crazyflie the body frame is the
board frame of ``crazyflie_deck``) measures the specific force ``f = R_w_board^T (a - g)``,
so ``R_w_board f`` is *up* times 9.81 plus the receiver's linear acceleration ``a``. Samples
at rest (:func:`still_mask`) have ``a = 0``; over a long stretch of hand-held motion the mean
of ``a`` is ``(v_end - v_start) / duration``, a few mm/s^2 for 120 s (about 0.05 deg of tilt
for 1 m/s of speed difference), so the mean over *all* samples serves when the receiver never
rests. ``consistency`` = |mean of ``R f``| / 1 g is ~1 when poses and accelerometer agree
(within the accelerometer's scale error, a few %); a wrong IMU frame or clock scatters the
gravity parts of the vectors and shrinks the mean (on the shared LH1 log, 0.978 over 125 s of
hand-held motion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.choices import EXPORT_FRAMES, EXPORT_IMU_SAMPLES, EXPORT_UP
from lhgraph.config import check_fields, option
from lhgraph.errors import InputError
from lhgraph.estimation.gravity import gravity_rotation, up_vectors
from lhgraph.geometry.transforms import make_pose
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2
from lhgraph.io.stations import Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.calibration import StationCalibration

Array = NDArray[np.float64]

MIN_CONSISTENCY = 0.9
"""Below this |mean of R f| / 1 g the IMU-derived up is refused as unreliable."""


@dataclass(frozen=True)
class WorldOptions:
    """How the new world is chosen (module docstring). ``auto``: ``up`` = imu when an IMU
    stream is given, else ootx when a station has an accelerometer vector, else none;
    ``origin`` and ``x`` = receiver-start when a trajectory is given, else reference-station;
    ``imu_samples`` = still when at least ``min_still_s`` of still samples exist, else all.
    A sample is still when, over ``still_window_s`` around it, every accelerometer axis
    varies by less than ``still_accel_std_mps2`` (standard deviation), the rms gyro rate is
    below ``still_gyro_rad_s`` and the mean specific force is within 10 % of 1 g."""

    up: str = option("auto", choices=EXPORT_UP)
    origin: str = option("auto", choices=EXPORT_FRAMES)
    x: str = option("auto", choices=EXPORT_FRAMES)
    at_s: float | None = option(None, kind=float)
    imu_samples: str = option("auto", choices=EXPORT_IMU_SAMPLES)
    still_window_s: float = option(0.5, gt=0)
    still_accel_std_mps2: float = option(0.15, gt=0)
    still_gyro_rad_s: float = option(0.05, gt=0)
    min_still_s: float = option(1.0, ge=0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class UpEstimate:
    """Up (unit vector in the input world) and where it came from: ``source`` (imu, ootx,
    none), ``samples`` (still, all, or the OOTX station count as text), the number of
    vectors averaged, ``spread_deg`` (ootx: largest angle of one station's up from the mean;
    imu: rms angle of the sample vectors about the mean) and ``consistency`` (imu only, see
    the module docstring; 1 otherwise)."""

    up_world: Array
    source: str
    samples: str = ""
    n: int = 0
    spread_deg: float = 0.0
    consistency: float = 1.0

    def describe(self) -> str:
        """One phrase for summaries."""
        if self.source == "none":
            return "z kept from the input world"
        if self.source == "ootx":
            return (f"z up from the OOTX accelerometers of {self.n} station(s) (spread "
                    f"{self.spread_deg:.2f} deg)")
        return (f"z up from {self.n} {self.samples} IMU samples (consistency "
                f"{self.consistency:.3f}, rms spread {self.spread_deg:.1f} deg)")


@dataclass(frozen=True)
class WorldAlignment:
    """``T_new_w`` (4x4) and the choices that made it (``origin``, ``x``, ``at_s``)."""

    T_new_w: Array
    up: UpEstimate
    origin: str
    x: str
    at_s: float | None

    def summary(self) -> str:
        """One line: what the new world is."""
        at = f" (t = {self.at_s:.3f} s)" if self.at_s is not None else ""
        uses_receiver = "receiver-start" in (self.origin, self.x)
        return (f"world: {self.up.describe()}; origin {self.origin}, x {self.x}"
                f"{at if uses_receiver else ''}")


def _window_sums(time: Array, values: Array, half_s: float) -> tuple[Array, Array]:
    """Per sample: the sum of ``values`` (N, k) and the count within ``time +- half_s``."""
    c = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    lo = np.searchsorted(time, time - half_s, side="left")
    hi = np.searchsorted(time, time + half_s, side="right")
    return c[hi] - c[lo], (hi - lo).astype(float)


def still_mask(time: ArrayLike, accel_mps2: ArrayLike, gyro_rad_s: ArrayLike | None,
               options: WorldOptions = WorldOptions()) -> NDArray[np.bool_]:
    """True for IMU samples at rest (``time`` (N,) increasing, s; ``accel_mps2`` (N, 3);
    ``gyro_rad_s`` (N, 3) or None), by the rule of :class:`WorldOptions`."""
    t = np.asarray(time, dtype=float)
    a = np.asarray(accel_mps2, dtype=float).reshape(-1, 3)
    half = 0.5 * options.still_window_s
    s1, n = _window_sums(t, a, half)
    s2, _ = _window_sums(t, a * a, half)
    mean = s1 / n[:, None]
    var = np.maximum(s2 / n[:, None] - mean**2, 0.0)
    still = np.all(var < options.still_accel_std_mps2**2, axis=1) & (n >= 3)
    still &= np.abs(np.linalg.norm(mean, axis=1) / STANDARD_GRAVITY_MPS2 - 1.0) < 0.1
    if gyro_rad_s is not None:
        g = np.asarray(gyro_rad_s, dtype=float).reshape(-1, 3)
        g2, _ = _window_sums(t, np.sum(g * g, axis=1, keepdims=True), half)
        still &= g2[:, 0] / n < options.still_gyro_rad_s**2
    return still


def _mean_direction(vectors: Array) -> tuple[Array, float, float]:
    """Unit mean of ``vectors`` (N, 3, m/s^2), rms angle (deg) of the unit vectors about it
    and |mean| / 1 g."""
    norms = np.linalg.norm(vectors, axis=1)
    mean = vectors.mean(axis=0)
    length = float(np.linalg.norm(mean))
    if length == 0.0:
        raise InputError("the IMU samples average to zero: no up direction")
    up = mean / length
    cos = np.clip(vectors @ up / np.where(norms > 0, norms, 1.0), -1.0, 1.0)
    spread = float(np.degrees(np.sqrt(np.mean(np.arccos(cos) ** 2))))
    return up, spread, length / STANDARD_GRAVITY_MPS2


def up_from_imu(time: ArrayLike, accel_mps2: ArrayLike, gyro_rad_s: ArrayLike | None,
                trajectory: Trajectory, options: WorldOptions = WorldOptions()) -> UpEstimate:
    """Up in the trajectory's world from the receiver's accelerometer (board frame, m/s^2)
    and its poses ``T_world_board``; only samples within the trajectory's time span count."""
    t = np.asarray(time, dtype=float)
    a = np.asarray(accel_mps2, dtype=float).reshape(-1, 3)
    g = None if gyro_rad_s is None else np.asarray(gyro_rad_s, dtype=float).reshape(-1, 3)
    inside = (t >= trajectory.time[0]) & (t <= trajectory.time[-1])
    if np.count_nonzero(inside) < 3:
        raise InputError(f"only {np.count_nonzero(inside)} IMU samples lie within the "
                         f"trajectory's time span [{trajectory.time[0]:.3f}, "
                         f"{trajectory.time[-1]:.3f}] s: are they on the same clock?",
                         where="imu")
    still = still_mask(t, a, g, options) & inside
    rate = (len(t) - 1) / max(float(t[-1] - t[0]), 1e-9)
    enough = np.count_nonzero(still) / rate >= max(options.min_still_s, 1e-9)
    mode = options.imu_samples
    if mode == "auto":
        mode = "still" if enough else "all"
    if mode == "still" and not np.any(still):
        raise InputError("no still IMU sample within the trajectory's time span (use "
                         "--imu-samples all to average over the motion)", where="imu")
    use = still if mode == "still" else inside
    R = trajectory.at(t[use])[:, :3, :3]
    up, spread, consistency = _mean_direction(np.einsum("nij,nj->ni", R, a[use]))
    return UpEstimate(up, "imu", mode, int(np.count_nonzero(use)), spread, consistency)


def up_from_ootx(stations: Stations, calibrations: dict[int, StationCalibration]
                 ) -> UpEstimate:
    """Up in the stations' world from their OOTX accelerometer vectors (the rule of
    :func:`lhgraph.estimation.gravity.gravity_rotation`)."""
    up = up_vectors(calibrations)
    T, spread = gravity_rotation(stations, up)
    n = len([k for k in stations.indices() if k in up])
    return UpEstimate(T[2, :3].copy(), "ootx", f"{n} station(s)", n, spread)


def _horizontal(axis: Array, up: Array, what: str) -> Array:
    x = axis - (axis @ up) * up
    norm = float(np.linalg.norm(x))
    if norm < 1e-3:
        raise InputError(f"{what} points straight up or down: it cannot give the x axis "
                         "(choose another --x)")
    return x / norm


def align_world(stations: Stations, up: UpEstimate, trajectory: Trajectory | None = None,
                options: WorldOptions = WorldOptions()) -> WorldAlignment:
    """``T_new_w`` of the world chosen by ``options`` (module docstring) for ``stations``
    given in ``w``; ``trajectory`` (``T_w_board``) is needed for the receiver-start choices."""
    default = "receiver-start" if trajectory is not None else "reference-station"
    origin = default if options.origin == "auto" else options.origin
    x_name = default if options.x == "auto" else options.x
    at_s = None
    T_w_receiver = None
    if "receiver-start" in (origin, x_name):
        if trajectory is None:
            raise InputError("receiver-start needs the receiver's trajectory (--trajectory)")
        at_s = float(trajectory.time[0]) if options.at_s is None else options.at_s
        if not trajectory.time[0] <= at_s <= trajectory.time[-1]:
            raise InputError(f"--at {at_s:g} s is outside the trajectory "
                             f"[{trajectory.time[0]:.3f}, {trajectory.time[-1]:.3f}] s")
        T_w_receiver = trajectory.at(np.array([at_s]))[0]
    z = np.asarray(up.up_world, dtype=float) / np.linalg.norm(up.up_world)
    T_w_ref = stations.pose(stations.reference)
    frames = {"receiver-start": T_w_receiver, "reference-station": T_w_ref, "world": np.eye(4)}
    p0 = frames[origin][:3, 3]
    x = _horizontal(frames[x_name][:3, 0], z, f"the {x_name} x axis")
    R_new_w = np.stack([x, np.cross(z, x), z])
    if up.source == "imu" and up.consistency < MIN_CONSISTENCY:
        raise InputError(
            f"the IMU and the trajectory agree poorly (consistency {up.consistency:.2f} < "
            f"{MIN_CONSISTENCY}): up from them is not reliable. Either the trajectory's "
            "orientations are wrong (a light-only track of a few-diode receiver such as the "
            "Crazyflie deck turns poses into their mirror image: track it with --imu) or the "
            "IMU's frame or clock is not the trajectory's; or choose --up ootx / none")
    return WorldAlignment(make_pose(R_new_w, -R_new_w @ p0), up, origin, x_name, at_s)


def transform_stations(stations: Stations, T_new_w: Array) -> Stations:
    """``stations`` re-expressed in the new world (covariances are in each station's own
    tangent space and do not change)."""
    return Stations(stations.reference,
                    {k: s.moved(T_new_w) for k, s in stations.stations.items()},
                    dict(stations.extra))
