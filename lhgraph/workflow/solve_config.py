"""The solve configuration file that ``lhgraph solve CONFIG.toml`` takes (docs/solve.md).

:class:`SolveConfig` is frozen and declares each key's allowed values
(:mod:`lhgraph.config`); :func:`load_solve_config` reads and checks a file, the CLI's flags
replace fields with :func:`lhgraph.config.override`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from lhgraph.choices import METHODS, WORLDS
from lhgraph.config import Table, check_fields, option, rules
from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.io.files import read_toml

SENSOR_OFFSET_SIGMA_M = 3e-4
"""Prior spread (m) of each sensor-position correction when a ``board_output`` is asked for
and the config does not set ``graph.sensor_offset_sigma_m``: a board's assembly tolerance."""


@dataclass(frozen=True)
class SolveConfig:
    """A solve described by a file: inputs, method(s) and options (paths absolute).

    The angles come from ``angles`` or, when ``capture`` is set instead, from decoding that
    capture (its OOTX calibration is used unless ``calibration`` is given). ``methods``
    (several methods, run directory output only) overrides ``method``; ``seed`` is recorded
    in a run directory's summary; ``path`` is the configuration file itself; ``duration_s``
    (old spelling ``duration``) keeps only that many seconds from the moment the board starts
    moving; ``world`` is ``"reference"`` (the reference station's frame) or ``"gravity"``
    (z up from the stations' OOTX accelerometer vectors, :mod:`lhgraph.estimation.gravity`);
    ``imu`` the receiver's ``imu.csv`` (board frame, the angles' clock): the graph refines its
    solution with IMU factors (:func:`lhgraph.estimation.graph.solver.solve_graph`);
    ``board_output`` a board TOML to write with the sensor positions the graph solved for
    (:meth:`graph_options`: the sensor offsets are then on); ``more_angles`` the angles of
    further captures solved jointly with ``angles`` (a list ``angles = [A, B, ...]`` in the
    file, ``--angles`` repeated: :func:`lhgraph.io.captures.join_captures`); ``prior`` an
    earlier stations TOML whose poses and covariances become priors on the stations
    (:mod:`lhgraph.estimation.station_prior`).
    """

    board: Path = option(kind=Path)
    angles: Path | None = option(None, kind=Path)
    output: Path | None = option(None, kind=Path)
    method: str = option("graph", choices=METHODS)
    calibration: Path | None = option(None, kind=Path)
    trajectory: Path | None = option(None, kind=Path)
    truth: Path | None = option(None, kind=Path)
    reference: int | None = option(None, kind=int, ge=0)
    graph: GraphOptions = field(default_factory=GraphOptions)
    capture: Path | None = option(None, kind=Path)
    methods: tuple[str, ...] | None = None
    seed: int | None = option(None, kind=int)
    path: Path | None = None
    duration_s: float | None = option(None, kind=float, gt=0, alias="duration")
    world: str = option("reference", choices=WORLDS)
    imu: Path | None = option(None, kind=Path)
    board_output: Path | None = option(None, kind=Path)
    more_angles: tuple[Path, ...] = ()
    prior: Path | None = option(None, kind=Path)

    def __post_init__(self) -> None:
        check_fields(self)

    def graph_options(self) -> GraphOptions:
        """The graph's options: ``graph``, with the sensor offsets on
        (``SENSOR_OFFSET_SIGMA_M``) when a ``board_output`` is asked for and ``graph`` does not
        set their prior."""
        if self.board_output is None or self.graph.board.sensor_offset_sigma_m > 0:
            return self.graph
        return self.graph.with_values(sensor_offset_sigma_m=SENSOR_OFFSET_SIGMA_M)

    def method_list(self) -> list[str]:
        """The methods to run, in order."""
        return list(self.methods) if self.methods else [self.method]


def check_methods(value: object, source: str | Path, where: str = "methods") -> list[str]:
    """A config's list of methods: non-empty, distinct, each one of :data:`METHODS`."""
    if (not isinstance(value, list) or not value or any(m not in METHODS for m in value)
            or len(set(value)) != len(value)):
        raise InputError(f"expected a non-empty list of distinct methods from "
                         f"{', '.join(METHODS)}, got {value!r}", source, where)
    return value


def load_solve_config(path: str | Path) -> SolveConfig:
    """Read a solve configuration; relative paths are relative to the file's folder."""
    path = Path(path)
    table = Table(read_toml(path), path, "", path.parent)
    declared = rules(SolveConfig)
    table.refuse_unknown({*declared, "duration", "graph", "methods"})
    methods = table.get("methods")
    if methods is not None:
        if "method" in table:
            raise InputError("give 'method' or 'methods', not both", path, "methods")
        methods = tuple(check_methods(methods, path))
    if ("angles" in table) == ("capture" in table):
        raise InputError("give exactly one of 'angles' and 'capture'", path,
                         "angles" if "angles" in table else "capture")
    board = table.path("board", required=True)
    more: tuple[Path, ...] = ()
    if isinstance(table.data.get("angles"), list):
        listed = table.get("angles")
        if len(listed) < 1 or not all(isinstance(a, str) for a in listed):
            raise InputError("expected a path or a non-empty list of paths", path, "angles")
        first, *rest = (path.parent / a for a in listed)
        more = tuple(rest)
        table.data = {**table.data, "angles": str(first)}
    values = {name: table.value(name, rule, None) for name, rule in declared.items()
              if name != "board"}
    given = {k: v for k, v in values.items() if v is not None}
    return SolveConfig(board=board, graph=table.options("graph", GraphOptions),
                       methods=methods, path=path, more_angles=more, **given)
