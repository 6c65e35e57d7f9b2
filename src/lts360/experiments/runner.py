"""Studies of independent trials: plan, run locally or on Dask, store atomically, resume, combine.

A *study* is a list of :class:`Trial` (parameters + seed). :func:`run_study` calls a trial
function on every trial, writes each finished trial to its own NetCDF file and combines them
into one :class:`xarray.Dataset` along a ``trial`` dimension. The on-disk layout is::

    out_dir/plan.json                  study name, trial list and fingerprint
    out_dir/trials/trial_000042.nc     one finished trial (written atomically)
    out_dir/results.nc                 all trials along ``trial`` (written at the end)

A study interrupted at any point (even ``kill -9``) is finished by calling :func:`run_study`
again with the same arguments: trials already on disk are kept, the others are run, and the
result is identical to that of an uninterrupted run, whatever the number of workers.

>>> trials = plan_trials(grid_params(alpha_deg=[30, 40], beta_deg=[80, 90]), seed=1)
>>> ds = run_study("out/angles", trials, my_trial, name="angles")  # doctest: +SKIP
>>> to_grid(ds, "alpha_deg", "beta_deg")["rms_mm"].plot()          # doctest: +SKIP
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import hashlib
import itertools
import json
import logging
import multiprocessing
import os
import pickle
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import xarray as xr
from tqdm import tqdm

from lts360.simulator.io import atomic_path, write_json

if TYPE_CHECKING:
    from lts360.scenes.objects import SceneObject
    from lts360.scenes.rig import Rig

__all__ = ["Trial", "TrialOutput", "TrialError", "plan_trials", "grid_params", "run_study",
           "study_pool", "to_grid", "trial_path", "trial_setup"]

logger = logging.getLogger(__name__)

#: Names the runner gives to the combined dataset; params and output variables may not use them.
RESERVED_NAMES = frozenset({"trial", "seed"})
#: NetCDF engine of every file the runner writes (variable-length strings, bools via xarray).
ENGINE = "netcdf4"
#: Value kinds a trial output may hold: bool, signed and unsigned int, float.
_VALUE_KINDS = "biuf"
_PARAM_TYPES = (bool, int, float, str)


# --- the plan -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Trial:
    """One independent trial of a study.

    Parameters
    ----------
    index : int, >=0
        Position in the plan, ``0 .. n-1``; names the trial's file.
    params : dict[str, bool | int | float | str]
        The trial's parameters, JSON-serialisable scalars; numpy scalars are converted to Python
        scalars. Units belong in the names (``alpha_deg``, ``noise_mm``).
    seed : int, >=0
        Root seed of the trial's random streams, e.g. ``np.random.default_rng(trial.seed)``.
    """

    index: int
    params: dict
    seed: int

    def __post_init__(self) -> None:
        if not _is_int(self.index) or self.index < 0:
            raise ValueError(f"Trial.index must be an int >= 0, got {self.index!r}")
        if not _is_int(self.seed) or self.seed < 0:
            raise ValueError(f"Trial.seed must be an int >= 0, got {self.seed!r}")
        object.__setattr__(self, "index", int(self.index))
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "params", _check_params(self.params, f"trial {self.index}"))


def plan_trials(params: Sequence[dict], seed: int) -> list[Trial]:
    """Trials for the given parameter sets, with independent seeds.

    Parameters
    ----------
    params : sequence of dict
        Parameters of each trial, in plan order (see :func:`grid_params`).
    seed : int, >=0
        Root seed of the study.

    Returns
    -------
    list of Trial
        Trial ``i`` has ``params[i]`` and the seed
        ``int(np.random.SeedSequence(seed).spawn(n)[i].generate_state(1)[0])``, which depends only
        on ``(seed, i)``: appending trials to a plan does not change the seeds of the others.
    """
    if not _is_int(seed) or seed < 0:
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    children = np.random.SeedSequence(int(seed)).spawn(len(params))
    return [Trial(i, p, int(child.generate_state(1)[0]))
            for i, (p, child) in enumerate(zip(params, children))]


def grid_params(**axes: Sequence) -> list[dict]:
    """Cartesian product of named parameter axes, the last axis varying fastest.

    >>> grid_params(alpha_deg=[30, 40], beta_deg=[80, 90])
    [{'alpha_deg': 30, 'beta_deg': 80}, {'alpha_deg': 30, 'beta_deg': 90}, {'alpha_deg': 40, 'beta_deg': 80}, {'alpha_deg': 40, 'beta_deg': 90}]
    """
    if not axes:
        raise ValueError("grid_params needs at least one axis, got none")
    values = {}
    for name, axis in axes.items():
        if isinstance(axis, (str, bytes)) or not isinstance(axis, Iterable):
            raise ValueError(f"axis {name!r} must be a sequence of values, got {axis!r}")
        values[name] = [_python_scalar(v) for v in axis]
        if not values[name]:
            raise ValueError(f"axis {name!r} is empty")
    return [dict(zip(values, combo)) for combo in itertools.product(*values.values())]


# --- what a trial returns -----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TrialOutput:
    """The data variables of one trial, as returned by a trial function.

    Parameters
    ----------
    values : dict[str, float | int | bool | np.ndarray]
        Named results. Scalars become ``(trial,)`` variables of the combined dataset, arrays of
        shape ``s`` become ``(trial, *dims)`` variables; bool, int and float values only. Every
        trial of a study must return the same names with the same shapes (pad ragged results,
        e.g. with NaN). Stored as numpy arrays (0-d for scalars).
    dims : dict[str, tuple[str, ...]]
        Dimension names of every non-scalar value, one per array axis; scalars need none.
    coords : dict[str, np.ndarray]
        Optional 1-D coordinates of those dimensions (e.g. ``{"theta_deg": ...}``); they must be
        identical across the trials of a study.
    """

    values: dict
    dims: dict = field(default_factory=dict)
    coords: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        values = {str(k): np.asarray(v) for k, v in dict(self.values).items()}
        dims = {str(k): tuple(str(d) for d in v) for k, v in dict(self.dims).items()}
        coords = {str(k): np.asarray(v) for k, v in dict(self.coords).items()}
        for name, value in values.items():
            if value.dtype.kind not in _VALUE_KINDS:
                raise ValueError(f"TrialOutput value {name!r} must be bool, int or float, "
                                 f"got dtype {value.dtype}")
            if name in RESERVED_NAMES:
                raise ValueError(f"TrialOutput value name {name!r} is reserved by the runner")
            if len(dims.get(name, ())) != value.ndim:
                raise ValueError(f"TrialOutput value {name!r} has shape {value.shape}, so dims "
                                 f"must name {value.ndim} dimensions, got {dims.get(name, ())}")
        for name, names in dims.items():
            if name not in values:
                raise ValueError(f"TrialOutput dims given for {name!r}, which is not a value")
            if "trial" in names:
                raise ValueError(f"TrialOutput value {name!r}: dimension name 'trial' is reserved")
        used = {d for names in dims.values() for d in names}
        for name, coord in coords.items():
            if name not in used or coord.ndim != 1:
                raise ValueError(f"TrialOutput coord {name!r} must be 1-D along a dimension of "
                                 f"the values {sorted(used)}, got shape {coord.shape}")
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "dims", dims)
        object.__setattr__(self, "coords", coords)


class TrialError(RuntimeError):
    """A trial function raised; ``index`` is the failing trial, the cause is chained."""

    def __init__(self, message: str, index: int) -> None:
        super().__init__(message)
        self.index = index


# --- a trial's set-up ---------------------------------------------------------------------------


def trial_setup(params: dict, *, spec: str | None = None) -> tuple[Rig, SceneObject]:
    """The Mitsuba variant, the rig and the object of a trial, from its parameters.

    Every study's trial function opens with this (a worker process starts with no variant).

    Parameters
    ----------
    params : dict
        The trial's parameters: ``rig`` (a preset name or a rig TOML path), ``object`` (an object
        spec, e.g. ``"plug-gauge:d=20"``; not read when ``spec`` is given) and, optionally,
        ``variant`` (a Mitsuba variant; absent or empty: :func:`default_variant`).
    spec : str, optional
        The object's spec, where the trial names its object otherwise (another parameter, or a
        spec built from several).

    Returns
    -------
    (Rig, SceneObject)
        The loaded rig and the built object. The variant is set only where none is set yet (a
        variant already set, e.g. by the command line, is kept).
    """
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.render import ensure_variant

    ensure_variant(params.get("variant") or None)
    rig = load_rig(params["rig"])
    obj = build_object(params["object"] if spec is None else spec)
    return rig, obj


# --- running ------------------------------------------------------------------------------------


def run_study(out_dir, trials: Sequence[Trial], fn: Callable[[Trial], TrialOutput], *, name: str,
              workers: int | None = None, dask_address: str | None = None,
              progress: bool = True, attrs: dict | None = None,
              pool: concurrent.futures.ProcessPoolExecutor | None = None) -> xr.Dataset:
    """Run every trial not yet on disk, then combine all trials into ``out_dir/results.nc``.

    Parameters
    ----------
    out_dir : path-like
        Directory of the study (created if needed). It holds one study: calling again with the
        same ``name`` and ``trials`` resumes it, anything else raises ``ValueError``.
    trials : sequence of Trial
        The plan, with indices ``0 .. n-1`` in order (see :func:`plan_trials`); every trial has
        the same parameter names.
    fn : callable (Trial) -> TrialOutput
        The trial function. It must depend only on the trial (draw randomness from
        ``trial.seed``), so that results do not depend on the workers or the completion order.
        With ``workers > 1`` or ``dask_address`` it must be a picklable module-level function,
        importable by the workers (in a script, guard the call with
        ``if __name__ == "__main__":`` as processes are started with "spawn").
    name : str
        Name of the study, stored in the plan and the results.
    workers : int, >=1, optional
        Local processes; ``None`` means ``os.cpu_count()``. ``1`` runs the trials sequentially in
        this process, without a pool (use it when ``fn`` is multithreaded itself, as Mitsuba and
        Dr.Jit are). More uses a process pool started with "spawn" (never fork: forking after
        the LLVM JIT threads have started can deadlock).
    dask_address : str, optional
        Scheduler address of a Dask distributed cluster to run the trials on instead; excludes
        ``workers``.
    progress : bool
        Show a tqdm bar on stderr (only when stderr is a terminal).
    attrs : dict, optional
        Extra attributes of the results (NetCDF-serialisable: str, int, float or lists of them);
        ``name``, ``n_trials`` and ``plan_fingerprint`` are set by the runner.
    pool : ProcessPoolExecutor, optional
        A pool opened by :func:`study_pool` and shared by several calls (the batches of one
        study), used where ``workers > 1``: its worker processes, their imports and caches are
        kept from one call to the next, and the pool is left open. ``None``: a pool of
        ``workers`` processes is started for this call and shut down at its end. Not with
        ``dask_address``.

    Returns
    -------
    xarray.Dataset
        The contents of ``results.nc``, loaded into memory (the file is closed): every output
        value with a leading ``trial`` dimension (coordinate ``0 .. n-1``), the coordinates
        ``seed(trial)`` and one ``<param>(trial)`` per parameter.

    Raises
    ------
    ValueError
        ``out_dir`` holds a different study, or the arguments are invalid.
    TrialError
        A trial function raised (or returned something that is not a valid ``TrialOutput``).
        The trials that finished are on disk; nothing is written for the failed one, and no
        ``results.nc``.

    Notes
    -----
    Only this process writes files. A trial file is written to a temporary sibling and renamed
    into place, so it is either complete or absent; on (re)start leftover temporaries and
    unreadable trial files are removed, and a trial file is kept only if its index, params and
    seed match the plan. The plan does not cover the code of ``fn``: after changing it, use a new
    ``out_dir``. Two runs must not share an ``out_dir`` at the same time. On an interrupt, the
    pool waits for the trials already running.
    """
    out_dir = Path(out_dir)
    trials = _check_trials(trials)
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string, got {name!r}")
    attrs = _check_attrs(attrs)
    workers = _check_workers(workers, dask_address)
    if pool is not None and dask_address is not None:
        raise ValueError("pass either pool or dask_address, not both")
    plan = _plan_record(name, trials)
    out_dir.mkdir(parents=True, exist_ok=True)
    _claim_plan(out_dir / "plan.json", plan)
    trials_dir = out_dir / "trials"
    trials_dir.mkdir(exist_ok=True)
    _remove_temporaries(trials_dir)
    pending = [t for t in trials if not _stored_trial_ok(trial_path(out_dir, t.index), t)]
    if pending and dask_address is None and workers > 1:
        _check_picklable(fn)
    logger.info("study %r: %d of %d trials done, running %d", name, len(trials) - len(pending),
                len(trials), len(pending))
    _run_pending(out_dir, pending, fn, name, workers, dask_address, pool,
                 bar=tqdm(total=len(trials), initial=len(trials) - len(pending), desc=name,
                          unit="trial", disable=None if progress else True))
    results = _combine(out_dir, trials, {"name": name, "n_trials": len(trials),
                                         "plan_fingerprint": plan["fingerprint"], **attrs})
    path = out_dir / "results.nc"
    with atomic_path(path) as tmp:
        results.to_netcdf(tmp, engine=ENGINE)
    return xr.load_dataset(path, engine=ENGINE)


def trial_path(out_dir, index: int) -> Path:
    """The file of trial ``index`` in the study directory ``out_dir``."""
    return Path(out_dir) / "trials" / f"trial_{index:06d}.nc"


def _run_pending(out_dir: Path, pending: list[Trial], fn, name: str, workers: int | None,
                 dask_address: str | None, pool, bar) -> None:
    """Run ``pending``, writing each finished trial; raise the first failure at the end."""
    if not pending:
        bar.close()
        return
    if dask_address is not None:
        outcomes = _outcomes_dask(fn, pending, dask_address)
    elif workers == 1:
        outcomes = _outcomes_sequential(fn, pending)
    else:
        outcomes = _outcomes_pool(fn, pending, min(workers, len(pending)), pool)
    failure = None
    with bar, contextlib.closing(outcomes):  # shuts the pool or client down on errors
        for trial, outcome in outcomes:
            if isinstance(outcome, BaseException):
                if failure is None:
                    failure = (trial, outcome)
                else:
                    logger.error("study %r: trial %d failed too: %r", name, trial.index, outcome)
                continue
            _write_trial(trial_path(out_dir, trial.index), outcome)
            bar.update()
    if failure is not None:
        trial, exc = failure
        raise TrialError(f"trial {trial.index} of study {name!r} failed (params {trial.params}, "
                         f"seed {trial.seed}): {type(exc).__name__}: {exc}", trial.index) from exc


def _evaluate(fn: Callable[[Trial], TrialOutput], trial: Trial) -> xr.Dataset:
    """Run one trial and turn its output into the dataset of its file (runs on the worker)."""
    out = fn(trial)
    if not isinstance(out, TrialOutput):
        raise TypeError(f"the trial function must return a TrialOutput, got {type(out).__name__}")
    return _trial_dataset(trial, out)


def _outcomes_sequential(fn, pending: list[Trial]) -> Iterator[tuple[Trial, object]]:
    """Yield ``(trial, dataset or exception)`` in plan order, stopping after a failure."""
    for trial in pending:
        try:
            yield trial, _evaluate(fn, trial)
        except Exception as exc:  # reported by run_study with the trial index
            yield trial, exc
            return


def _outcomes_pool(fn, pending: list[Trial], workers: int,
                   shared: concurrent.futures.ProcessPoolExecutor | None = None,
                   ) -> Iterator[tuple[Trial, object]]:
    """Yield outcomes as a spawn process pool completes them; after a failure no trial starts,
    those already running are still yielded. ``shared``: a pool of :func:`study_pool`, left
    open (on an early exit its trials not yet started are cancelled and the running ones
    waited for); otherwise a pool of ``workers`` processes, shut down at the end."""
    pool = shared if shared is not None else _spawn_pool(workers)
    futures = {}
    try:
        futures = {pool.submit(_evaluate, fn, t): t for t in pending}
        for fut in concurrent.futures.as_completed(futures):
            if fut.cancelled():
                continue
            exc = fut.exception()
            if exc is not None:
                for other in futures:
                    other.cancel()
            yield futures[fut], exc if exc is not None else fut.result()
    finally:
        if shared is None:
            pool.shutdown(wait=True, cancel_futures=True)
        else:
            for fut in futures:
                fut.cancel()
            concurrent.futures.wait(futures)


def _spawn_pool(workers: int) -> concurrent.futures.ProcessPoolExecutor:
    threads = max(1, (os.cpu_count() or 1) // workers)
    return concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
        initializer=limit_native_threads, initargs=(threads,))


#: Environment variables of the native thread pools a worker process caps (read when the
#: library loads: BLAS/LAPACK of numpy and scipy, OpenMP of Open3D).
THREAD_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_native_threads(threads: int) -> None:
    """Cap the native thread pools (BLAS, LAPACK, OpenMP, Dr.Jit's) of this process at
    ``threads``: a pool worker's share of the cores.  Uncapped, each of ``w`` workers runs
    OpenBLAS with one thread per core, whose threads spin after every call: on 2 cores they
    took a quarter of a Monte Carlo trial's CPU and saved no wall time (BENCHMARKS.md).  Libraries loaded later
    read the environment; those already loaded (numpy's and scipy's OpenBLAS, loaded here)
    are capped through :mod:`threadpoolctl`, Dr.Jit's LLVM thread pool through
    ``drjit.set_thread_count`` (a twin-rendering trial: 0.71 -> 0.63 s of CPU with one
    thread).  Where the user set any of :data:`THREAD_ENV`, nothing is changed."""
    if any(name in os.environ for name in THREAD_ENV):
        return
    import scipy.linalg  # noqa: F401  (loads scipy's own OpenBLAS, beside numpy's)
    from threadpoolctl import threadpool_limits

    threads = max(1, int(threads))
    for name in THREAD_ENV:
        os.environ[name] = str(threads)
    threadpool_limits(limits=threads)
    import drjit  # its LLVM backend's pool (nanothread): one thread per core by default

    drjit.set_thread_count(threads)


@contextlib.contextmanager
def study_pool(workers: int | None = None, dask_address: str | None = None,
               ) -> Iterator[concurrent.futures.ProcessPoolExecutor | None]:
    """One local process pool for every :func:`run_study` call of a study (``pool=``).

    A study run as several calls (the batches of a Monte Carlo) otherwise starts a pool per
    call, each worker importing numpy, xarray and Mitsuba again (seconds of CPU each) and
    rebuilding its caches. Results do not change: every trial depends on its seed only.

    Parameters
    ----------
    workers, dask_address
        As for :func:`run_study`. Yields ``None`` (nothing to share) for ``workers=1`` or a
        Dask cluster, else a "spawn" pool of ``workers`` processes, shut down on exit
        (waiting for the trials already running).

    >>> with study_pool(workers=2) as pool:                                 # doctest: +SKIP
    ...     for h in range(4):
    ...         run_study(f"out/batch_{h}", plans[h], my_trial, name=f"b{h}", workers=2, pool=pool)
    """
    workers = _check_workers(workers, dask_address)
    if dask_address is not None or workers == 1:
        yield None
        return
    pool = _spawn_pool(workers)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _outcomes_dask(fn, pending: list[Trial], address: str) -> Iterator[tuple[Trial, object]]:
    """Yield outcomes as a Dask cluster completes them, stopping after a failure."""
    try:
        from distributed import Client, as_completed
    except ImportError as exc:
        raise ImportError("dask_address needs the 'distributed' package") from exc
    client = Client(address, set_as_default=False)
    futures = []
    try:
        futures = [client.submit(_evaluate, fn, t, pure=False) for t in pending]
        trial_of = {fut.key: t for fut, t in zip(futures, pending)}
        for fut in as_completed(futures, loop=client.loop):
            try:
                dataset = fut.result()
            except Exception as exc:  # reported by run_study with the trial index
                yield trial_of[fut.key], exc
                return
            yield trial_of[fut.key], dataset
    finally:
        unfinished = [fut for fut in futures if not fut.done()]
        if unfinished:
            client.cancel(unfinished)
        client.close()


# --- files --------------------------------------------------------------------------------------


def _trial_dataset(trial: Trial, out: TrialOutput) -> xr.Dataset:
    """The dataset of one trial's file: its values, plus index, seed and params as attributes."""
    clash = sorted(set(out.values) & set(trial.params))
    if clash:
        raise ValueError(f"output names {clash} are also parameter names")
    data_vars = {k: (out.dims.get(k, ()), v) for k, v in out.values.items()}
    attrs = {"trial_index": trial.index, "trial_seed": trial.seed,
             "trial_params": _canonical_json(trial.params)}
    return xr.Dataset(data_vars, coords=out.coords, attrs=attrs)


def _write_trial(path: Path, dataset: xr.Dataset) -> None:
    with atomic_path(path) as tmp:
        dataset.to_netcdf(tmp, engine=ENGINE)


def _stored_trial_ok(path: Path, trial: Trial) -> bool:
    """Whether ``path`` is a readable file of exactly this trial; remove it if it is not."""
    if not path.exists():
        return False
    try:
        a = xr.load_dataset(path, engine=ENGINE).attrs
        ok = (a.get("trial_index") == trial.index and a.get("trial_seed") == trial.seed
              and a.get("trial_params") == _canonical_json(trial.params))
    except Exception as exc:  # any read error means the trial must be run again
        logger.warning("%s is unreadable (%s); running trial %d again", path, exc, trial.index)
        ok = False
    else:
        if not ok:
            logger.warning("%s does not match the plan; running trial %d again", path, trial.index)
    if not ok:
        path.unlink()
    return ok


def _remove_temporaries(trials_dir: Path) -> None:
    """Remove what an interrupted write left behind (``atomic_path``'s ``.<stem>.tmp.nc``)."""
    for tmp in trials_dir.glob(".trial_*.tmp.nc"):
        logger.info("removing the leftover temporary file %s", tmp)
        tmp.unlink()


def _combine(out_dir: Path, trials: list[Trial], attrs: dict) -> xr.Dataset:
    """All trial files along a new ``trial`` dimension, with params and seeds as coordinates."""
    datasets = [xr.load_dataset(trial_path(out_dir, t.index), engine=ENGINE) for t in trials]
    _check_consistent(datasets, trials)
    ds = xr.concat(datasets, dim="trial", data_vars="all", coords="minimal", compat="equals",
                   join="exact", combine_attrs="drop")
    coords = {"trial": np.array([t.index for t in trials], dtype=np.int64),
              "seed": ("trial", np.array([t.seed for t in trials], dtype=np.int64))}
    for key in trials[0].params:
        coords[key] = ("trial", np.array([t.params[key] for t in trials]))
    return ds.assign_coords(coords).assign_attrs(attrs)


def _check_consistent(datasets: list[xr.Dataset], trials: list[Trial]) -> None:
    """Every trial must return the same variables with the same dims, shapes and coords."""
    def layout(ds):
        return {k: (v.dims, v.shape) for k, v in ds.data_vars.items()}

    first = datasets[0]
    for ds, trial in zip(datasets[1:], trials[1:]):
        if layout(ds) != layout(first):
            raise ValueError(f"trial {trial.index} returned {layout(ds)}, but trial "
                             f"{trials[0].index} returned {layout(first)}; every trial must return "
                             "the same values with the same shapes")
        if set(ds.coords) != set(first.coords):
            raise ValueError(f"trial {trial.index} has coords {sorted(ds.coords)}, trial "
                             f"{trials[0].index} has {sorted(first.coords)}")
        for name, coord in ds.coords.items():
            if not coord.equals(first.coords[name]):
                raise ValueError(f"coord {name!r} of trial {trial.index} differs from trial "
                                 f"{trials[0].index}'s; coords must be identical across trials")


# --- analysis -----------------------------------------------------------------------------------


def to_grid(ds: xr.Dataset, *axes: str) -> xr.Dataset:
    """Reshape the ``trial`` dimension of a grid study into the named parameter axes.

    Parameters
    ----------
    ds : xarray.Dataset
        Results of :func:`run_study`, with the parameters as ``(trial,)`` coordinates.
    *axes : str
        Parameters to become dimensions, in order, e.g. ``"alpha_deg", "beta_deg"``. Their value
        combinations must be unique across trials.

    Returns
    -------
    xarray.Dataset
        ``trial`` replaced by ``axes`` (sorted coordinate values): a ``(trial, k)`` variable
        becomes ``(*axes, k)``; ``trial``, ``seed`` and the other parameters stay as coordinates
        over ``axes``. Combinations missing from an incomplete grid are NaN (ints become floats).

    >>> to_grid(ds, "alpha_deg", "beta_deg")["rms_mm"].plot()   # doctest: +SKIP
    """
    if not axes:
        raise ValueError("to_grid needs at least one axis, got none")
    for axis in axes:
        if axis not in ds.coords or ds[axis].dims != ("trial",):
            along = [k for k, c in ds.coords.items() if c.dims == ("trial",) and k != "trial"]
            raise ValueError(f"axis {axis!r} is not a coordinate along 'trial'; those are {along}")
    combos = list(zip(*(ds[axis].values.tolist() for axis in axes)))
    if len(set(combos)) != len(combos):
        seen = set()
        dup = next(c for c in combos if c in seen or seen.add(c))
        raise ValueError(f"the trials do not form a grid over {list(axes)}: "
                         f"{dict(zip(axes, dup))} occurs more than once")
    ds = ds.assign_coords(_trial_index=("trial", ds["trial"].values))
    if len(axes) == 1:
        grid = ds.swap_dims(trial=axes[0]).drop_vars("trial").sortby(axes[0])
    else:
        grid = ds.set_index(trial=list(axes)).unstack("trial")
    return grid.rename_vars(_trial_index="trial").transpose(*axes, ...)


# --- the plan on disk ---------------------------------------------------------------------------


def _plan_record(name: str, trials: list[Trial]) -> dict:
    records = [{"index": t.index, "params": t.params, "seed": t.seed} for t in trials]
    digest = hashlib.sha256(_canonical_json({"name": name, "trials": records}).encode())
    return {"name": name, "n_trials": len(trials), "fingerprint": digest.hexdigest(),
            "trials": records}


def _claim_plan(path: Path, plan: dict) -> None:
    """Write the plan, or check that the one already there is the same study."""
    if not path.exists():
        write_json(path, plan)
        return
    try:
        old = json.loads(path.read_text())
        difference = _plan_difference(old, plan)
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path} is not a readable plan ({exc}); remove it or use another "
                         "directory") from exc
    if difference:
        raise ValueError(f"{path.parent} holds a different study: {difference}; use another "
                         "directory or delete this one")


def _plan_difference(old: dict, new: dict) -> str | None:
    """One line naming the first difference between two plans, or None if they are the same."""
    if old["name"] != new["name"]:
        return f"name {old['name']!r} there, {new['name']!r} now"
    if len(old["trials"]) != len(new["trials"]):
        return f"{len(old['trials'])} trials there, {len(new['trials'])} now"
    for a, b in zip(old["trials"], new["trials"]):
        if _canonical_json(a) != _canonical_json(b):
            return (f"trial {b['index']} is {_canonical_json(a)} there, "
                    f"{_canonical_json(b)} now")
    if old["fingerprint"] != new["fingerprint"]:
        return f"fingerprint {old['fingerprint'][:12]}… there, {new['fingerprint'][:12]}… now"
    return None


def _canonical_json(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


# --- argument checks ----------------------------------------------------------------------------


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _python_scalar(value):
    return value.item() if isinstance(value, np.generic) else value


def _check_params(params, where: str) -> dict:
    if not isinstance(params, dict):
        raise ValueError(f"{where}: params must be a dict, got {type(params).__name__}")
    out = {}
    for key, value in params.items():
        value = _python_scalar(value)
        if not isinstance(key, str) or key in RESERVED_NAMES:
            raise ValueError(f"{where}: param name {key!r} must be a string other than "
                             f"{sorted(RESERVED_NAMES)}")
        if not isinstance(value, _PARAM_TYPES):
            raise ValueError(f"{where}: param {key!r} must be a bool, int, float or str, "
                             f"got {type(value).__name__}")
        out[key] = value
    return out


def _check_trials(trials: Sequence[Trial]) -> list[Trial]:
    trials = list(trials)
    if not trials:
        raise ValueError("a study needs at least one trial, got none")
    for i, trial in enumerate(trials):
        if not isinstance(trial, Trial):
            raise ValueError(f"trials[{i}] must be a Trial, got {type(trial).__name__}")
    keys = list(trials[0].params)
    for i, trial in enumerate(trials):
        if trial.index != i:
            raise ValueError(f"trials[{i}] has index {trial.index}; indices must be 0 .. n-1 "
                             "in order (use plan_trials)")
        if sorted(trial.params) != sorted(keys):
            raise ValueError(f"trial {i} has params {sorted(trial.params)}, trial 0 has "
                             f"{sorted(keys)}; every trial must have the same param names")
    return trials


def _check_workers(workers, dask_address) -> int | None:
    if dask_address is not None:
        if workers is not None:
            raise ValueError("pass either workers or dask_address, not both")
        return None
    if workers is None:
        return os.cpu_count() or 1
    if not _is_int(workers) or workers < 1:
        raise ValueError(f"workers must be an int >= 1 or None, got {workers!r}")
    return int(workers)


def _check_attrs(attrs) -> dict:
    attrs = dict(attrs or {})
    for key, value in attrs.items():
        if key in ("name", "n_trials", "plan_fingerprint"):
            raise ValueError(f"attrs may not set {key!r}; the runner sets it")
        items = value if isinstance(value, (list, tuple)) else [value]
        if isinstance(value, (bool, np.bool_)) or not all(
                isinstance(v, (str, int, float, np.number)) and not isinstance(v, bool)
                for v in items):
            raise ValueError(f"attr {key!r} must be a str, int, float or a list of them "
                             f"(NetCDF), got {value!r}")
    return attrs


def _check_picklable(fn) -> None:
    try:
        pickle.dumps(fn)
    except Exception as exc:  # pickling errors come in several types
        raise TypeError(f"with workers > 1 the trial function must be a picklable module-level "
                        f"function, got {fn!r} ({exc})") from exc
