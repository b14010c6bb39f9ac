"""The co-visibility graph in the run report (:mod:`lhgraph.estimation.visibility`): which
stations saw the board together, in how many sweeps, and how far each station's pose hangs
from the reference's.

The figure is a plan of the stations at their solved positions, projected on the plane that
fits them best (a room's stations stand at about one height: the plan is the room seen from
above, whatever the world frame), one line per linked pair (width by the sweeps seen
together, log scale), the reference a square; with several captures each station's colour
is the first capture that saw it. The table gives per station its hits, captures,
neighbours and hops from the reference.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from lhgraph.estimation.visibility import Visibility


def plan_coordinates(positions: NDArray[np.float64]) -> NDArray[np.float64]:
    """Positions (n, 3) m projected on their best-fitting plane (n, 2): the two principal
    axes about their mean (a line or a point: the axes it has, zeros for the others)."""
    centred = positions - positions.mean(axis=0)
    if len(positions) < 2:
        return np.zeros((len(positions), 2))
    _, _, Vt = np.linalg.svd(centred, full_matrices=False)
    plan = centred @ Vt[:2].T
    return np.pad(plan, ((0, 0), (0, 2 - plan.shape[1])))


def visibility_figure(vis: Visibility, positions: dict[int, NDArray[np.float64]],
                      reference: int) -> Figure:
    """The plan of the co-visibility graph (module docstring); ``positions`` (m, any world)
    by station index, stations without one left out."""
    shown = [k for k in vis.stations() if k in positions]
    xy = dict(zip(shown, plan_coordinates(np.array([positions[k] for k in shown])),
                  strict=True))
    fig = Figure(figsize=(7, 5.5))
    ax = fig.add_subplot()
    top = max(vis.links.values(), default=1)
    for (a, b), n in vis.links.items():
        if a in xy and b in xy:
            width = 0.5 + 3.5 * np.log1p(n) / np.log1p(top)
            ax.plot(*np.array([xy[a], xy[b]]).T, color="tab:gray", lw=width, alpha=0.7,
                    zorder=1)
            mid = 0.5 * (xy[a] + xy[b])
            ax.annotate(str(n), mid, fontsize=6, color="tab:gray", ha="center")
    several = len({c for cs in vis.captures.values() for c in cs}) > 1
    colours = [vis.captures[k][0] if several else 0 for k in shown]
    points = np.array([xy[k] for k in shown])
    ax.scatter(points[:, 0], points[:, 1], c=colours, cmap="tab10", vmin=0, vmax=9, s=120,
               marker="o", zorder=2, edgecolors="k")
    if reference in xy:
        ax.scatter(*xy[reference], marker="s", s=260, facecolors="none", edgecolors="k",
                   lw=2, zorder=3, label=f"reference (station {reference})")
    for k in shown:
        ax.annotate(str(k), xy[k], xytext=(6, 6), textcoords="offset points", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("plan axis 1 (m)")
    ax.set_ylabel("plan axis 2 (m)")
    ax.legend(fontsize=7, loc="best")
    hops = vis.hops(reference)
    unlinked = [k for k in shown if k not in hops]
    title = (f"Co-visibility: {len(shown)} stations, {len(vis.links)} linked pairs "
             f"(sweeps seen together); at most {max(hops.values())} links from the reference")
    if several:
        title += "\ncolour: first capture that saw the station"
    if unlinked:
        title += f"\nnot linked to the reference: {', '.join(map(str, unlinked))}"
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def visibility_rows(vis: Visibility, reference: int) -> list[list[str]]:
    """Table rows: station, hits, captures, linked stations, hops from the reference."""
    hops = vis.hops(reference)
    return [[str(k), str(vis.hits[k]), ", ".join(map(str, vis.captures[k])),
             ", ".join(map(str, vis.neighbours(k))) or "none",
             str(hops[k]) if k in hops else "not linked"] for k in vis.stations()]
