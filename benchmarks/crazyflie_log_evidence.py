"""What the shared Crazyflie LH1 log holds, from the raw events (docs/crazyflie.md):

1. station 0's "extra" sweeps: how the ``lhAngle`` events are grouped, how many are
   bit-identical copies of an earlier pair, and the rate of fresh values per station/sweep;
2. their timing against the LH1 slot pattern: delay from the deck's last raw pulse frame
   (``lhUartFrame``) to the logged group;
3. the Bitcraze -> ours calibration mapping: our correction of ``angle`` against the
   firmware's ``correctedAngle`` (and the identity mapping for contrast);
4. the deck geometry: distances between the diodes' crossing-beam positions (cfclient's
   geometry) against ``crazyflie_deck``.

    python -m benchmarks crazyflie_log_evidence

Writes docs/results/crazyflie_log_evidence.md.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks import prog
from benchmarks.crazyflie_evaluation import crossing_points, ray_directions
from lhgraph.importers.crazyflie import read_usd_log
from lhgraph.importers.crazyflie.sweeps import repeated_hits
from lhgraph.io.cfclient import read_system_config
from lhgraph.model.bitcraze import firmware_equivalent
from lhgraph.model.boards import crazyflie_deck
from lhgraph.model.station import FactoryCalibration, StationModel, ideal_from_measured

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "bitcraze-positioning" / "lh1_crossingBeam_move"


def groups(t: np.ndarray) -> np.ndarray:
    """Group index of every lhAngle event (a group spans < 1 ms; groups >= 15 ms apart)."""
    return np.r_[0, np.cumsum(np.diff(t) > 1e-3)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    parser.parse_args(argv)
    start = time.perf_counter()
    log = read_usd_log(DATA / "log02")
    config = read_system_config(DATA / "system-config.yaml")
    a, t = log.events["lhAngle"], log.time_s("lhAngle")
    g = groups(t)
    n = g.max() + 1
    table = np.full((n, 2, 2, 4), np.nan)
    table[g, a["basestation"], a["sweep"], a["sensor"]] = a["angle"]
    corr = np.full((n, 2, 2, 4), np.nan)
    corr[g, a["basestation"], a["sweep"], a["sensor"]] = a["correctedAngle"]
    t_group = np.bincount(g, weights=t) / np.bincount(g)
    has = np.any(np.isfinite(table), axis=(2, 3))
    only0 = has[:, 0] & ~has[:, 1]
    both = has[:, 0] & has[:, 1]
    out = ["# Crazyflie LH1 log: what the events hold", "",
           "`python -m benchmarks crazyflie_log_evidence` on the shared `log02` "
           "(docs/crazyflie.md).", "", "## 1. Station 0's extra sweeps", "",
           f"lhAngle events: {len(a)} in {n} groups; groups with station 0 only: "
           f"{only0.sum()}, with both stations: {both.sum()}, station 1 only: "
           f"{(has[:, 1] & ~has[:, 0]).sum()}.", ""]
    d = np.diff(t_group) * 1e3
    kind = np.where(only0[:-1], "0-only -> next", "both -> next")
    for k in ("0-only -> next", "both -> next"):
        out.append(f"- interval {k}: median {np.median(d[kind == k]):.1f} ms")
    # station 0's values in a both-stations group against the previous group's
    prev0 = np.flatnonzero(both[1:] & has[:-1, 0]) + 1
    same = np.all((table[prev0, 0] == table[prev0 - 1, 0])
                  | ~np.isfinite(table[prev0, 0]), axis=(1, 2))
    after_only0 = only0[prev0 - 1]
    out += ["", f"- station 0's pair in a both-stations group that directly follows a "
            f"station-0-only group: {after_only0.sum()}; of those bit-identical to it (angle, "
            f"every diode seen): {(same & after_only0).sum()}",
            f"- after a both-stations group: {(~after_only0).sum()}, identical: "
            f"{(same & ~after_only0).sum()}"]
    rep = repeated_hits(log)
    out += ["", "| station | sweep | hits | bit-identical repeats | fresh-value interval "
            "p5 / p50 / p95 (ms) |", "|---|---|---|---|---|"]
    for bs in (0, 1):
        for sw in (0, 1):
            sel = (a["basestation"] == bs) & (a["sweep"] == sw)
            dts = []
            for k in range(4):
                s = sel & (a["sensor"] == k) & ~rep
                dts.append(np.diff(t[s]))
            p = np.percentile(np.concatenate(dts) * 1e3, [5, 50, 95])
            out.append(f"| {bs} | {sw} | {sel.sum()} | {(sel & rep).sum()} | "
                       f"{p[0]:.1f} / {p[1]:.1f} / {p[2]:.1f} |")
    # 2. timing: delay from the last raw pulse frame to the group
    tu = log.time_s("lhUartFrame")
    first = np.r_[0, np.flatnonzero(np.diff(g)) + 1]
    i = np.searchsorted(tu, t[first]) - 1
    delay = (t[first] - tu[np.clip(i, 0, None)]) * 1e3
    out += ["", "## 2. Timing against the slot pattern", "",
            "Delay from the deck's last raw pulse frame to the logged group (ms), p5 / p50 / "
            "p95: station-0-only groups "
            + " / ".join(f"{x:.2f}" for x in np.percentile(delay[only0], [5, 50, 95]))
            + "; both-stations groups "
            + " / ".join(f"{x:.2f}" for x in np.percentile(delay[both], [5, 50, 95])) + "."]
    # 3. calibration mapping
    out += ["", "## 3. Our correction of `angle` against the firmware's `correctedAngle`", "",
            "Pairs of one group (fresh station data), residual |ours - correctedAngle| (µrad).",
            "", "| station | mapping | axis | p50 | p95 | p99 | pairs |",
            "|---|---|---|---|---|---|---|"]
    for bs in (0, 1):
        fresh = only0 if bs == 0 else both
        m = table[fresh, bs].transpose(0, 2, 1).reshape(-1, 2)
        c = corr[fresh, bs].transpose(0, 2, 1).reshape(-1, 2)
        ok = np.all(np.isfinite(m), axis=1)
        broadcast = config.calibrations[bs].calibration
        for name, cal in (("bitcraze -> ours, firmware's curve",
                           firmware_equivalent(broadcast)),
                          ("bitcraze -> ours, broadcast curve (default)", broadcast),
                          ("identity (none)", FactoryCalibration())):
            az, el = ideal_from_measured(m[ok, 0], m[ok, 1], StationModel(cal))
            for ax, v in ((0, az), (1, el)):
                r = np.abs(v - c[ok, ax]) * 1e6
                p = np.percentile(r, [50, 95, 99])
                out.append(f"| {bs} | {name} | {ax} | {p[0]:.1f} | {p[1]:.1f} | {p[2]:.1f} | "
                           f"{ok.sum()} |")
    # 4. deck geometry from per-diode crossing beams (fresh station-1 groups, station 0 of
    # the same group is at most one cycle old)
    P = []
    for k in range(4):
        rays = []
        for bs in (0, 1):
            T = config.T_world_lh[bs]
            d = ray_directions(corr[both, bs, 0, k], corr[both, bs, 1, k]) @ T[:3, :3].T
            rays.append((np.broadcast_to(T[:3, 3], d.shape), d))
        P.append(crossing_points(*rays[0], *rays[1])[0])
    P = np.stack(P)
    deck = crazyflie_deck().positions
    out += ["", "## 4. Deck geometry", "",
            "Distance between diodes' crossing-beam positions (cfclient geometry, "
            "correctedAngle), median over groups with both stations, against `crazyflie_deck`"
            " (mm):", "", "| diodes | measured | crazyflie_deck |", "|---|---|---|"]
    for i in range(4):
        for j in range(i + 1, 4):
            dist = np.linalg.norm(P[i] - P[j], axis=1)
            out.append(f"| {i}-{j} | {np.nanmedian(dist) * 1e3:.1f} | "
                       f"{np.linalg.norm(deck[i] - deck[j]) * 1e3:.1f} |")
    out += ["", f"Run time: {time.perf_counter() - start:.1f} s.", ""]
    path = ROOT / "docs/results/crazyflie_log_evidence.md"
    path.write_text("\n".join(out))
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
