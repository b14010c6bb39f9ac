"""Tracking with the stations held fixed (`lhgraph track`): error against the simulator's
truth, batch and streaming, and time per sync cycle.

    python -m benchmarks track_benchmark [--output docs/results/track.md] [--force]

Captures (the true stations and factory calibration given to the tracker):
1. the 32-diode board on the default layout (8 s, 0.5 m/s, quantisation only), 3 seeds;
2. the Crazyflie deck (4 diodes) on the default layout, 20 s, 30 % of hits dropped (exact hit
   times), 2 seeds;
3. the deck with the character of a real deck log (configs/simulation/deck.toml: 1.5 m/s
   hand-held, 24 MHz timing, 65 µrad noise, factory calibration, half the cycles logged,
   18 % of sweeps losing one half of the deck), first 40 s: (a) its hits re-timed from the
   log stamps by the slot pattern (what an importer gives: the per-cycle stamp jitter
   remains), (b) the log stamps taken as hit times (both sweeps of a cycle at one instant).

Errors: board-origin position |p_est - p_true| per state (mm) and rotation angle (deg);
`err/sigma`: median of the position error over the reported `sigma_m`. Streaming: every state
as estimated in the update that added it (filtered), the warm-up's states from its batch.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import dataclasses
import os
import platform
import time
from pathlib import Path

import numpy as np

from benchmarks import command, prog
from lhgraph.estimation.graph.streaming import track_stream
from lhgraph.estimation.graph.track import TrackedPath, track
from lhgraph.geometry.transforms import rotation_angle
from lhgraph.io.angles import Angles
from lhgraph.io.files import check_writable, write_atomic
from lhgraph.sim.simulate import (
    SimulatedCapture,
    default_simulation_config,
    load_simulation_config,
    simulate,
)

ROOT = Path(__file__).resolve().parent.parent


def retimed(cap: SimulatedCapture) -> Angles:
    """The deck log's stamps turned back into hit times by the slot pattern: a cycle is
    stamped ``latency_ms`` after its axis-1 sweep's centre, axis 0 was swept one slot before,
    and a hit lies ``angle T / 2 pi`` from its sweep's centre (per-cycle jitter and the events'
    spacing remain as timing error)."""
    a = cap.angles
    period = cap.slots.period_samples / cap.config.sample_rate_hz
    time_s = (a.time - cap.config.logging.latency_ms * 1e-3 - (1 - a.axis) * period / 2
              + a.angle * period / (2 * np.pi))
    order = np.argsort(time_s, kind="stable")
    return Angles(time_s[order], a.lighthouse[order], a.axis[order], a.sensor[order],
                  a.angle[order])


def errors(cap: SimulatedCapture, path: TrackedPath) -> dict:
    truth = cap.trajectory.at(path.trajectory.time)
    est = path.trajectory.T_world_board
    pos = np.linalg.norm(est[:, :3, 3] - truth[:, :3, 3], axis=1) * 1e3
    rot = np.degrees(rotation_angle(np.swapaxes(truth[:, :3, :3], 1, 2) @ est[:, :3, :3]))
    return {"median": np.median(pos), "p95": np.percentile(pos, 95), "max": pos.max(),
            "rot": np.median(rot), "z": np.median(pos / (path.sigma_m * 1e3))}


def run(name: str, cap: SimulatedCapture, angles: Angles, streaming: bool = True) -> list[dict]:
    """Batch and streaming rows of one capture."""
    tic = time.perf_counter()
    batch = track(cap.board, angles, cap.truth)
    seconds = time.perf_counter() - tic
    duration = angles.time[-1] - angles.time[0]
    per_sweep = np.bincount(angles.sweep_ids())
    rows = [{"name": name, "mode": "batch", **errors(cap, batch.path),
             "time": f"{seconds:.1f} s ({seconds / duration * 1e3 / 30:.1f} ms per cycle), "
                     f"{batch.iterations} it., {batch.status}",
             "states": len(batch.path.hits), "pnp": batch.initialised,
             "hits": f"{np.median(per_sweep):.0f}, {np.mean(per_sweep <= 3) * 100:.0f} %"}]
    if streaming:
        tic = time.perf_counter()
        estimates = list(track_stream(cap.board, angles, cap.truth))
        seconds = time.perf_counter() - tic
        update = np.array([e.update_s for e in estimates[1:-1]]) * 1e3
        rows.append({"name": name, "mode": "streaming",
                     **errors(cap, TrackedPath.concatenate([e.path for e in estimates if e.path])),
                     "time": f"update median {np.median(update):.1f} ms, p95 "
                             f"{np.percentile(update, 95):.1f} ms, max {update.max():.0f} ms "
                             f"(warm-up {estimates[0].update_s:.2f} s; {seconds:.1f} s)",
                     "states": rows[0]["states"], "pnp": "", "hits": ""})
    for r in rows:
        print(f"{r['name']} {r['mode']}: median {r['median']:.3f} mm, {r['time']}", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--output", default=str(ROOT / "docs/results/track.md"))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    start = time.perf_counter()
    default = default_simulation_config()
    deck = dataclasses.replace(default, board="crazyflie_deck", duration_s=20.0,
                               noise=dataclasses.replace(default.noise, dropout_fraction=0.3))
    real = dataclasses.replace(load_simulation_config(ROOT / "configs/simulation/deck.toml"),
                               duration_s=40.0)
    rows = []
    for seed in (1, 2, 3):
        cap = simulate(default, seed)
        rows += run(f"32-diode board, seed {seed}", cap, cap.angles)
    for seed in (1, 2):
        cap = simulate(deck, seed)
        rows += run(f"deck, 30 % dropped, seed {seed}", cap, cap.angles)
    cap = simulate(real)
    rows += run("deck.toml 40 s, re-timed", cap, retimed(cap))
    rows += run("deck.toml 40 s, log stamps", cap, cap.angles, streaming=False)
    lines = ["# Tracking with the stations held fixed: measured accuracy and speed", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}; {time.strftime('%Y-%m-%d')}; run time "
             f"{time.perf_counter() - start:.0f} s", "",
             "Position error of the board origin per state against the simulator's truth "
             "(mm), rotation error (deg), `err/sigma` = median error over the reported "
             "`sigma_m`. `hits`: median diodes per sweep, and the share of sweeps with at most 3; "
             "`PnP`: poses the start was made of. Streaming: each state as estimated 0.1 s "
             "after it (`--delay`, the default).", "",
             "| capture | mode | states | hits | PnP | median | p95 | max | rotation | "
             "err/sigma | time |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['name']} | {r['mode']} | {r['states']} | {r['hits']} | {r['pnp']} | "
                     f"{r['median']:.3f} | {r['p95']:.3f} | {r['max']:.2f} | {r['rot']:.3f} | "
                     f"{r['z']:.2f} | {r['time']} |")
    write_atomic(out, ("\n".join(lines) + "\n").encode(), args.force)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
