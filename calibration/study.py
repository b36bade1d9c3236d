"""Calibration studies: plan a campaign before measuring.

* :func:`monte_carlo`: repeat "simulate -> calibrate on the training measurements -> validate on the
  held-out ones" over noise draws and pose sets (a new simulator seed each run); report the
  parameter errors against the truth (expressed in the identifiable parameterization, see
  :meth:`CalibrationResult.equivalent`) next to the uncertainties the fits reported, and the predicted
  post-calibration accuracy (validation figures before/after).
* :func:`select_measurements`: greedy choice of a pose set (measurements) from a candidate pool by the
  observability index O1 of Borm and Menq (1991), ``O1 = (s_1 s_2 ... s_m)^(1/m) / sqrt(n)`` with
  ``s_i`` the singular values of the column-scaled identification Jacobian (nuisance eliminated) and
  ``n`` the number of poses (points).

Runs go to local processes (:class:`concurrent.futures.ProcessPoolExecutor`) by default, or to a
Dask cluster when a scheduler address (or a ``distributed.Client``) is given. Progress is shown by
:class:`arm_model.log.Progress` (this module's logger: redrawn in place on a terminal, plain lines in a log
file; silent unless logging is enabled for INFO, as under ``aacmm`` without ``--quiet``).
"""
from __future__ import annotations

import logging
import math
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from arm_model import AacmmError, InputError, NumericalError
from arm_model.log import Progress, counted
from arm_model.model import ArmModel
from arm_model.parallel import cores

from .calibrate import calibrate, resolve_parameters
from .data import CalibrationData, make_data, split_holdout
from .identifiability import reduced_jacobian
from .options import FitOptions
from .problem import Problem
from .solver import blas_threads

__all__ = ["Progress", "run_tasks", "SimSource", "SynthSource", "RunSettings", "run_once", "monte_carlo",
           "MonteCarloResult", "select_measurements", "Selection", "observability_index"]

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------------
# execution

#: seconds to wait for a Dask scheduler before giving up
CONNECT_TIMEOUT_S = 3.0


def connect(address: str):
    """A ``distributed.Client`` of the scheduler at ``address``, or an InputError naming the address
    within about :data:`CONNECT_TIMEOUT_S` (a TCP address is tried with a plain socket first, so that an
    unreachable host does not wait for Dask's own retries)."""
    import logging
    import socket
    from urllib.parse import urlsplit

    from distributed import Client

    def fail(reason: str):
        return InputError(f"cannot reach the Dask scheduler at {address!r}: {reason}")

    url = urlsplit(address if "://" in address else f"tcp://{address}")
    if url.scheme in ("tcp", "tls"):
        try:
            host, port = url.hostname, url.port
        except ValueError as exc:
            raise fail(str(exc)) from None
        if not host or port is None:
            raise fail("expected an address like tcp://host:8786")
        try:
            socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
        except OSError as exc:
            raise fail(f"{exc.strerror or exc} (waited at most {CONNECT_TIMEOUT_S:g} s)") from None
    quiet = logging.getLogger("distributed")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)         # its own retry messages would bury ours
    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S)
    except Exception as exc:                 # whatever Dask raises: one message naming the address
        raise fail(f"{type(exc).__name__}: {exc}") from None
    finally:
        quiet.setLevel(level)


def run_tasks(fn, items, *, scheduler=None, workers: int | None = None, progress: bool = True,
              label: str = "runs") -> list:
    """``[fn(item) for item in items]``, in parallel, results in the order of ``items``.

    Args:
        fn: a picklable top-level function.
        scheduler: None (local processes), a Dask scheduler address (``"tcp://host:8786"``) or a
            ``distributed.Client``.
        workers: local processes (default: the CPU count; at most the cores this process may run on); 1 runs in
            this process.
    """
    items = list(items)
    bar = Progress(len(items), label, logger=log, enabled=progress)
    out = [None] * len(items)
    if scheduler is not None:
        from distributed import Client, as_completed as dask_completed
        client = scheduler if isinstance(scheduler, Client) else connect(scheduler)
        try:
            futures = client.map(fn, items, pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            for fut in dask_completed(futures):
                out[index[fut.key]] = _dask_result(fut, client)
                bar.update()
        except BaseException:
            client.cancel(futures)
            raise
        finally:
            if client is not scheduler:
                client.close()
        return out
    if workers is not None:
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers must be a whole number >= 1, got {workers!r}")
        workers = min(workers, cores())     # more than the cores only cost memory (100000 forked 100000 processes)
    if workers == 1 or len(items) <= 1:
        for i, it in enumerate(items):
            out[i] = fn(it)
            bar.update()
        return out
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futs = {pool.submit(fn, it): i for i, it in enumerate(items)}
        try:
            for fut in as_completed(futs):
                out[futs[fut]] = fut.result()
                bar.update()
        except BaseException:       # an error (or Ctrl-C) ends the work: the items not started are not run
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return out


def _dask_result(fut, client):
    """The result of a Dask future; an error of the toolkit as it is (a run's input error stops the study as it
    would locally), any other error of a worker (the toolkit missing or of another version there, a worker lost)
    as one message naming the scheduler."""
    try:
        return fut.result()
    except AacmmError:
        raise
    except Exception as exc:
        raise InputError(f"a Dask worker of the scheduler at {client.scheduler.address!r} failed: "
                         f"{type(exc).__name__}: {exc} (does every worker run this toolkit, version "
                         f"{_version()}, and reach the scheduler?)") from None


def _version() -> str:
    from arm_model.shipped import version
    return version()


# ---------------------------------------------------------------------------------------------
# campaign sources (picklable: they travel to worker processes)

@dataclass(frozen=True)
class SimSource:
    """Campaigns from :mod:`arm_model.sim`: a campaign (an :class:`arm_model.sim.Campaign` as
    :func:`arm_model.sim.load_campaign` read it, or the path of its file, read here once), simulated with a new seed
    each run. The campaign read travels to the workers, so that a worker on another machine needs no file and every
    run simulates the same campaign, whatever happens to its file meanwhile."""
    campaign: Any

    def __post_init__(self):
        from arm_model.sim import Campaign, load_campaign
        if isinstance(self.campaign, (str, Path)):
            object.__setattr__(self, "campaign", load_campaign(self.campaign))
        elif not isinstance(self.campaign, Campaign):
            raise TypeError(f"SimSource: campaign must be a Campaign or the path of its file, got "
                            f"{type(self.campaign).__name__}")

    def make(self, seed: int):
        from arm_model.sim import simulate
        sim = simulate(self.campaign, seed=seed, progress=_no_progress)   # the study prints its own
        return self.campaign.arm, sim.points, sim.artefacts, sim.reference_points, dict(sim.truth["p"])


def _no_progress(message: str) -> None:
    """A run's simulation says nothing: between the study's own progress lines, each run's 'planned', 'inverse
    kinematics', 'writing files in memory', 'force signals' (four lines a run, files it does not write) misled."""


@dataclass(frozen=True)
class SynthSource:
    """Campaigns of the simulator's fast path (:mod:`arm_model.sim.quick`): ``spec`` on the arm ``desc``;
    the truth is drawn anew each run unless ``truth`` (name -> value) is given."""
    desc: object
    spec: object
    truth: dict | None = None

    def make(self, seed: int):
        from arm_model.sim.quick import make_campaign
        model = ArmModel(self.desc)
        p_true = None if self.truth is None else model.spec.vector(self.truth)
        c = make_campaign(model, self.spec, seed, p_true)
        return self.desc, c.points, c.artefacts, c.reference_points, c.truth


@dataclass(frozen=True)
class RunSettings:
    """How each run calibrates (``fit``: free set, weights and every option of the fit) and validates
    (``holdout``: the share of measurements held out, in [0, 1); 0: none, every run fits all its measurements and
    reports no predicted accuracy); ``effects``: added to the campaign's arm."""
    holdout: float = 0.25
    fit: FitOptions = field(default_factory=FitOptions)
    effects: tuple = ()

    def __post_init__(self):
        h = self.holdout
        if isinstance(h, bool) or not isinstance(h, (int, float)) or not 0.0 <= h < 1.0:
            raise ValueError(f"RunSettings: holdout must be a fraction in [0, 1) (0: no held-out data), got {h!r}")


def run_once(task) -> dict:
    """One Monte Carlo run: ``task = (source, settings, seed)``. A run that fails numerically is reported with its
    error; an :class:`~arm_model.InputError` is raised: the campaign or the settings are wrong (a held-out set
    that would be empty), the same in every run, and the study stops there."""
    source, settings, seed = task
    t0 = time.perf_counter()
    try:
        with blas_threads(1):
            return _run(source, settings, seed, t0)
    except InputError:
        raise
    except (AacmmError, ValueError) as exc:
        return {"seed": seed, "ok": False, "error": f"{type(exc).__name__}: {exc}",
                "seconds": time.perf_counter() - t0}


def _run(source, settings, seed, t0) -> dict:
    desc, points, artefacts, reference, truth = source.make(seed)
    model = ArmModel(desc, tuple(settings.effects))
    data = make_data(points, artefacts, model, reference=reference)
    try:
        train, test = (split_holdout(data, settings.holdout, seed, remedy="give a larger --holdout, or 0 to hold "
                                     "nothing out") if settings.holdout else (data, None))
    except InputError as exc:       # the simulated points file is no user's: name the option instead
        raise InputError(f"--holdout {settings.holdout:g}: {exc.reason}") from None
    res = calibrate(model, train, settings.fit)
    p_true = model.spec.vector({k: v for k, v in truth.items() if k in model.spec.names})
    p_eq = res.equivalent(p_true)
    idx = [model.spec.index(n) for n in res.free]
    return {"seed": seed, "ok": True, "free": list(res.free), "p": res.p[idx].tolist(),
            "u": res.u.tolist(), "truth": p_eq[idx].tolist(), "fixed": [f.name for f in res.fixed],
            "s0": res.s0, "iterations": res.iterations, "validation": [] if test is None else res.compare(test),
            "seconds": time.perf_counter() - t0}


@dataclass
class MonteCarloResult:
    """Aggregated Monte Carlo runs.

    Attributes:
        runs: every run's dict (:func:`run_once`).
        parameters: per parameter free in every successful run: ``rms_error`` (estimate minus the
            truth in the fit's parameterization) [SI], ``mean_u`` (mean reported u) [SI], ``ratio``
            rms_error / mean_u, ``within_3u`` (fraction of runs with |error| <= 3 u), and from the
            standardized errors z = error / u of each run: ``z_rms`` (about 1 when the reported
            uncertainties are right), ``z_mean`` (a bias: the model lacks something the truth has),
            ``z_rms_95`` the interval that z_rms of this many runs falls in with 95 % probability when
            the uncertainties are right (chi distribution: with 20 runs 0.69-1.31, so a spread of
            ratios over that range is sampling, not a fault), and ``verdict``.
        s0: the runs' residual scale factors (far from 1: the stated uncertainties do not match the
            residuals; one factor rescales every residual group alike, see docs/uncertainty.md).
        accuracy: per validation figure: median and 95th percentile, before and after [shown unit].
    """
    runs: list
    parameters: dict
    accuracy: dict
    s0: list = field(default_factory=list)

    @property
    def failures(self) -> list:
        return [r for r in self.runs if not r["ok"]]

    def check(self) -> None:
        """Raise a NumericalError when no run succeeded: a study without a result is a failure, never an empty
        table (some runs failing is a result: they are listed)."""
        if self.runs and len(self.failures) == len(self.runs):
            errors = list(dict.fromkeys(r["error"] for r in self.runs))
            raise NumericalError(f"no run succeeded ({counted(len(self.runs), 'run')}): " + "; ".join(errors[:3])
                                 + (" ..." if len(errors) > 3 else ""))

    def to_dict(self) -> dict:
        return {"runs": self.runs, "parameters": self.parameters, "accuracy": self.accuracy,
                "failures": len(self.failures), "s0": self.s0}


def rms_z_interval(runs: int, probability: float = 0.95) -> tuple[float, float]:
    """The interval the RMS of ``runs`` standard normal z falls in with ``probability``."""
    from scipy.stats import chi2
    a = (1.0 - probability) / 2
    return float(np.sqrt(chi2.ppf(a, runs) / runs)), float(np.sqrt(chi2.ppf(1 - a, runs) / runs))


def _verdict(z: np.ndarray, lo: float, hi: float) -> str:
    rms, mean = float(np.sqrt(np.mean(z ** 2))), float(np.mean(z))
    if abs(mean) > 2.0 / np.sqrt(len(z)) and rms > hi:
        return "biased"
    if rms > hi:
        return "u too small"
    if rms < lo:
        return "u too large"
    return "ok"


def _aggregate(runs: list) -> MonteCarloResult:
    ok = [r for r in runs if r["ok"]]
    params = {}
    lo, hi = rms_z_interval(len(ok)) if ok else (0.0, 0.0)
    if ok:
        common = [n for n in ok[0]["free"] if all(n in r["free"] for r in ok)]
        for n in common:
            e = np.array([r["p"][r["free"].index(n)] - r["truth"][r["free"].index(n)] for r in ok])
            u = np.array([r["u"][r["free"].index(n)] for r in ok])
            rms = float(np.sqrt(np.mean(e ** 2)))
            z = e / u
            params[n] = {"rms_error": rms, "mean_u": float(u.mean()), "ratio": rms / float(u.mean()),
                         "within_3u": float(np.mean(np.abs(e) <= 3 * u)),
                         "z_rms": float(np.sqrt(np.mean(z ** 2))), "z_mean": float(np.mean(z)),
                         "z_rms_95": [lo, hi], "verdict": _verdict(z, lo, hi)}
    acc = {}
    for r in ok:
        for row in r["validation"]:
            a = acc.setdefault(row["key"], {"label": row["label"], "unit": row["unit"], "before": [], "after": []})
            a["before"].append(row["before"])
            a["after"].append(row["after"])
    for a in acc.values():
        b, f = np.array(a.pop("before")), np.array(a.pop("after"))
        a.update(n=len(b), before_median=float(np.median(b)), before_p95=float(np.percentile(b, 95)),
                 after_median=float(np.median(f)), after_p95=float(np.percentile(f, 95)))
    return MonteCarloResult(runs, params, acc, [float(r["s0"]) for r in ok])


def monte_carlo(source, runs: int, *, seed: int = 0, settings: RunSettings | None = None, scheduler=None,
                workers: int | None = None, progress: bool = True) -> MonteCarloResult:
    """``runs`` Monte Carlo runs of ``source`` (:class:`SimSource` or :class:`SynthSource`) with
    seeds ``seed, seed + 1, ...``; see :func:`run_tasks` for ``scheduler`` and ``workers``."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ValueError(f"monte_carlo: runs must be a whole number >= 1, got {runs!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"monte_carlo: seed must be a whole number >= 0, got {seed!r}")
    settings = settings or RunSettings()
    tasks = [(source, settings, seed + i) for i in range(runs)]
    return _aggregate(run_tasks(run_once, tasks, scheduler=scheduler, workers=workers, progress=progress,
                                label="monte carlo"))


# ---------------------------------------------------------------------------------------------
# pose-set choice by an observability index

def observability_index(info: np.ndarray, n_poses: int) -> float:
    """Borm and Menq's O1 = (prod s_i)^(1/m) / sqrt(n) from the information matrix ``J^T J``
    (``s_i^2`` its eigenvalues) of ``n_poses`` poses."""
    ev = np.linalg.eigvalsh(info)
    if ev.min() <= 0 or n_poses == 0:
        return 0.0
    return float(np.exp(0.5 * np.mean(np.log(ev))) / math.sqrt(n_poses))


@dataclass
class Selection:
    """Measurements chosen greedily, in order, with O1 after each addition; the O1 of random sets of
    the same sizes (mean of ``random_draws``) for comparison; predicted standard uncertainties [SI]
    of the parameters with the chosen set and with the whole pool (stated weights, s0 = 1)."""
    parameters: tuple
    chosen: list
    o1: list
    o1_random: list
    n_points: list
    u_chosen: dict
    u_pool: dict

    def to_dict(self) -> dict:
        return {"parameters": list(self.parameters), "chosen": self.chosen, "o1": self.o1,
                "o1_random": self.o1_random, "n_points": self.n_points, "u_chosen": self.u_chosen,
                "u_pool": self.u_pool}


def select_measurements(model: ArmModel, data: CalibrationData, count: int, options: FitOptions = FitOptions(), *,
                        p=None, random_draws: int = 20, seed: int = 0, progress: bool = True,
                        always=()) -> Selection:
    """Choose ``count`` measurements of ``data`` that best identify the parameters.

    The pool is first reduced to its identifiable parameters (:func:`calibration.calibrate.identify`,
    with the fit's ``options``: free set, weights, rank and resolution rules (none with a prior), at ``p``,
    default the nominal, on the whole pool with the nuisance
    fitted); then each measurement's
    rows of the reduced, column-scaled Jacobian give an information block and measurements are added
    one at a time, each time the one that maximises O1 (a shared reference transform is eliminated
    over the whole pool, a stated approximation). ``always``: measurements kept from the start.
    """
    from .calibrate import column_scale, default_free, identify
    from .solver import levenberg_marquardt

    spec = model.spec
    cand = resolve_parameters(spec, default_free(model, data) if options.free is None else options.free)
    p = np.zeros(spec.size) if p is None else np.asarray(p, float)
    prob = Problem(model, data, options.weights, cand, reference=options.reference)
    states = levenberg_marquardt(prob.with_free([]), p, prob.initial_states(p)).states
    if options.prior_scale is not None:           # a prior shrinks what the data resolve poorly: nothing is weak
        options = replace(options, min_resolution=None)
    kept, _, _ = identify(prob, p, states, cand, options)
    prob = prob.with_free(kept)
    ev = prob.evaluate(p, states)
    jred = reduced_jacobian(ev.jp, ev.jt) / column_scale(ev.jp)
    meas_of_row = np.full(len(prob.row_point), None, dtype=object)
    on_point = prob.row_point >= 0
    meas_of_row[on_point] = data.points.measurement[prob.row_point[on_point]]
    for k, d in enumerate(prob.distance_items):
        meas_of_row[prob.n_point_rows + k] = d.measurement
    ids = data.measurements()
    blocks = {m: jred[meas_of_row == m] for m in ids}
    info = {m: b.T @ b for m, b in blocks.items()}
    npts = {m: int(np.sum(data.points.measurement == m)) for m in ids}
    total = sum(info.values())
    eps = 1e-12 * np.trace(total) / len(kept)
    reg = eps * np.eye(len(kept))
    count = min(count, len(ids))
    chosen = [m for m in always if m in info]
    cur = sum((info[m] for m in chosen), np.zeros((len(kept),) * 2))
    o1s, ns = [], []
    bar = Progress(count, "selecting", logger=log, enabled=progress)
    bar.update(len(chosen))
    while len(chosen) < count:
        n_now = sum(npts[m] for m in chosen)
        best, best_val = None, -np.inf
        for m in ids:
            if m in chosen:
                continue
            sign, logdet = np.linalg.slogdet(cur + info[m] + reg)
            val = 0.5 * logdet / len(kept) - 0.5 * math.log(n_now + npts[m])
            if val > best_val:
                best, best_val = m, val
        assert best is not None, "an unchosen measurement is left while len(chosen) < count"
        chosen.append(best)
        cur = cur + info[best]
        o1s.append(observability_index(cur + reg, n_now + npts[best]))
        ns.append(n_now + npts[best])
        bar.update()
    rng = np.random.default_rng(seed)
    o1r = []
    for k in range(1, len(chosen) + 1):
        vals = []
        for _ in range(random_draws):
            pick = rng.choice(len(ids), size=k, replace=False)
            mat = sum((info[ids[i]] for i in pick), np.zeros((len(kept),) * 2))
            vals.append(observability_index(mat + reg, sum(npts[ids[i]] for i in pick)))
        o1r.append(float(np.mean(vals)))
    scale = column_scale(ev.jp)
    names = [spec.names[i] for i in kept]

    def u_of(mat):
        cov = np.linalg.pinv(mat) / np.outer(scale, scale)
        return {n: float(np.sqrt(max(cov[k, k], 0.0))) for k, n in enumerate(names)}
    return Selection(tuple(names), chosen, o1s, o1r, ns, u_of(cur), u_of(total))
