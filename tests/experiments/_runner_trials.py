"""Trial functions for ``test_runner.py``, in a module that spawned workers can import.

Process-pool workers are started with "spawn" and inherit ``sys.path``, so this module is found
by the name pytest imported it under. The kill test runs :func:`run_resume_study` in a
subprocess with ``RUNNER_TRIAL_SLEEP_S`` set, to slow each trial down.
"""

from __future__ import annotations

import os
import time

import numpy as np

from lts360.experiments.runner import TrialOutput, grid_params, plan_trials, run_study

N_SAMPLES = 5
IMAGE_SHAPE = (2, 3)
#: Seconds each trial of :func:`noisy_trial` sleeps (environment variable, default 0).
SLEEP_ENV = "RUNNER_TRIAL_SLEEP_S"


def noisy_trial(trial):
    """A seeded normal vector and image, a closed-form scalar from the params, an int count."""
    delay_s = float(os.environ.get(SLEEP_ENV, "0"))
    if delay_s > 0:
        time.sleep(delay_s)
    rng = np.random.default_rng(trial.seed)
    p = trial.params
    return TrialOutput(
        values={"noise_mm": rng.normal(size=N_SAMPLES), "image": rng.random(IMAGE_SHAPE),
                "sum_deg": expected_sum_deg(p), "n_hits": 2 * trial.index},
        dims={"noise_mm": ("sample",), "image": ("row", "col")},
        coords={"sample": np.arange(N_SAMPLES) * 0.5})


def expected_sum_deg(params) -> float:
    return params["alpha_deg"] + 0.5 * params["beta_deg"]


def pid_trial(trial):
    """:func:`noisy_trial` plus the id of the process that ran it (``pid``)."""
    out = noisy_trial(trial)
    return TrialOutput(values={**out.values, "pid": os.getpid()}, dims=out.dims,
                       coords=out.coords)


def crashes_on_trial_3(trial):
    """Like :func:`noisy_trial`, but trial 3 raises (a renderer crash, say)."""
    if trial.index == 3:
        raise RuntimeError("simulated renderer crash")
    return noisy_trial(trial)


def returns_a_dict(trial):
    """Breaks the contract: returns a plain dict instead of a TrialOutput."""
    return {"sum_deg": 1.0}


def resume_trials():
    """12 trials: 3 alpha × 4 beta."""
    return plan_trials(grid_params(alpha_deg=[30.0, 35.0, 40.0],
                                   beta_deg=[80.0, 85.0, 90.0, 95.0]), seed=2024)


def run_resume_study(out_dir):
    """The study the kill test interrupts (one process, sequential)."""
    return run_study(out_dir, resume_trials(), noisy_trial, name="resume", workers=1,
                     progress=False)


def threads_trial(trial):
    """:func:`noisy_trial` plus what the worker's native pools and block loops use: the
    fewest and most threads of its BLAS libraries, the sensor's block threads and Dr.Jit's."""
    import drjit
    from threadpoolctl import threadpool_info

    from lts360.simulator.sensor import block_threads

    out = noisy_trial(trial)
    blas = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return TrialOutput(values={**out.values, "blas_min": min(blas), "blas_max": max(blas),
                               "blocks": block_threads(), "drjit": drjit.thread_count()},
                       dims=out.dims, coords=out.coords)
