#!/usr/bin/env python3
"""Where one parameter's error comes from in single runs of ``aacmm study montecarlo`` (the study behind
docs/uncertainty.md's account of ``j5.a``).

For each seed the campaign is simulated and calibrated as the study does (training measurements of a
25 % held-out split, default free parameters, weights from the data). Linearised at the fit:

* ``a``: the sensitivity of the parameter's estimate to the ball centre of every fitted point (central
  differences through the fit's own weighted residuals, the nuisance eliminated);
* the spread ``sigma |a|`` the estimate has under the simulator's probing noise (``sigma`` per axis,
  independent per point), against the reported ``u``, and the standard deviation of ``a . n / u`` over
  fresh draws ``n`` of that noise;
* the realized reading noise of the run (the truth model's ball centres from the readings minus the true
  centres: probing noise, encoder quantisation, force noise) projected on ``a``, against the error
  (estimate minus the truth in the fit's parameterization).

    python scripts/noise_projection_study.py examples/campaigns/calibration.toml --seeds 0,1,20

Prints one line a seed and writes ``results.json`` into ``-o`` when given.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def sensitivity(res, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(a, used): d(estimate of ``name``)/d(ball centre) (n_used, 3) [1 for a length, rad/m for an angle]
    of the fit ``res``, and the indices of the fitted points (into ``res.data``)."""
    from calibration.identifiability import reduced_jacobian
    from calibration.problem import Problem
    from calibration.solver import levenberg_marquardt

    spec = res.model.spec
    prob = Problem(res.model, res.data, res.weights, [spec.index(n) for n in res.free], reference=res.reference_mode)
    states = levenberg_marquardt(prob.with_free([]), res.p, prob.initial_states(res.p)).states
    ev = prob.evaluate(res.p, states)
    jr = reduced_jacobian(ev.jp, ev.jt)
    g = -np.linalg.solve(jr.T @ jr, jr.T)[res.free.index(name)]     # d estimate / d weighted residual
    own = prob.centres
    shift = np.zeros((len(prob.used), 3))
    prob.centres = lambda p, jac=False, columns=None: (lambda x, d: (x + shift, d))(*own(p, jac, columns))
    h = 1e-9
    a = np.zeros_like(shift)
    for i in range(len(shift)):
        for c in range(3):
            out = []
            for s in (h, -h):
                shift[:] = 0.0
                shift[i, c] = s
                out.append(g @ prob.evaluate(res.p, states, jac=False).r)
            a[i, c] = (out[0] - out[1]) / (2 * h)
    return a, prob.used


def one(campaign, seed: int, name: str, draws: int) -> dict:
    from arm_model.model import ArmModel
    from arm_model.sim import simulate
    from calibration.calibrate import FitOptions, calibrate
    from calibration.data import make_data, split_holdout

    sim = simulate(campaign, seed=seed, progress=lambda m: None)
    model = ArmModel(campaign.arm, ())
    data = make_data(sim.points, sim.artefacts, model, reference=sim.reference_points)
    train, _ = split_holdout(data, 0.25, seed)
    res = calibrate(model, train, FitOptions(weights_from_data=True))
    spec = model.spec
    k = res.free.index(name)
    p_true = spec.vector({n: v for n, v in sim.truth["p"].items() if n in spec.names})
    error = float(res.p[spec.index(name)] - res.equivalent(p_true)[spec.index(name)])
    a, used = sensitivity(res, name)
    # the realized reading noise of every point: the truth model's ball centres from the readings minus
    # the true centres (rows of the training data: points rows, then the tracker's, as make_data merges them)
    truth_model = sim.truth["model"]
    everything = make_data(sim.points, sim.artefacts, truth_model, reference=sim.reference_points)
    true_all = (sim.true_centres if sim.reference_points is None
                else np.vstack([sim.true_centres, sim.ref_true_centres]))
    noise_all = truth_model.ball_centres(everything.points.q, everything.wrench, sim.truth["p_vector"],
                                         everything.aux) - true_all
    key_all = {(everything.file_of(i), int(ln)): i for i, ln in enumerate(everything.points.lines)}
    rows = np.array([key_all[(res.data.file_of(i), int(res.data.points.lines[i]))] for i in used])
    noise = noise_all[rows]
    u = float(res.u[k])
    sigma = float(campaign.noise["probing_repeatability"])
    rng = np.random.default_rng(seed)
    fresh = np.array([np.sum(a * rng.normal(0.0, sigma, a.shape)) for _ in range(draws)]) / u
    realized = float(np.sum(a * noise))
    return {"seed": seed, "parameter": name, "error": error, "u": u, "z": error / u,
            "spread_over_u": sigma * float(np.linalg.norm(a)) / u, "fresh_sd": float(fresh.std()),
            "z_realized_noise": realized / u, "z_rest": (error - realized) / u,
            "largest_point_share": float(np.max(np.abs(np.sum(a * noise, axis=1)))) / u, "points": int(len(used))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--seeds", default="0,1,20", help="comma-separated seeds (default 0,1,20)")
    ap.add_argument("--parameter", default="j5.a")
    ap.add_argument("--draws", type=int, default=4000, help="fresh noise draws (default 4000)")
    ap.add_argument("-o", "--output", type=Path)
    args = ap.parse_args(argv)
    from arm_model.sim import load_campaign
    campaign = load_campaign(args.campaign)
    out = []
    for s in (int(t) for t in args.seeds.split(",")):
        r = one(campaign, s, args.parameter, args.draws)
        out.append(r)
        print(f"seed {s} {r['parameter']}: z {r['z']:+.2f} (error {r['error'] * 1e6:+.3f}, u {r['u'] * 1e6:.3f}); "
              f"spread under the probing noise / u {r['spread_over_u']:.2f}, fresh draws sd {r['fresh_sd']:.2f}; "
              f"the run's reading noise gives z {r['z_realized_noise']:+.2f}, the rest {r['z_rest']:+.2f}; "
              f"largest one point {r['largest_point_share']:.2f}")
    if args.output:
        args.output.mkdir(parents=True, exist_ok=True)
        (args.output / "results.json").write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
