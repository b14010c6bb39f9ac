"""What ``lhgraph compare`` shows and writes: the station-by-station table and the JSON of a
:class:`~lhgraph.estimation.layout_compare.LayoutComparison` (docs/compare.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from lhgraph.estimation.layout_compare import LayoutComparison


def _finite(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def comparison_table(c: LayoutComparison) -> str:
    """One row per common station (B - A in station ``c.reference``'s frame: mm, deg,
    combined sigmas), then the stations only one file has."""
    lines = [f"in the frame of station {c.reference}; moved: over {c.options.k_sigma:g} "
             f"combined sigma and over {c.options.floor_mm:g} mm or {c.options.floor_deg:g} deg",
             f"{'station':>7} {'dx mm':>8} {'dy mm':>8} {'dz mm':>8} {'|dp| mm':>8} "
             f"{'dR deg':>7} {'sigma mm':>8} {'sigma deg':>9} {'|dp|/s':>7} {'dR/s':>6}  moved"]
    for d in c.differences:
        lines.append(
            f"{d.station:>7} {d.dp_m[0] * 1e3:>8.1f} {d.dp_m[1] * 1e3:>8.1f} "
            f"{d.dp_m[2] * 1e3:>8.1f} {d.position_m * 1e3:>8.1f} "
            f"{np.degrees(d.rotation_rad):>7.3f} {d.sigma_position_m * 1e3:>8.2f} "
            f"{np.degrees(d.sigma_rotation_rad):>9.4f} {d.position_sigmas:>7.1f} "
            f"{d.rotation_sigmas:>6.1f}  {'yes' if d.moved else 'no'}")
    for name, only in (("A", c.only_in_a), ("B", c.only_in_b)):
        if only:
            lines.append(f"only in {name}: station(s) {', '.join(map(str, only))}")
    return "\n".join(lines)


def comparison_json(c: LayoutComparison, a: str | Path, b: str | Path) -> str:
    """The comparison as a JSON document (docs/compare.md): inputs, options, per-station
    differences (m, rad, sigmas; null without covariances), the verdict."""
    return json.dumps({
        "a": str(a), "b": str(b), "reference": c.reference,
        "options": {"k_sigma": c.options.k_sigma, "floor_mm": c.options.floor_mm,
                    "floor_deg": c.options.floor_deg},
        "stations": {str(d.station): {
            "dp_m": [float(x) for x in d.dp_m], "position_m": d.position_m,
            "rotation_rad": d.rotation_rad,
            "sigma_position_m": _finite(d.sigma_position_m),
            "sigma_rotation_rad": _finite(d.sigma_rotation_rad),
            "position_sigmas": _finite(d.position_sigmas),
            "rotation_sigmas": _finite(d.rotation_sigmas), "moved": bool(d.moved),
            "sigma_white_position_m": _finite(d.sigma_white_position_m),
            "sigma_white_rotation_rad": _finite(d.sigma_white_rotation_rad)}
            for d in c.differences},
        "only_in_a": c.only_in_a, "only_in_b": c.only_in_b,
        "moved": [d.station for d in c.moved], "verdict": c.verdict(),
    }, indent=2) + "\n"
