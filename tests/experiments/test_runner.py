"""The study runner: plans, storage, resumption after kill -9, pools and Dask give the same numbers.

Results are compared exactly (``assert_identical``): every trial draws from its own seed and does
the same float64 operations wherever it runs, so no tolerance is needed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import _runner_trials as trials_mod
import numpy as np
import pytest
import xarray as xr

import lts360
from lts360.experiments.runner import (
    THREAD_ENV,
    Trial,
    TrialError,
    TrialOutput,
    grid_params,
    plan_trials,
    run_study,
    study_pool,
    to_grid,
    trial_path,
)

ALPHAS_DEG = [30.0, 40.0]
BETAS_DEG = [80.0, 85.0, 90.0]
STUDY_SEED = 7


def small_plan():
    return plan_trials(grid_params(alpha_deg=ALPHAS_DEG, beta_deg=BETAS_DEG), seed=STUDY_SEED)


def run(out_dir, trials=None, fn=trials_mod.noisy_trial, **kw):
    kw = {"name": "small", "workers": 1, "progress": False, **kw}
    return run_study(out_dir, small_plan() if trials is None else trials, fn, **kw)


def trial_files(out_dir) -> list[str]:
    return sorted(p.name for p in (Path(out_dir) / "trials").iterdir())


def stamps(out_dir) -> dict[str, tuple[int, int]]:
    """(inode, mtime) of every trial file, to tell a kept file from a rewritten one."""
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns)
            for p in (Path(out_dir) / "trials").glob("trial_*.nc")}


# --- the plan -----------------------------------------------------------------------------------


def test_seeds_depend_only_on_study_seed_and_index():
    params = grid_params(x=range(10))
    seeds = [t.seed for t in plan_trials(params, seed=11)]
    assert [t.seed for t in plan_trials(params[:4], seed=11)] == seeds[:4]
    assert [t.seed for t in plan_trials(params, seed=11)] == seeds
    assert len(set(seeds)) == 10 and set(seeds).isdisjoint(t.seed for t in plan_trials(params, 12))
    child = np.random.SeedSequence(11).spawn(10)[6]
    assert seeds[6] == int(child.generate_state(1)[0])
    assert [t.index for t in plan_trials(params, 11)] == list(range(10))


def test_grid_params_last_axis_fastest():
    grid = grid_params(alpha_deg=[30, 40], beta_deg=[80, 90], mode=["a", "b"])
    assert len(grid) == 8
    assert grid[0] == {"alpha_deg": 30, "beta_deg": 80, "mode": "a"}
    assert grid[1] == {"alpha_deg": 30, "beta_deg": 80, "mode": "b"}
    assert grid[2] == {"alpha_deg": 30, "beta_deg": 90, "mode": "a"}
    assert grid[4] == {"alpha_deg": 40, "beta_deg": 80, "mode": "a"}
    # numpy scalars become Python scalars, so that the plan is JSON.
    assert type(grid_params(x=np.array([1.5]))[0]["x"]) is float
    with pytest.raises(ValueError, match="'mode'"):
        grid_params(mode="ab")
    with pytest.raises(ValueError, match="empty"):
        grid_params(x=[])


def test_invalid_trials_and_outputs_are_refused(tmp_path):
    with pytest.raises(ValueError, match="param 'x'"):
        Trial(0, {"x": [1, 2]}, 3)
    with pytest.raises(ValueError, match="reserved|other than"):
        Trial(0, {"seed": 1}, 3)
    with pytest.raises(ValueError, match="dims must name 1"):
        TrialOutput(values={"v": np.zeros(3)})
    with pytest.raises(ValueError, match="coord 'u'"):
        TrialOutput(values={"v": np.zeros(3)}, dims={"v": ("x",)}, coords={"u": [1, 2, 3]})
    with pytest.raises(ValueError, match="indices must be 0"):
        run_study(tmp_path, small_plan()[1:], trials_mod.noisy_trial, name="x", workers=1)


# --- running and storing ------------------------------------------------------------------------


def test_sequential_study_is_stored_and_combined(tmp_path):
    ds = run(tmp_path, attrs={"note": "test"})
    plan = small_plan()
    assert dict(ds.sizes) == {"trial": 6, "sample": 5, "row": 2, "col": 3}
    assert ds["noise_mm"].dims == ("trial", "sample") and ds["image"].dims == ("trial", "row", "col")
    assert ds["sum_deg"].dims == ("trial",) and ds["n_hits"].dtype == np.int64
    np.testing.assert_array_equal(ds["trial"], np.arange(6))
    np.testing.assert_array_equal(ds["alpha_deg"], [30.0] * 3 + [40.0] * 3)
    np.testing.assert_array_equal(ds["beta_deg"], BETAS_DEG * 2)
    np.testing.assert_array_equal(ds["seed"], [t.seed for t in plan])
    np.testing.assert_array_equal(ds["sample"], np.arange(5) * 0.5)
    for t in plan:
        rng = np.random.default_rng(t.seed)
        np.testing.assert_array_equal(ds["noise_mm"][t.index], rng.normal(size=5))
        np.testing.assert_array_equal(ds["image"][t.index], rng.random((2, 3)))
        assert ds["sum_deg"][t.index] == trials_mod.expected_sum_deg(t.params)
    assert ds.attrs["name"] == "small" and ds.attrs["n_trials"] == 6 and ds.attrs["note"] == "test"

    assert trial_files(tmp_path) == [f"trial_{i:06d}.nc" for i in range(6)]
    stored = xr.load_dataset(trial_path(tmp_path, 4))
    assert stored.attrs["trial_index"] == 4 and stored.attrs["trial_seed"] == plan[4].seed
    xr.testing.assert_identical(xr.load_dataset(tmp_path / "results.nc"), ds)

    # Everything is done: a second call runs nothing (this function would fail) and rewrites
    # results.nc, which the returned dataset must not hold open.
    again = run(tmp_path, fn=trials_mod.returns_a_dict, attrs={"note": "test"})
    xr.testing.assert_identical(again, ds)


@pytest.mark.slow
def test_process_pool_gives_the_sequential_results(tmp_path):
    sequential = run(tmp_path / "one")
    pooled = run(tmp_path / "two", workers=2)
    xr.testing.assert_identical(pooled, sequential)


@pytest.mark.slow
def test_one_pool_serves_every_call_of_a_study(tmp_path):
    """The batches of a study share one pool: the same two worker processes run every trial of
    three calls (one failing in between), with the sequential run's values."""
    with study_pool(workers=2) as pool:
        first = run(tmp_path / "a", fn=trials_mod.pid_trial, workers=2, pool=pool)
        with pytest.raises(TrialError, match="trial 3 of study 'small' failed"):
            run(tmp_path / "fails", fn=trials_mod.crashes_on_trial_3, workers=2, pool=pool)
        second = run(tmp_path / "b", fn=trials_mod.pid_trial, workers=2, pool=pool)
    pids = set(first["pid"].values.tolist()) | set(second["pid"].values.tolist())
    assert len(pids) <= 2 and os.getpid() not in pids
    assert pool._processes is None or not pool._processes, "the pool was not shut down"
    sequential = run(tmp_path / "one")
    xr.testing.assert_identical(first.drop_vars("pid"), sequential)
    xr.testing.assert_identical(second.drop_vars("pid"), sequential)


def test_pool_workers_share_the_cores_with_their_native_threads(tmp_path, monkeypatch):
    """Each of w workers caps BLAS (numpy's and scipy's OpenBLAS), Dr.Jit and the sensor's
    block loops at its share of the cores, cpu // w (uncapped, their spinning threads took a quarter of a
    Monte Carlo trial's CPU); a thread count the user set is left alone."""
    for name in THREAD_ENV:
        monkeypatch.delenv(name, raising=False)
    share = max(1, (os.cpu_count() or 1) // 2)
    ds = run(tmp_path / "capped", fn=trials_mod.threads_trial, workers=2)
    assert set(ds["blas_max"].values.tolist()) == {share}
    assert set(ds["blas_min"].values.tolist()) == {share}
    assert set(ds["blocks"].values.tolist()) == {share}
    assert set(ds["drjit"].values.tolist()) == {share}
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    ds = run(tmp_path / "user", fn=trials_mod.threads_trial, workers=2)
    assert set(ds["blocks"].values.tolist()) == {3}


def test_block_threads_follow_omp_num_threads(monkeypatch):
    from lts360.simulator.sensor import block_threads

    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert block_threads() == 1
    for bad in ("0", "two", ""):
        monkeypatch.setenv("OMP_NUM_THREADS", bad)
        assert block_threads() == (os.cpu_count() or 1)
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert block_threads() == (os.cpu_count() or 1)


def test_study_pool_is_local_processes_only(tmp_path):
    with study_pool(workers=1) as pool:
        assert pool is None
    with study_pool(dask_address="tcp://127.0.0.1:1") as pool:
        assert pool is None
    with pytest.raises(ValueError, match="workers must be an int"):
        with study_pool(workers=0):
            pass
    with pytest.raises(ValueError, match="either pool or dask_address"):
        run(tmp_path, workers=None, dask_address="tcp://127.0.0.1:1", pool=object())
    assert not (tmp_path / "plan.json").exists()


def test_resume_after_kill_9(tmp_path):
    n = len(trials_mod.resume_trials())
    killed = tmp_path / "killed"
    src = Path(lts360.__file__).parents[1]
    code = ("import sys; sys.path[:0] = [{!r}, {!r}]; import _runner_trials as m; "
            "m.run_resume_study({!r})").format(str(Path(__file__).parent), str(src), str(killed))
    env = {**os.environ, trials_mod.SLEEP_ENV: "0.2"}
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while len(list(killed.glob("trials/trial_*.nc"))) < 3:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the study did not start"
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    done_before = stamps(killed)
    assert 3 <= len(done_before) < n
    # What an interrupted write leaves, and a file of the wrong trial.
    (killed / "trials" / ".trial_000010.tmp.nc").write_bytes(b"\x89HDF\r\n\x1a\n partial")
    wrong = trial_path(killed, n - 1)
    wrong.write_bytes(trial_path(killed, 0).read_bytes())

    resumed = trials_mod.run_resume_study(killed)
    reference = trials_mod.run_resume_study(tmp_path / "uninterrupted")

    assert trial_files(killed) == [f"trial_{i:06d}.nc" for i in range(n)]
    np.testing.assert_array_equal(resumed["trial"], np.arange(n))
    xr.testing.assert_identical(resumed, reference)
    after = stamps(killed)
    assert all(after[name] == stamp for name, stamp in done_before.items()), "a done trial re-ran"


def test_a_different_plan_in_the_same_directory_is_refused(tmp_path):
    run(tmp_path)
    with pytest.raises(ValueError, match="different study: 6 trials there, 4 now"):
        run(tmp_path, trials=small_plan()[:4])
    with pytest.raises(ValueError, match="different study: trial 0 is"):
        run(tmp_path, trials=plan_trials(grid_params(alpha_deg=ALPHAS_DEG, beta_deg=BETAS_DEG),
                                         seed=STUDY_SEED + 1))
    with pytest.raises(ValueError, match="different study: name 'small' there, 'other' now"):
        run(tmp_path, name="other")


@pytest.fixture(scope="module")
def dask_address():
    """Scheduler address of an in-process Dask cluster (one worker thread)."""
    distributed = pytest.importorskip("distributed", reason="the Dask cluster path needs dask.distributed (test extras)")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        yield cluster.scheduler_address


@pytest.fixture(params=["sequential", pytest.param("pool", marks=pytest.mark.slow), "dask"])
def executor(request) -> dict:
    """run_study keywords of each way to run trials."""
    if request.param == "dask":
        return {"workers": None, "dask_address": request.getfixturevalue("dask_address")}
    return {"workers": 1 if request.param == "sequential" else 2}


def test_failing_trial_keeps_finished_trials_and_reruns(tmp_path, executor):
    with pytest.raises(TrialError, match="trial 3 of study 'small' failed") as info:
        run(tmp_path, fn=trials_mod.crashes_on_trial_3, **executor)
    assert info.value.index == 3 and isinstance(info.value.__cause__, RuntimeError)
    kept = trial_files(tmp_path)
    assert "trial_000003.nc" not in kept and not (tmp_path / "results.nc").exists()
    if executor["workers"] == 1:
        assert kept == [f"trial_{i:06d}.nc" for i in range(3)]
    else:  # trials running beside the failed one may finish too
        assert set(kept) <= {f"trial_{i:06d}.nc" for i in range(6)}
    before = stamps(tmp_path)

    fixed = run(tmp_path, **executor)
    assert all(stamps(tmp_path)[name] == stamp for name, stamp in before.items())
    xr.testing.assert_identical(fixed, run(tmp_path / "reference"))


def test_invalid_output_is_a_trial_error(tmp_path):
    with pytest.raises(TrialError, match="trial 0 .*must return a TrialOutput"):
        run(tmp_path, fn=trials_mod.returns_a_dict)
    assert trial_files(tmp_path) == []


def test_dask_cluster_gives_the_sequential_results(tmp_path, dask_address):
    on_dask = run(tmp_path / "dask", workers=None, dask_address=dask_address)
    xr.testing.assert_identical(on_dask, run(tmp_path / "local"))


# --- analysis -----------------------------------------------------------------------------------


def test_to_grid_reshapes_a_2x3_study(tmp_path):
    ds = run(tmp_path)
    grid = to_grid(ds, "alpha_deg", "beta_deg")
    assert dict(grid.sizes) == {"alpha_deg": 2, "beta_deg": 3, "sample": 5, "row": 2, "col": 3}
    assert grid["noise_mm"].dims == ("alpha_deg", "beta_deg", "sample")
    np.testing.assert_array_equal(grid["alpha_deg"], ALPHAS_DEG)
    np.testing.assert_array_equal(grid["beta_deg"], BETAS_DEG)
    np.testing.assert_array_equal(grid["trial"], np.arange(6).reshape(2, 3))
    for i, a in enumerate(ALPHAS_DEG):
        for j, b in enumerate(BETAS_DEG):
            k = 3 * i + j
            assert grid["sum_deg"][i, j] == trials_mod.expected_sum_deg({"alpha_deg": a,
                                                                         "beta_deg": b})
            np.testing.assert_array_equal(grid["noise_mm"][i, j], ds["noise_mm"][k])
            assert grid["seed"][i, j] == ds["seed"][k]
    transposed = to_grid(ds, "beta_deg", "alpha_deg")
    np.testing.assert_array_equal(transposed["trial"], np.arange(6).reshape(2, 3).T)
    with pytest.raises(ValueError, match="do not form a grid"):
        to_grid(ds, "beta_deg")
    with pytest.raises(ValueError, match="'gamma_deg' is not a coordinate"):
        to_grid(ds, "gamma_deg")
