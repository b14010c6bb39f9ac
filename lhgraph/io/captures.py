"""Several captures as one angles table for one joint solve: :func:`join_captures`.

Each capture keeps its own clock: capture ``c`` is shifted in time to start
:data:`CAPTURE_GAP_S` after the previous one ends, its sweeps keep their own grouping (an
``extra["sweep"]`` column numbered across the captures) and every hit is labelled with its
capture (``extra["capture"]``, 0-based). The graph builds one board trajectory per capture
(no motion prior across the boundary, :meth:`lhgraph.estimation.problem.GraphProblem.linked`)
and shares the station variables.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError
from lhgraph.io.angles import Angles

CAPTURE_GAP_S = 1.0
"""Time (s) between the end of one capture and the start of the next on the joined clock."""


@dataclass(frozen=True)
class CaptureSpan:
    """One capture in a joined table: its name (file), its clock's shift (s: joined time =
    its time + ``shift_s``) and its hits per station index."""

    name: str
    shift_s: float
    hits: dict[int, int]


def join_captures(captures: list[Angles], names: list[str | Path]
                  ) -> tuple[Angles, list[CaptureSpan], list[str]]:
    """The captures as one angles table (module docstring), their spans and notes (extra
    columns only some captures have are dropped, one note each). InputError when there
    are fewer than two captures or one is empty."""
    if len(captures) < 2:
        raise InputError("joining captures needs at least two")
    for angles, name in zip(captures, names, strict=True):
        if len(angles) == 0:
            raise InputError("no hits", name)
    common = set.intersection(*(set(a.extra) for a in captures)) - {"sweep", "capture"}
    notes = [f"column '{k}' dropped: not in every capture"
             for k in sorted(set().union(*(a.extra for a in captures)) - common
                             - {"sweep", "capture"})]
    parts, spans = [], []
    start, sweep_base = 0.0, 0
    for c, (angles, name) in enumerate(zip(captures, names, strict=True)):
        shift = start - float(angles.time[0])
        sweep = angles.sweep_ids() + sweep_base
        sweep_base = int(sweep.max()) + 1
        extra = {k: angles.extra[k] for k in sorted(common)}
        extra |= {"sweep": sweep, "capture": np.full(len(angles), c, dtype=np.int64)}
        parts.append(Angles(angles.time + shift, angles.lighthouse, angles.axis, angles.sensor,
                            angles.angle, extra))
        stations, counts = np.unique(angles.lighthouse, return_counts=True)
        spans.append(CaptureSpan(str(name), shift, dict(zip(stations.tolist(),
                                                              counts.tolist(), strict=True))))
        start = float(angles.time[-1]) + shift + CAPTURE_GAP_S
    keys = parts[0].extra
    joined = Angles(*(np.concatenate([getattr(p, f) for p in parts])
                      for f in ("time", "lighthouse", "axis", "sensor", "angle")),
                    {k: np.concatenate([p.extra[k] for p in parts]) for k in keys})
    return joined, spans, notes


def capture_lines(spans: list[CaptureSpan]) -> list[str]:
    """One line per capture: which stations it saw (hits), the link between them."""
    return [f"capture {c} ({span.name}): " + ", ".join(
        f"station {k} {n} hits" for k, n in sorted(span.hits.items()))
        for c, span in enumerate(spans)]
