# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # The paper's pipeline vs the factor graph, on the same simulated captures
#
# Simulate a few captures of the paper's protocol (`configs/paper_simulation.toml`, cut to
# 2 s so this runs in CI), calibrate each with both methods and compare the errors against
# the simulation's truth: signed errors per capture, the paper's Table III statistics, and
# the residuals of one capture. Python API only (what `lhgraph study` does at scale).

# %%
import dataclasses
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lhgraph.estimation.baseline import PaperOptions
from lhgraph.sim.simulate import paper_protocol, simulate
from lhgraph.workflow.solve import solve
from lhgraph.workflow.study import protocol_statistics, signed_errors, table_iii_markdown

REPO = Path.cwd().parent if Path.cwd().name == "notebooks" else Path.cwd()
CAPTURES = 2        # first captures of the protocol
DURATION_S = 2.0    # seconds each (the paper used 8 s captures)
cases = [(name, dataclasses.replace(config, duration_s=DURATION_S))
         for name, config in paper_protocol(REPO / "configs/paper_simulation.toml")[:CAPTURES]]
[(name, config.layout.distance_m, config.motion.speed_mps) for name, config in cases]

# %% [markdown]
# Solve every capture with both methods. The paper's method runs with warm-started board
# pose fits (faster; docs/baseline.md).

# %%
rows, results = [], {}
for name, config in cases:
    sim = simulate(config)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    for method in ("graph", "paper"):
        result = solve(sim.board, sim.angles, method, models,
                       paper_options=PaperOptions(warm_start=True))
        results[name, method] = (sim, result)
        err = signed_errors(sim.truth, result.stations)[0]
        rows.append({"capture": name, "method": method, "signed": err,
                     "position_mm": float(np.linalg.norm(err[:3])),
                     "rms_urad": result.residuals.rms_urad(),
                     "seconds": sum(result.timings_s.values())})
for r in rows:
    print(f"{r['capture']:>14} {r['method']:>5}: |p| {r['position_mm']:8.3f} mm, "
          f"residual rms {r['rms_urad']:8.1f} urad")

# %% [markdown]
# ## Table III layout (MAE and average per-setup SD of the signed errors)

# %%
stats = {m: protocol_statistics([r["capture"] for r in rows if r["method"] == m],
                                [r["signed"] for r in rows if r["method"] == m])
         for m in ("graph", "paper")}
print("\n".join(table_iii_markdown(stats)))

# %% [markdown]
# ## Errors side by side

# %%
fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
x = np.arange(len(cases))
for i, method in enumerate(("graph", "paper")):
    errs = np.array([r["signed"] for r in rows if r["method"] == method])
    axes[0].bar(x + 0.4 * i, np.linalg.norm(errs[:, :3], axis=1), 0.4, label=method)
    axes[1].bar(x + 0.4 * i, np.abs(errs[:, 3:]).max(axis=1), 0.4, label=method)
for ax, label in zip(axes, ("position error (mm)", "max |Euler error| (deg)"), strict=True):
    ax.set_xticks(x + 0.2, [n for n, _ in cases], rotation=20)
    ax.set_ylabel(label)
    ax.set_yscale("log")
    ax.legend()
fig.tight_layout()

# %% [markdown]
# ## Residuals of the first capture
#
# The graph fits every hit with the full moving-board model; the paper's pipeline fits one
# rigid pose per measurement, so the board's motion during a sweep pair is left in its
# residuals.

# %%
fig, axes = plt.subplots(1, 2, figsize=(10, 3))
for ax, method in zip(axes, ("graph", "paper"), strict=True):
    res = results[cases[0][0], method][1].residuals
    ax.hist(np.clip(res.residual_rad * 1e6, -1000, 1000), bins=80)
    ax.set_title(f"{method}: rms {res.rms_urad():.0f} urad")
    ax.set_xlabel("residual (urad, clipped to +-1000)")
fig.tight_layout()
