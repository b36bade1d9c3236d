"""Calibration speed: our Levenberg-Marquardt on exact CasADi Jacobians vs
``scipy.optimize.least_squares`` with finite differences on the same problem, and scaling with the
number of points.

The problem: the nominal 7-axis arm with first-harmonic encoder eccentricity on joints 1-6 (about 40
parameters: DH errors, probe offset and compliance, 12 eccentricity terms; the identifiability
analysis holds the ones the data cannot see), a synthetic campaign of ball-bar spheres, seat
articulations, reference spheres and tracker points (force 1.5 N, probing noise 2 um). The nuisance
unknowns (sphere and seat centres, T_ref_base) are solved jointly in both solvers. SciPy gets the same
residual written in numpy (ball centres from ``ArmModel.ball_centres``), the same free parameters, the
same start and tight tolerances; its Jacobian is by 2-point finite differences (MINPACK ``lm``, and
``trf`` told the Jacobian's sparsity, which it uses to group the differences).

Large campaigns (:func:`large`): the whole ``aacmm calibrate`` command on simulated campaigns of about 10^3, 10^4 and
10^5 residual rows (:func:`large_campaign`), its wall, CPU and peak memory against :data:`LARGE_TARGET`.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from arm_model import load_description
from arm_model.effects import EncoderEccentricity
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, Problem, Weights, calibrate, levenberg_marquardt, make_data
from calibration.solver import blas_threads

ARM = "urdf/aacmm7.dh.toml"
WEIGHTS = Weights(probe=2e-6, reference=5e-6)


def campaign(model: ArmModel, n: int, seed: int = 1):
    """About ``n`` points: 60 % ball bar (6 points a sphere), 15 % seats (30 articulations),
    5 % spheres (25 points), 20 % tracker points."""
    rng = np.random.default_rng(seed)
    truth = random_truth(model, rng)
    for i, name in enumerate(model.spec.names):
        if ".ecc" in name:
            truth[i] = rng.normal(0, 2e-5)
    spec = SynthSpec(ballbars=max(1, round(0.6 * n / 12)), ballbar_points=6, seats=max(1, round(0.15 * n / 30)),
                     articulations=30, spheres=max(1, round(0.05 * n / 25)), sphere_points=25,
                     reference_points=round(0.2 * n), force=1.5, noise=2e-6, reference_noise=5e-6)
    c = make_campaign(model, spec, seed, truth)
    return make_data(c.points, c.artefacts, model, reference=c.reference_points)


class NumpyResidual:
    """The same weighted residual as :class:`calibration.Problem`, in numpy, over
    z = [free parameters, sphere/seat centres (3 each), T_ref_base (rotation vector, translation)]."""

    def __init__(self, prob: Problem, p0: np.ndarray, states):
        self.prob, self.p0 = prob, p0.copy()
        self.free = prob.free
        data = prob.data
        self.q, self.w, self.aux = data.points.q, data.wrench, data.aux
        self.model = prob.model
        insts = prob.instances
        self.centre_index = {}
        k = len(self.free)
        z0 = [p0[self.free]]
        for i, it in enumerate(insts):
            if it.kind in ("seat", "sphere"):
                self.centre_index[i] = k
                z0.append(states[i][:3])
                k += 3
            elif it.kind == "reference":
                rot = states[i][0:9].reshape(3, 3, order="F")
                self.ref = (i, k)
                z0 += [Rotation.from_matrix(rot).as_rotvec(), states[i][9:12]]
                k += 6
            else:
                raise ValueError(f"benchmark residual: no numpy version of {it.kind}")
        self.z0 = np.concatenate(z0)
        self.rows = []
        for g in prob.groups:
            cidx = np.array([self.centre_index.get(i, -1) for i in g["inst"]])
            radius = np.array([insts[i].radius or 0.0 for i in g["inst"]])
            self.rows.append((g["kind"], g["points"], cidx, radius))
        self.dist = [(self.centre_index[d.a], self.centre_index[d.b], d.length) for d in prob.distance_items]
        self.sigma = prob.sigma
        self.ref_xyz = None if data.points.ref is None else data.points.ref[:, 0]

    def params(self, z):
        p = self.p0.copy()
        p[self.free] = z[: len(self.free)]
        return p

    def __call__(self, z):
        p = self.params(z)
        x = self.model.ball_centres(self.q, self.w, p, self.aux)
        out = []
        for kind, pts, cidx, radius in self.rows:
            xi = x[pts]
            if kind == "seat":
                c = z[cidx[:, None] + np.arange(3)]
                out.append((xi - c).ravel())
            elif kind == "sphere":
                c = z[cidx[:, None] + np.arange(3)]
                out.append(np.linalg.norm(xi - c, axis=1) - radius)
            else:
                k = self.ref[1]
                rot = Rotation.from_rotvec(z[k:k + 3]).as_matrix()
                out.append((xi @ rot.T + z[k + 3:k + 6] - self.ref_xyz[pts]).ravel())
        for a, b, length in self.dist:
            out.append([np.linalg.norm(z[a:a + 3] - z[b:b + 3]) - length])
        return np.concatenate(out) / self.sigma

    def sparsity(self) -> sp.csr_matrix:
        """Which unknowns each residual row depends on (for scipy's grouped differences)."""
        rows, cols = [], []
        r = 0
        nf = len(self.free)
        for kind, pts, cidx, _ in self.rows:
            per = 3 if kind in ("seat", "reference") else 1
            for j in range(len(pts)):
                own = list(range(nf))
                own += list(range(self.ref[1], self.ref[1] + 6)) if kind == "reference" else \
                    [cidx[j], cidx[j] + 1, cidx[j] + 2]
                for _ in range(per):
                    rows += [r] * len(own)
                    cols += own
                    r += 1
        for a, b, _ in self.dist:
            rows += [r] * 6
            cols += [a, a + 1, a + 2, b, b + 1, b + 2]
            r += 1
        return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(r, len(self.z0)))


def _best(fun, repeats):
    best, out = np.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fun()
        best = min(best, time.perf_counter() - t)
    return best, out


def compare(model: ArmModel, n: int, scipy_methods=("lm", "trf-sparse")) -> dict:
    data = campaign(model, n)
    t_full, res = _best(lambda: calibrate(model, data, FitOptions(weights=WEIGHTS)), 2)
    free = [model.spec.index(nm) for nm in res.free]
    prob = Problem(model, data, WEIGHTS, free)
    p0 = np.zeros(model.spec.size)
    states0 = levenberg_marquardt(prob.with_free([]), p0, prob.initial_states(p0)).states
    t_lm, sol = _best(lambda: levenberg_marquardt(prob, p0, states0), 3)
    row = {"n": len(data), "params": len(free), "nuisance": prob.n_nuisance, "t_calibrate": t_full, "t_lm": t_lm,
           "iterations": sol.iterations, "cost": sol.cost, "p": sol.p[free]}
    fun = NumpyResidual(prob, p0, states0)
    assert abs(0.5 * np.sum(fun(fun.z0) ** 2) - 0.5 * np.sum(prob.evaluate(p0, states0, False).r ** 2)) \
        <= 1e-9 * (0.5 * np.sum(fun(fun.z0) ** 2))
    for method in scipy_methods:
        kw = dict(jac="2-point", x_scale="jac", ftol=1e-14, xtol=1e-14, gtol=1e-14, max_nfev=100000)
        if method == "lm":
            kw["method"] = "lm"
        else:
            kw.update(method="trf", jac_sparsity=fun.sparsity(), tr_solver="lsmr")
        t = time.perf_counter()
        s = least_squares(fun, fun.z0, **kw)
        t = time.perf_counter() - t
        ps = s.x[: len(free)]
        u = res.u
        row[method] = {"t": t, "status": s.status, "nfev": s.nfev, "cost": s.cost,
                       "rel_cost": abs(s.cost - sol.cost) / sol.cost,
                       "rel_p": float(np.linalg.norm(ps - sol.p[free]) / np.linalg.norm(sol.p[free])),
                       "max_dp_over_u": float(np.max(np.abs(ps - sol.p[free]) / u))}
    return row


def large_campaign(points: int, seed: int = 5) -> str:
    """A campaign TOML (``aacmm simulate``) of about ``points`` points for the nominal arm, its nuisance unknowns
    growing with the points as a long real campaign's do: 6 sphere positions (25 points a measurement, 25 % of the
    points), 4 planes (30 a measurement, 15 %), a ball bar (two spheres of 6 points a position, 20 %), 8 seat
    positions (20 articulations a measurement, 30 %) and tracker nests (3 articulations a nest, 10 %), the
    positions drawn (``seed``) over the arm's working volume; each measurement is an instance of its own (a centre,
    a plane, the bar's two centres linked by their certified length)."""
    rng = np.random.default_rng(seed)

    def place(height=(-0.05, 0.35)) -> str:
        a, radius = rng.uniform(-2.0, 2.0), rng.uniform(0.45, 0.7)
        return f"[{radius * math.cos(a) * 1e3:.1f}, {radius * math.sin(a) * 1e3:.1f}, {rng.uniform(*height) * 1e3:.1f}]"

    def count(share: float, per: int, tasks: int = 1) -> int:
        return max(1, round(share * points / per / tasks))

    tasks = [f'kind = "sphere"\nid = "sph{i}"\ncentre_mm = {place()}\ndiameter_mm = 25.4\npoints = 25\n'
             f"measurements = {count(0.25, 25, 6)}" for i in range(6)]
    tasks += [f'kind = "plane"\nid = "pl{i}"\npoint_mm = {place((-0.1, 0.0))}\nsize_mm = [200.0, 200.0]\npoints = 30\n'
              f"measurements = {count(0.15, 30, 4)}" for i in range(4)]
    tasks += [f'kind = "ballbar"\nid = "bar"\npositions = {count(0.2, 12)}\nlength_mm = 600.004\nu_length_mm = 0.0008\n'
              "points_per_sphere = 6"]
    # the seats after the spheres, planes and ball bar (residuals.csv names a point by its file and line: the order no
    # longer matters, kept so that the campaign stays the one measured)
    tasks += [f'kind = "seat"\nid = "seat{i}"\nposition_mm = {place()}\narticulations = 20\n'
              f"measurements = {count(0.3, 20, 8)}" for i in range(8)]
    tasks += [f'kind = "tracker"\nid = "nest"\nnests = {count(0.1, 3)}\narticulations = 3']
    head = (f'name = "large"\ndescription = "about {points} points"\nseed = {seed}\narm = "aacmm7"\nsensor = "xyz"\n'
            "[noise]\nprobing_repeatability_um = 2.0\nforce_noise_N = 0.01\n[operator]\nforce_mean_N = 1.5\n")
    return head + "".join(f"[[task]]\n{t}\n" for t in tasks)


#: what ``aacmm calibrate`` (default options) should take on a campaign of about 10^5 residual rows (45 000 points of
#: :func:`large_campaign`, 2.1-2.2 rows a point) on 2 cores
LARGE_TARGET = {"wall_s": 300.0, "peak_MiB": 2048.0}


def large(sizes=(450, 4500, 45_000)) -> list[dict]:
    """``aacmm calibrate`` (default options: the fit under one BLAS thread) on :func:`large_campaign` of each size,
    simulated first (``aacmm simulate --no-signals``): wall, CPU (user + system) and peak memory of the command
    (:func:`benchmarks.bench_io.run`), against :data:`LARGE_TARGET`."""
    import json
    import subprocess

    from benchmarks.bench_io import AACMM, run
    print(f"aacmm calibrate on a large campaign (default options); target at 10^5 rows: <= "
          f"{LARGE_TARGET['wall_s']:.0f} s wall, < {LARGE_TARGET['peak_MiB'] / 1024:.0f} GiB peak")
    print(f"{'points':>7} {'rows':>7} {'unknowns':>8} {'wall s':>8} {'CPU s':>8} {'peak MiB':>9}")
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            d = Path(tmp) / str(n)
            d.mkdir()
            (d / "c.toml").write_text(large_campaign(n))
            sim = d / "sim"
            subprocess.run(AACMM + ["simulate", str(d / "c.toml"), "--no-signals", "-q", "-o", str(sim)], check=True)
            wall, cpu, peak = run(["calibrate", sim / "points.csv", sim / "artefacts.toml", "--reference-points",
                                   sim / "points-ref.csv", "--arm", "aacmm7", "--no-plots", "-q", "-o", d / "cal"])
            summary = json.loads((d / "cal" / "summary.json").read_text())
            row = {"points": n, "rows": summary["n_residuals"], "wall": wall, "cpu": cpu, "peak": peak,
                   "unknowns": len(summary["free"]) + summary["n_nuisance"]}
            print(f"{n:>7} {row['rows']:>7} {row['unknowns']:>8} {wall:>8.1f} {cpu:>8.1f} {peak:>9.0f}", flush=True)
            out.append(row)
    return out


QUICK = {"sizes": (500, 1000), "scipy_sizes": (500,), "large_sizes": (450,)}   # make bench BENCH=--quick


def main(sizes=(500, 1000, 2000, 5000), scipy_sizes=(500, 1000, 2000), large_sizes=(450, 4500, 45_000)) -> dict:
    desc = load_description(ARM)
    model = ArmModel(desc, (EncoderEccentricity(joints=(0, 1, 2, 3, 4, 5), harmonics=(1,)),))
    print(f"model: {model.spec.size} parameters ({model.base_size} base + 12 eccentricity); times: best of 2-3 runs")
    print(f"{'points':>7} {'free':>5} {'nuis':>5} {'calibrate s':>12} {'LM s':>8} {'it':>3} | "
          f"{'scipy lm s':>10} {'x LM':>7} {'x cal':>6} {'rel p':>8} {'dp/u':>8} {'rel cost':>8} | "
          f"{'trf+sparsity s':>14} {'x LM':>6} {'rel p':>8}")
    rows = {}
    with blas_threads(1):               # both solvers under the same BLAS setting (one thread)
        for n in sizes:
            rows[n] = _report(model, n, scipy_sizes)
    print("x LM: scipy time / our LM time (same start, same free set); x cal: / our whole calibrate (identifiability "
          "twice, covariance, leverage); rel p: |p_scipy - p_ours| / |p_ours|; dp/u: max |difference| / reported u; "
          "rel cost: |cost_scipy - cost_ours| / cost_ours")
    print()
    rows["large"] = large(large_sizes)
    return rows


def _report(model, n, scipy_sizes) -> dict:
    row = compare(model, n, ("lm", "trf-sparse") if n in scipy_sizes else ())
    line = (f"{row['n']:>7} {row['params']:>5} {row['nuisance']:>5} {row['t_calibrate']:>12.3f} "
            f"{row['t_lm']:>8.3f} {row['iterations']:>3} | ")
    if "lm" in row:
        a, b = row["lm"], row["trf-sparse"]
        line += (f"{a['t']:>10.2f} {a['t'] / row['t_lm']:>7.1f} {a['t'] / row['t_calibrate']:>6.1f} "
                 f"{a['rel_p']:>8.1e} {a['max_dp_over_u']:>8.1e} {a['rel_cost']:>8.1e} | {b['t']:>14.2f} "
                 f"{b['t'] / row['t_lm']:>6.1f} "
                 f"{b['rel_p']:>8.1e}")
    else:
        line += "(scipy not run: minutes)"
    print(line, flush=True)
    return row


if __name__ == "__main__":
    main()
