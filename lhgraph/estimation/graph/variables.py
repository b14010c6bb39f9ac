"""The graph's variables: one :class:`VariableFamily` per kind of unknown (key symbol,
dimension, meaning) and the :class:`VariableLayout` of one graph (which indices of each family
it holds). Every read of a ``gtsam.Values`` or ``gtsam.VectorValues`` by family goes through the
layout, vectorised (one GTSAM call per family, no per-key Python loop).

Families (GTSAM key symbols are one character; ``v`` and ``b`` follow GTSAM's IMU idiom, a
3-D velocity and an IMU bias):

==============  ======  ===  ============================================================
family          symbol  dim  meaning
==============  ======  ===  ============================================================
board pose      ``x``   6    ``T_world_board`` at sweep k (``Pose3``)
board twist     ``w``   6    body twist ``[omega, v]`` (rad/s, m/s, board frame) at sweep k
sweep offset    ``o``   1    angle offset (rad) common to every diode of sweep k
station pose    ``l``   6    ``T_world_lh`` of station slot s >= 1 (slot 0 is the world)
IMU bias        ``i``   6    gyro (rad/s) and accelerometer (m/s^2) bias, board frame
gravity         ``n``   3    gravity vector (m/s^2) in the world
IMU calibration ``c``   10   gyro scale error, IMU time offset (s), IMU frame rotation and
                             position
IMU velocity    ``v``   3    the board origin's velocity (m/s) in the world at sweep k
IMU bias (k)    ``b``   6    accelerometer (m/s^2) and gyro (rad/s) bias at sweep k
                             (``gtsam.imuBias.ConstantBias``)
diode bias      ``d``   2n   angle bias (rad) of each diode and axis, per station slot
sensor offset   ``p``   3n   correction (m, board frame) of every sensor position
factory terms   ``f``   2m   correction (rad) of m factory terms per axis, per station slot
board scale     ``s``   1    relative scale correction of every sensor position
==============  ======  ===  ============================================================

Gravity exists only when the graph has IMU factors. With the twist factors
(:mod:`lhgraph.estimation.imu.inertial`, ``imu_factors = "twist"``) so does the one IMU bias
``i`` and, when the options ask for it (``gyro_scale_sigma``, ...), the calibration; with
GTSAM's combined factors (:mod:`lhgraph.estimation.imu.combined`) a velocity and a
bias per state instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import gtsam
import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from lhgraph.estimation.init.pnp_kabsch import Initialisation

Array = NDArray[np.float64]
Elimination = Literal["leaf", "chain", "root"]


@dataclass(frozen=True)
class VariableFamily:
    """One kind of variable.

    ``symbol``: the GTSAM key character (key = ``gtsam.symbol(symbol, index)``); ``dim``: tangent
    dimension; ``is_pose``: a ``Pose3`` (else a vector of ``dim``); ``elimination``: where its
    variables go in the elimination order (``"leaf"``: with its board state, after the chain
    families, each touches that state's factors only; ``"chain"``: per board state, in time
    order; ``"root"``: last, shared by the whole capture, so their marginals are read off the
    root clique); ``relinearize_threshold``: iSAM2
    relinearises a variable whose step exceeds this (tangent units; 0.1 is GTSAM's default, 1.0
    for variables the factors are nearly linear in); ``is_bias``: a
    ``gtsam.imuBias.ConstantBias`` (its vector: accelerometer, then gyro)."""

    name: str
    symbol: str
    dim: int
    is_pose: bool
    elimination: Elimination
    relinearize_threshold: float
    meaning: str
    is_bias: bool = False
    _key0: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # a gtsam Symbol key is the character in the top byte, the index below it
        object.__setattr__(self, "_key0", gtsam.symbol(self.symbol, 0))

    def key(self, index: int) -> int:
        """GTSAM key of variable ``index`` of this family (``gtsam.symbol(symbol, index)``)."""
        return self._key0 + index


BOARD_POSE = VariableFamily("board pose", "x", 6, True, "chain", 0.1,
                            "T_world_board at sweep k")
BOARD_TWIST = VariableFamily("board twist", "w", 6, False, "chain", 1.0,
                             "body twist [omega, v] (rad/s, m/s, board frame) at sweep k")
SWEEP_OFFSET = VariableFamily("sweep offset", "o", 1, False, "leaf", 1.0,
                              "angle offset (rad) common to every diode of sweep k")
STATION_POSE = VariableFamily("station pose", "l", 6, True, "root", 0.1,
                              "T_world_lh of station slot s >= 1")
IMU_BIAS = VariableFamily("IMU bias", "i", 6, False, "root", 1.0,
                          "gyro (rad/s) and accelerometer (m/s^2) bias, board frame")
GRAVITY = VariableFamily("gravity", "n", 3, False, "root", 1.0,
                         "gravity vector (m/s^2) in the world")
IMU_CALIBRATION = VariableFamily(
    "IMU calibration", "c", 10, False, "root", 1.0,
    "per-axis gyro scale error s (the gyro reads (1 + s) omega + bias), the time offset (s) "
    "at which the IMU is read on the light's clock (its stamps that much late), the "
    "rotation vector (rad) of the IMU's frame in the board's and the IMU's position (m) in "
    "the board frame (the accelerometer's lever arm)")

IMU_VELOCITY = VariableFamily("IMU velocity", "v", 3, False, "chain", 1.0,
                              "velocity (m/s) of the board origin in the world at sweep k")
BOARD_SCALE = VariableFamily("board scale", "s", 1, False, "root", 1.0,
                             "relative scale correction k of the board's sensor positions "
                             "(each at (1 + k) times its position, board frame)")
IMU_BIAS_STATE = VariableFamily("IMU bias at state", "b", 6, False, "chain", 1.0,
                                "accelerometer (m/s^2) and gyro (rad/s) bias at sweep k",
                                is_bias=True)


DIODE_BIAS = "diode bias"
SENSOR_OFFSET = "sensor offset"
FACTORY_TERMS = "factory terms"
"""Names of the families whose size depends on the problem or the options (built by
:func:`diode_bias_family`, :func:`sensor_offset_family` and :func:`factory_family`;
:meth:`VariableLayout.family` finds them)."""


def diode_bias_family(n_sensors: int) -> VariableFamily:
    """The per-diode angle biases of a board of ``n_sensors``: one vector per station slot,
    ``2 * n_sensors`` long (axis-major: ``axis * n_sensors + board row``), in rad."""
    return VariableFamily(DIODE_BIAS, "d", 2 * n_sensors, False, "root", 1.0,
                          "angle bias (rad) of each diode and axis as station slot s sees it")


def sensor_offset_family(n_sensors: int) -> VariableFamily:
    """The board's sensor-position corrections: one vector of ``3 * n_sensors`` (m, board
    frame, row-major by board row), shared by every station."""
    return VariableFamily(SENSOR_OFFSET, "p", 3 * n_sensors, False, "root", 1.0,
                          "correction (m, board frame) of every sensor's position")


def factory_family(n_terms: int) -> VariableFamily:
    """The corrections of ``n_terms`` factory terms (each per axis) to a station's decoded
    values: one vector per station slot, ``2 * n_terms`` long (key-major: ``[key0 axis0,
    key0 axis1, key1 axis0, ...]``), in rad."""
    return VariableFamily(FACTORY_TERMS, "f", 2 * n_terms, False, "root", 1.0,
                          "correction (rad) of station slot s's factory terms to OOTX")


FAMILIES = (BOARD_POSE, BOARD_TWIST, SWEEP_OFFSET, STATION_POSE, IMU_BIAS, GRAVITY,
            IMU_CALIBRATION, IMU_VELOCITY, IMU_BIAS_STATE, BOARD_SCALE)
"""Every family the graph and the streaming smoother know."""


class VariableLayout:
    """The variables of one graph: for each family, the indices it holds (a ``range``; the
    dict's order is the order the chain interleaves its families per state).

    GTSAM orders a ``Values`` by key, i.e. by symbol character, then index; the layout turns
    that order into per-family slices, so reading every pose back is one ``extractPose3``.
    """

    def __init__(self, indices: dict[VariableFamily, range]):
        self._indices = dict(indices)
        self._keys = {f: [f.key(i) for i in r] for f, r in self._indices.items()}
        chain = [r for f, r in self._indices.items() if f.elimination == "chain"]
        if any(r != chain[0] for r in chain):
            raise ValueError("chain families must hold the same state indices")
        self._pose_slices: dict[VariableFamily, slice] = {}
        start = 0
        for family in sorted((f for f in self._indices if f.is_pose), key=lambda f: f.symbol):
            n = len(self._indices[family])
            self._pose_slices[family] = slice(start, start + n)
            start += n
        self._n_poses = start
        self._ordering: gtsam.Ordering | None = None

    @classmethod
    def of_problem(cls, n_states: int, n_stations: int, fixed_stations: bool = False,
                   inertial: bool = False, diode_bias: VariableFamily | None = None,
                   sensor_offset: VariableFamily | None = None,
                   imu_calibration: bool = False, combined_imu: bool = False,
                   factory: VariableFamily | None = None, board_scale: bool = False
                   ) -> VariableLayout:
        """The batch graph's layout: every family per board state ``0..n_states-1``, a station
        pose for slots ``1..n_stations-1`` (none with ``fixed_stations``: tracking, every
        station held at a known pose), with ``inertial`` one IMU bias and the gravity, and
        with ``inertial`` and ``imu_calibration`` the IMU's calibration; with
        ``combined_imu`` (GTSAM's combined IMU factors) instead a velocity and an IMU bias
        per state and the gravity; ``diode_bias`` and ``factory`` one vector per station
        slot, ``sensor_offset`` one, with ``board_scale`` the board's scale correction."""
        states = range(n_states)
        stations = range(0) if fixed_stations else range(1, n_stations)
        imu = range(1) if inertial and not combined_imu else range(0)
        families = {BOARD_POSE: states, BOARD_TWIST: states, SWEEP_OFFSET: states,
                    STATION_POSE: stations, IMU_BIAS: imu,
                    GRAVITY: range(1) if inertial else range(0)}
        if inertial and combined_imu:
            families[IMU_VELOCITY] = states
            families[IMU_BIAS_STATE] = states
        if inertial and imu_calibration and not combined_imu:
            families[IMU_CALIBRATION] = range(1)
        if diode_bias is not None:
            families[diode_bias] = range(n_stations)
        if sensor_offset is not None:
            families[sensor_offset] = range(1)
        if factory is not None:
            families[factory] = range(n_stations)
        if board_scale:
            families[BOARD_SCALE] = range(1)
        return cls(families)

    @property
    def families(self) -> tuple[VariableFamily, ...]:
        return tuple(self._indices)

    def family(self, name: str) -> VariableFamily | None:
        """This layout's family called ``name`` (None when it has none)."""
        return next((f for f in self._indices if f.name == name), None)

    def indices(self, family: VariableFamily) -> range:
        return self._indices[family]

    def holds(self, family: VariableFamily, index: int) -> bool:
        """Whether variable ``index`` of ``family`` is one of this graph's (a station slot
        that is not held fixed, say)."""
        return index in self._indices.get(family, range(0))

    def keys(self, family: VariableFamily) -> list[int]:
        """Keys of ``family``, in index order."""
        return self._keys[family]

    def elimination_ordering(self) -> gtsam.Ordering:
        """The chain families state by state (board pose, twist), each state followed by its
        leaf variables (its sweep offset), the root families last (the stations): the
        stations sit in the root clique, so their marginal covariances come with the last
        iteration's Bayes tree for free. Leaf variables of no state go first.

        A state's leaves eliminated with it share its clique: on the real Crazyflie LH1 log
        (3739 states) 3739 cliques instead of 7466 and 64 ms instead of 74 per elimination.
        The states go in time order when the graph has no root variables (tracking: the chain
        eliminates without fill-in), else in the nested-dissection order of the chain
        (:func:`chain_dissection`): eliminated in time order, every state's clique would hold
        every station seen before it (all 8 of a room, though each state sees 3 or 4), and the
        8-station room's elimination took 0.93 s instead of 0.59 s. Made once per layout
        (12 ms for the real Crazyflie log's 3739 states); not to be modified."""
        if self._ordering is not None:
            return self._ordering
        ordering = gtsam.Ordering()
        by_stage = {stage: [f for f in self._indices if f.elimination == stage]
                    for stage in ("leaf", "chain", "root")}
        chain = by_stage["chain"]
        states = self._indices[chain[0]] if chain else range(0)
        leaves: dict[int, list[int]] = {}
        for family in by_stage["leaf"]:
            for index, key in zip(self._indices[family], self._keys[family], strict=True):
                if index in states:
                    leaves.setdefault(index, []).append(key)
                else:
                    ordering.push_back(key)
        has_root = any(self._keys[f] for f in by_stage["root"])
        for state in chain_dissection(len(states)) if has_root else range(len(states)):
            for family in chain:
                ordering.push_back(self._keys[family][state])
            for key in leaves.get(states[state], []):
                ordering.push_back(key)
        for family in by_stage["root"]:
            for key in self._keys[family]:
                ordering.push_back(key)
        self._ordering = ordering
        return ordering

    def read_poses(self, values: gtsam.Values) -> dict[VariableFamily, Array]:
        """Every pose family's poses ``(n, 4, 4)`` in index order (views of one array)."""
        rows = gtsam.utilities.extractPose3(values)  # every Pose3 of values, in key order
        if len(rows) != self._n_poses:
            raise ValueError(f"values hold {len(rows)} poses, the layout {self._n_poses}")
        T = np.zeros((len(rows), 4, 4))
        T[:, :3, :3] = rows[:, :9].reshape(-1, 3, 3)
        T[:, :3, 3] = rows[:, 9:]
        T[:, 3, 3] = 1.0
        return {family: T[s] for family, s in self._pose_slices.items()}

    def read_vectors(self, values: gtsam.Values, family: VariableFamily) -> Array:
        """A vector family's values ``(n, dim)`` in index order (a bias family's vectors:
        accelerometer, then gyro)."""
        if family.is_bias:
            return np.array([values.atConstantBias(k).vector() for k in self._keys[family]]
                            ).reshape(-1, family.dim)
        return gtsam.utilities.extractVectors(values, family.symbol)

    def read_steps(self, delta: gtsam.VectorValues, family: VariableFamily) -> Array:
        """A family's tangent steps ``(n, dim)`` in index order."""
        return delta.vector(self._keys[family]).reshape(-1, family.dim)

    def insert(self, values: gtsam.Values, family: VariableFamily, data: Array) -> None:
        """Insert ``data`` (``(n, 4, 4)`` poses or ``(n, dim)`` vectors, in index order)."""
        for key, x in zip(self._keys[family], data, strict=True):
            if family.is_bias:
                values.insert(key, gtsam.imuBias.ConstantBias(x[:3], x[3:]))
            else:
                values.insert(key, gtsam.Pose3(x) if family.is_pose else x)


def chain_dissection(n: int, leaf: int = 64) -> list[int]:
    """Nested-dissection order of a chain of ``n`` states: each half of a segment before the
    state between them, segments of at most ``leaf`` states in time order. A subtree's cliques
    hold only the stations seen within its segment (plus its two boundary states), so the
    elimination cost per state stays that of the few stations in view, not of all of them."""
    order: list[int] = []
    stack: list[tuple[int, int, bool]] = [(0, n, False)]
    while stack:  # iterative post-order: left half, right half, middle state
        lo, hi, expanded = stack.pop()
        if hi - lo <= leaf:
            order.extend(range(lo, hi))
        elif expanded:
            order.append((lo + hi) // 2)
        else:
            mid = (lo + hi) // 2
            stack += [(lo, hi, True), (mid + 1, hi, False), (lo, mid, False)]
    return order


def initial_values(layout: VariableLayout, init: Initialisation,
                   gravity: Array | None = None) -> gtsam.Values:
    """GTSAM Values of an initialisation (sweep offsets zero); with IMU variables in the
    layout, the IMU biases zero, ``gravity`` (3,) m/s^2 in the world and the states'
    velocities in the world from their poses and twists."""
    values = gtsam.Values()
    layout.insert(values, STATION_POSE, init.L[layout.indices(STATION_POSE)])
    layout.insert(values, BOARD_POSE, init.X)
    layout.insert(values, BOARD_TWIST, init.V)
    layout.insert(values, SWEEP_OFFSET, np.zeros((len(init.X), 1)))
    if layout.holds(GRAVITY, 0):
        if gravity is None:
            raise ValueError("a layout with IMU variables needs the initial gravity")
        layout.insert(values, GRAVITY, np.asarray(gravity, dtype=float)[None])
    if layout.holds(IMU_BIAS, 0):
        layout.insert(values, IMU_BIAS, np.zeros((1, 6)))
    if layout.holds(IMU_VELOCITY, 0):
        layout.insert(values, IMU_VELOCITY, np.einsum("kij,kj->ki", init.X[:, :3, :3],
                                                      init.V[:, 3:]))
        layout.insert(values, IMU_BIAS_STATE, np.zeros((len(init.X), 6)))
    for family in filter(None, (layout.family(DIODE_BIAS), layout.family(SENSOR_OFFSET),
                                layout.family(FACTORY_TERMS), layout.family(BOARD_SCALE.name),
                                layout.family(IMU_CALIBRATION.name))):
        layout.insert(values, family, np.zeros((len(layout.indices(family)), family.dim)))
    return values
