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
# # The attitude estimation workshop, step by step
#
# A spacecraft tumbles freely; a 100 Hz gyro and a 5 Hz star tracker watch it;
# we estimate its attitude three ways and tune the best one. This script opens
# as a notebook (Jupyter with jupytext, or VS Code) and runs top to bottom as
# plain `python`. Figures are saved to `OUT` and shown inline in a notebook.
#
# Set `ATTITUDE_BENCH_TSTOP` to shorten the simulated time (the workshop's is
# 50 s) and `ATTITUDE_BENCH_OUT` to choose where files go.

# %%
import os
from pathlib import Path

import numpy as np

from benchmarks import Scenario, error_statistics, simulate
from benchmarks.experiments import sweep
from benchmarks.experiments.landscape import compute_landscape, landscape_figure, pc_grid
from benchmarks.output import write_figure
from benchmarks.figures.plots import comparison_figure
from benchmarks.experiments.tuning import format_iteration_table, tune_pc_exponent

TSTOP = float(os.environ.get("ATTITUDE_BENCH_TSTOP", "50"))
OUT = Path(os.environ.get("ATTITUDE_BENCH_OUT", "results/notebook"))
SEED = 0
scenario = Scenario(tstop=TSTOP)
scenario.as_dict()

# %% [markdown]
# ## 1–2. The truth, and dead reckoning
# Integrating the gyro alone drifts as an angle random walk: after `t` seconds
# each axis has wandered by about `sqrt(gyro_noise * t)` radians.

# %%
result = simulate(scenario, ["dead-reckoning"], seed=SEED)
figure = comparison_figure(result.time_s, {"Dead Reckoning": result.error_deg["dead-reckoning"]})
write_figure(OUT / "dead_reckoning.png", figure)
expected_final_deg = np.degrees(np.sqrt(3 * scenario.gyro_noise * TSTOP))
print(f"final error {result.error_deg['dead-reckoning'][-1]:.3f} deg; "
      f"RMS expected from the random walk {expected_final_deg:.3f} deg")
figure

# %% [markdown]
# ## 3. Activity 1: a noisier gyro

# %%
rows = sweep(scenario, "dead-reckoning", "gyro-noise", [1e-5, 1e-4], SEED, OUT / "activity1",
             quiet=True)
for row in rows:
    print(f"gyro noise {row['value']:g}: std {row['std_deg']:.4f} deg")

# %% [markdown]
# ## 4–6. Star tracker resets and the EKF, on the same data

# %%
result = simulate(scenario, seed=SEED)
curves = {result.labels[name]: error for name, error in result.error_deg.items()}
figure = comparison_figure(result.time_s, curves)
write_figure(OUT / "compare.png", figure)
for name, error in result.error_deg.items():
    print(f"{name:<22} std {error_statistics(error)['std_deg']:.4f} deg")
figure

# %% [markdown]
# ## 5. Activity 2: fewer star tracker readings

# %%
rows = sweep(scenario, "dead-reckoning-resets", "time-between-measurements", [0.2, 1.0, 5.0],
             SEED, OUT / "activity2", quiet=True)
for row in rows:
    print(f"every {row['value']:g} s: std {row['std_deg']:.4f} deg")

# %% [markdown]
# ## 7. Activity 3a: the process covariance by hand

# %%
rows = sweep(scenario, "ekf", "pc-exponent", [-8.7, -10.9], SEED, OUT / "activity3a", quiet=True)
for row in rows:
    print(f"pc exponent {row['value']:g}: std {row['std_deg']:.4f} deg")

# %% [markdown]
# ## 8. Activity 3b: `fminbnd` on [-16, 0]

# %%
tuned = tune_pc_exponent(scenario, seeds=(SEED,), quiet=True)
print(format_iteration_table(tuned.iterations))
print(tuned.message)
print(f"pc_exponent = {tuned.pc_exponent:.4f}, loss = {tuned.loss_deg:.6f} deg")

# %% [markdown]
# ## 9. The loss landscape

# %%
landscape = compute_landscape(scenario, pc_grid(-18, 0, 0.5), seeds=(SEED,), quiet=True)
figure = landscape_figure(landscape)
write_figure(OUT / "landscape.png", figure)
print(f"lowest error std at pc_exponent = {landscape.best_pc_exponent:g}")
figure
