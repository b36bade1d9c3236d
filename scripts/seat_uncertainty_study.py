#!/usr/bin/env python3
"""Does the uncertainty of the corrected centres hold on seat placements the fit never saw? Alternatives measured.

For every training placement of a seat data set (the real Panda's, or a simulated robot of
``scripts/sim_seats_study.py``), ``calibrate``'s default estimation (the URDF's masses: joint compliance under
gravity, the evidence's prior scales, the noise from the data) is fitted through the Python API and the other
placements are predicted. Each corrected centre's deviation from its seat's mean is compared with 1.96 u, for
``tip``'s u of the centre and for the deviation's own u (:func:`calibration.placements.deviation_u`), with the
model discrepancy of the extrapolative folds taken as

* ``none``: no discrepancy (the posterior, the probing scatter);
* ``constant``: the constant discrepancy of the extrapolative folds (``sigma_d^2``, their pooled excess; no growth);
* ``linear``: the default, ``sigma_0^2 + (g d)^2`` with ``d`` the joint motions' ball travel from the nearest
  training pose (:mod:`arm_model.discrepancy`);
* ``predictive``: the same with the uncertainty of ``sigma_0`` and ``g`` (their jackknife u) added to their squares,
  ``sigma_0^2 + u(sigma_0)^2 + (g^2 + u(g)^2) d^2`` (the spread of the plug-in estimate carried into the prediction);
* ``per-joint``: ``sigma_0^2 + sum_j g_j^2 c_j`` at the per-joint estimates (no uncertainty carried, no floor);
* ``written``: what the model file carries and ``tip`` adds (:attr:`calibration.discrepancy.Discrepancy.written`):
  a growth per joint, ``sigma_0^2 + sum_j g_j^2 c_j`` with each joint's own ball travel ``c_j`` from the nearest
  training pose, every estimate with its jackknife u carried and each joint's growth at least the ``predictive``
  one for every joint together;
* ``saturating``: a bounded growth ``sigma_0^2 + S^2 (1 - exp(-g^2 d^2 / S^2))`` (a stationary discrepancy's variance
  cannot exceed its total ``S^2``; ``S -> inf`` is ``linear``), fitted by maximum likelihood to the same held-out
  rows, with its likelihood ratio over ``linear`` (1 degree of freedom).

Each training's folds also judge the variants themselves (:func:`fold_check`): every fold is predicted by the
variant fitted on the other folds (leave one fold out), and the mean of its squared standardised errors says
whether the variant's variance holds on a fold it did not see (1) or over-states it (below 1). Per pair, the
coverage's aim is 90-97 %; :func:`band_odds` gives how often even an exact u lands outside it by chance.

With ``--parameter-covariance`` the fit's parameter covariance that every variant propagates is replaced by a
model-robust one estimated from the training data (:func:`robust_covariance`): ``jackknife``, the delete-one-point
jackknife of the parameters (the leave-one-out shifts of the fit, exact for the model linearised at the solution:
an HC3-type sandwich that holds when the model is wrong), taken in every direction where it exceeds the posterior
(:func:`lifted`); ``fold-shift``, the posterior plus the positive part of the parameters' spread between the
extrapolative folds beyond what the fit predicts for it (each fold's shift of the parameters when its poses at an
end of a joint's range are left out, against the shift's covariance under the model): a random-effects variance of
the parameters across the joint range, which grows away from the training poses through the Jacobian.

With ``--noise joint-play`` the training scatter is carried to the held-out points as play in the joints rather than
as the fit's isotropic probing scatter (:func:`fit_joint_play`: a variance per joint angle, propagated through each
point's joint Jacobian, plus an isotropic one, by maximum likelihood from the training centres' deviations from their
seats' means), so that it grows where the joints' levers are long.

It also says how much of the largest axis' deviations a linear function of the seven gravity torques explains
(R^2, within each seat): an error driven by the load that the model lacks.

    python scripts/seat_uncertainty_study.py                       # the real Panda (examples/data/real-panda-seats)
    python scripts/seat_uncertainty_study.py --sim r1,r4,r8        # simulated robots, each trained on every placement
    python scripts/seat_uncertainty_study.py --parameter-covariance fold-shift
    python scripts/seat_uncertainty_study.py --parameter-covariance region     # calibration.region's random effect
    python scripts/seat_uncertainty_study.py --noise joint-play
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

VARIANTS = ("none", "constant", "linear", "predictive", "per-joint", "written", "saturating")
#: the variants :func:`fold_check` refits without each fold
CHECKED = ("constant", "linear", "predictive", "per-joint", "written")
#: the parameter covariances :func:`robust_covariance` offers
COVARIANCES = ("posterior", "jackknife", "fold-shift")
#: ``--parameter-covariance``'s choices: those, and ``region``, the covariance file's of a fit with
#: ``FitOptions(region_effect=True)`` (the posterior plus the parameters' random effect between regions of the joint
#: space, :mod:`calibration.region`)
CHOICES = ("posterior", "region", "jackknife", "fold-shift")
#: how the training scatter is carried to the held-out points (``--noise``, :func:`fit_joint_play`)
NOISES = ("isotropic", "joint-play")
#: the aim for each pair's coverage [%]
BAND = (90.0, 97.0)


def fit_saturating(e, v, d) -> tuple[np.ndarray, float]:
    """(sigma_0^2 [m^2], g^2 [1], S^2 [m^2]) maximising the Gaussian likelihood of the held-out errors ``e`` [m]
    with variances ``v + sigma_0^2 + S^2 (1 - exp(-g^2 d^2 / S^2))``, and twice the minimised negative
    log-likelihood's half (the value :func:`calibration.discrepancy.fit_growth` compares)."""
    from scipy.optimize import minimize
    e2, d2 = np.asarray(e) ** 2, np.asarray(d) ** 2
    v = np.maximum(np.asarray(v, dtype=float), 1e-100)
    scale = np.array([np.mean(v), np.mean(v) / max(np.mean(d2), 1e-30), np.mean(v)])

    def nll(x):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            a, b, s = np.exp(x) * scale
            tot = v + a + s * -np.expm1(-b * d2 / s)
            f = 0.5 * float(np.sum(np.log(tot) + e2 / tot))
        return f if np.isfinite(f) else np.inf
    best = min((minimize(nll, np.array(x0, float), method="Nelder-Mead",
                         options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 4000})
                for x0 in ((-3, -3, 0), (-3, 0, 2), (-1, 0, 5), (-3, 1, 8), (0, -2, 0))), key=lambda r: r.fun)
    return np.exp(best.x) * scale, float(best.fun)


def variant_fit(name: str, e, v, c, fold) -> tuple[float, np.ndarray]:
    """``(sigma_0^2 [m^2], g_j^2 (J,) [1])`` of the discrepancy variant ``name`` (one of :data:`CHECKED`) fitted to
    held-out rows (errors ``e`` [m], predicted variances ``v`` [m^2], joint shares ``c`` (rows, J) [m^2], folds
    ``fold``) as :mod:`calibration.discrepancy` fits them."""
    from calibration.discrepancy import Discrepancy, fit_growth, fit_joint_growth
    nj = c.shape[1]
    if name == "constant":
        return max(float(np.mean(e ** 2 - v)), 0.0), np.zeros(nj)
    pooled = fit_growth(e, v, np.sqrt(c.sum(axis=1)), fold)
    us0, ug = float(np.nan_to_num(pooled.u_sigma0)), float(np.nan_to_num(pooled.u_growth))
    if name == "linear":
        return pooled.sigma0 ** 2, np.full(nj, pooled.growth ** 2)
    if name == "predictive":
        return pooled.sigma0 ** 2 + us0 ** 2, np.full(nj, pooled.growth ** 2 + ug ** 2)
    joints = fit_joint_growth(e, v, c, fold, pooled)
    if name == "per-joint":
        return joints.sigma0 ** 2, np.square(joints.growth)
    if name == "written":
        s0, g = Discrepancy(0.0, 1.0, 1, len(e), growth=pooled, joints=joints).written
        return s0 ** 2, np.broadcast_to(np.square(0.0 if g is None else g), (nj,)).astype(float)
    raise ValueError(f"unknown variant {name!r} (known: {', '.join(CHECKED)})")


def fold_check(e, v, c, fold, fit=variant_fit, names=CHECKED) -> dict:
    """Leave one fold out: each fold's rows predicted by each variant fitted (``fit(name, e, v, c, fold)``) on the
    other folds. ``{name: {"z2": mean of e^2 / (v + sigma_0^2 + c g^2) over the predicted rows, "loglik": their
    summed Gaussian log-likelihood}}``; a z2 below 1 says the variant states more variance than the unseen folds
    show."""
    e, v, c, fold = (np.asarray(x, dtype=float) for x in (e, v, c, fold))
    out = {k: {"z2": 0.0, "loglik": 0.0} for k in names}
    for f in np.unique(fold):
        rest, held = fold != f, fold == f
        for k in names:
            a, g2 = fit(k, e[rest], v[rest], c[rest], fold[rest])
            tot = v[held] + a + c[held] @ g2
            out[k]["z2"] += float(np.sum(e[held] ** 2 / tot)) / len(e)
            out[k]["loglik"] += float(-0.5 * np.sum(np.log(2 * np.pi * tot) + e[held] ** 2 / tot))
    return out


def band_odds(n: int, p: float = 0.95, band=BAND) -> tuple[float, float]:
    """``(below, above)``: the probability that, with an exact u, the share of ``n`` independent axis values within
    1.96 u (each inside with probability ``p``) falls below ``band[0]`` or above ``band[1]`` [%]."""
    from scipy.stats import binom
    lo = math.ceil(band[0] / 100 * n - 1e-9)
    hi = math.floor(band[1] / 100 * n + 1e-9)
    return float(binom.cdf(lo - 1, n, p)), float(binom.sf(hi, n, p))


@contextlib.contextmanager
def captured_linearisation():
    """Within the block, a dict that holds the last fit's linearisation at its solution, as
    :func:`calibration.calibrate` hands it to :func:`calibration.discrepancy.model_discrepancy` (``prob``, ``r``,
    ``factor``, ``var``: see there)."""
    mod = importlib.import_module("calibration.calibrate")
    got: dict = {}
    original = mod.model_discrepancy

    def spy(prob, r, factor, var, *args, **kwargs):
        got.update(prob=prob, r=r, factor=factor, var=var)
        return original(prob, r, factor, var, *args, **kwargs)
    mod.model_discrepancy = spy
    try:
        yield got
    finally:
        mod.model_discrepancy = original


def lifted(post, other) -> np.ndarray:
    """The covariance that is ``post`` where ``other`` is smaller and ``other`` where it is larger, direction by
    direction: ``P^1/2 max(I, P^-1/2 O P^-1/2) P^1/2`` (the eigenvalues of the whitened ``other`` floored at 1)."""
    w, vec = np.linalg.eigh(post)
    w = np.maximum(w, 1e-30 * w.max())
    half, inv_half = (vec * np.sqrt(w)) @ vec.T, (vec / np.sqrt(w)) @ vec.T
    lw, lv = np.linalg.eigh(0.5 * (inv_half @ other @ inv_half + (inv_half @ other @ inv_half).T))
    return half @ ((lv * np.maximum(lw, 1.0)) @ lv.T) @ half


def _positive_part(m) -> np.ndarray:
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    return (v * np.maximum(w, 0.0)) @ v.T


def _whitened(lin: dict) -> tuple:
    """``(factor, r)`` of the linearised fit ``lin`` with its rows divided by ``sqrt(var)``, so that a row's variance
    is 1 and ``factor`` (:class:`calibration.schur.BlockNormal` of ``A = J^T J / var + diag(damping)``, the prior's
    precision as the fit put it in its normal matrix) gives the posterior itself, as the result's covariance is
    computed: ``(J^T J / var + P)^-1``."""
    from calibration.schur import BlockNormal
    factor, r, var = lin["factor"], lin["r"], lin["var"]
    return BlockNormal(factor.j / math.sqrt(var), factor.n_par, factor.damping), r / math.sqrt(var)


def robust_covariance(name: str, k: int, lin: dict) -> np.ndarray:
    """The covariance of the first ``k`` (column-scaled) unknowns of the linearised fit ``lin``
    (:func:`captured_linearisation`, rows whitened by :func:`_whitened`): ``posterior`` ``A^-1``; ``jackknife`` it
    :func:`lifted` to the delete-one-point jackknife ``sum_O d_O d_O^T`` (``d_O`` the change of the unknowns from the
    fit without point O's rows to the fit with them, :func:`calibration.discrepancy.group_deletions`); ``fold-shift``
    it plus the positive part of ``mean_F (d_F d_F^T - C_F)`` over the extrapolative folds F
    (:func:`calibration.discrepancy.extreme_folds`), ``C_F = Z_F^T (I - H_FF)^-1 Z_F`` (``Z_F = J_F A^-1``) the
    covariance of ``d_F`` when the model holds."""
    from calibration.discrepancy import deletion_shift, extreme_folds, group_deletions, holdable
    prob = lin["prob"]
    factor, r = _whitened(lin)
    js, solve = factor.j, factor.solve
    post = solve(np.eye(js.shape[1])[:, :k])[:k]
    rp = prob.row_point
    point_rows = (prob.row_distance < 0) & (rp >= 0)
    pts = np.unique(rp[point_rows])
    if name == "posterior":
        return post
    if name == "jackknife":
        groups = [np.flatnonzero(point_rows & (rp == i)) for i in pts]
        dels = group_deletions(factor, r, groups)
        shifts = np.array([deletion_shift(factor, o, e)[:k] for o, (e, _) in zip(groups, dels, strict=True)
                           if e is not None])
        return lifted(post, shifts.T @ shifts)
    if name != "fold-shift":
        raise ValueError(f"unknown parameter covariance {name!r} (known: {', '.join(COVARIANCES)})")
    excess, n = np.zeros((k, k)), 0
    for fold in extreme_folds(prob.data.points.q[pts]):
        rows = np.flatnonzero(point_rows & np.isin(rp, sorted(holdable(prob, pts[fold]))))
        e, m = group_deletions(factor, r, [rows])[0] if len(rows) else (None, None)
        if e is None:
            continue
        d = deletion_shift(factor, rows, e)
        z = solve(js[rows].toarray().T).T[:, :k]
        excess += np.outer(d[:k], d[:k]) - z.T @ m @ z
        n += 1
    return post + _positive_part(excess / max(n, 1))


def joint_blocks(model, p, d) -> np.ndarray:
    """(N, J, 3, 3) [m^2/rad^2]: for every point of the calibration data ``d`` and every joint j, ``J_j J_j^T``,
    the ball's motion per radian of joint j (per metre of a prismatic one) times its transpose, at parameters ``p``."""
    from arm_model.uncertainty import default_inputs, propagate
    nj = model.desc.n_joints
    out = []
    for j in range(nj):
        inputs = default_inputs(model.desc, has_force=False, probing=0.0, discrepancy=0.0, encoder=np.eye(nj)[j])
        out.append(propagate(model, p, d.points.q, d.wrench, d.aux, inputs=inputs).cov)
    return np.stack(out, axis=1)


def fit_joint_play(dev, blocks, weight) -> tuple[np.ndarray, float, float]:
    """``(sd_q (J,) [rad], sd_iso [m], lr)``: the maximum likelihood of deviations ``dev`` (N, 3) [m] of centres from
    their seat's mean, each ``N(0, w_i (sum_j sd_q_j^2 B_ij + sd_iso^2 I))`` (``blocks`` B (N, J, 3, 3) from
    :func:`joint_blocks`, ``weight`` w (N,) ``1 - 1/n`` of the seat's n points), and twice the log-likelihood it
    gains over the isotropic scatter alone (``sd_q = 0``; about chi-square with J degrees of freedom). A joint that
    moves the ball less than :data:`calibration.discrepancy.RESOLVED_TRAVEL` of the most moving joint's (RMS lever:
    its axis passes near the ball) keeps ``sd_q = 0``: the deviations cannot see its play."""
    from scipy.optimize import minimize

    from calibration.discrepancy import RESOLVED_TRAVEL
    nj = blocks.shape[1]
    lever2 = np.einsum("njii->j", blocks) / len(dev)
    seen = np.sqrt(lever2) >= RESOLVED_TRAVEL * math.sqrt(float(lever2.max()))
    scale = np.full(nj + 1, float(np.mean(dev ** 2)))
    scale[:nj] /= np.maximum(lever2, 1e-30)                     # unknowns of order 1

    def nll(x):
        var = np.exp(x) * scale * np.r_[seen, True]
        c = (np.einsum("j,njab->nab", var[:nj], blocks) + var[nj] * np.eye(3)) * weight[:, None, None]
        return 0.5 * float(np.sum(np.linalg.slogdet(c)[1] + np.einsum("na,nab,nb->n", dev, np.linalg.inv(c), dev)))
    bounds = [(-30.0, 5.0)] * (nj + 1)
    best = min((minimize(nll, np.full(nj + 1, x0), method="L-BFGS-B", bounds=bounds) for x0 in (-3.0, -1.0)),
               key=lambda r: r.fun)
    iso = minimize(lambda x: nll(np.r_[np.full(nj, -30.0), x]), np.zeros(1), method="L-BFGS-B", bounds=bounds[:1])
    var = np.exp(best.x) * scale * np.r_[seen, True]
    return np.sqrt(var[:nj]), float(math.sqrt(var[nj])), max(2 * (iso.fun - best.fun), 0.0)


def _seat_deviations(centres, feature, holes) -> np.ndarray:
    dev = np.zeros_like(centres)
    for h in holes:
        sel = feature == h
        dev[sel] = centres[sel] - centres[sel].mean(axis=0)
    return dev


def _linear_nll(g) -> float:
    tot = g.v + g.sigma0 ** 2 + (g.growth * g.d) ** 2
    return 0.5 * float(np.sum(np.log(tot) + g.e ** 2 / tot))


def _load_r2(desc, q, feature, dev) -> float:
    """R^2 of the largest axis' deviations ``dev`` on the gravity torques at ``q`` (and each seat's own mean)."""
    from arm_model import PinocchioArm
    tau, _ = PinocchioArm(desc).torques(q, None)
    ax = int(np.argmax(dev.std(axis=0)))
    a = np.column_stack([tau] + [(feature == h).astype(float) for h in np.unique(feature)])
    c, *_ = np.linalg.lstsq(a, dev[:, ax], rcond=None)
    return 1.0 - float(np.var(dev[:, ax] - a @ c) / np.var(dev[:, ax]))


def study(root: Path, urdf: Path, tip: str, places, holes, say=print, covariance: str = "posterior",
          noise: str = "isotropic") -> list[dict]:
    """One row per training placement and held-out placement: per variant, the coverage [%] of tip's u and of the
    deviation's u, the median and mean u [m]; the discrepancy fitted (linear and saturating) and the load R^2.
    ``covariance``: the parameter covariance propagated (:data:`CHOICES`, :func:`robust_covariance`); ``noise``:
    the training scatter as the fit's probing scatter or as joint play (:data:`NOISES`, :func:`fit_joint_play`)."""
    from arm_model.discrepancy import GrowingDiscrepancy, TrainingPoses, travel_shares
    from arm_model.effects import JointCompliance
    from arm_model.io import read_artefacts, read_points
    from arm_model.model import ArmModel
    from arm_model.uncertainty import ParameterCovariance, default_inputs, propagate
    from arm_model.urdf_import import load_arm
    from calibration import FitOptions, calibrate, make_data
    from calibration.model_output import discrepancy_fields
    from calibration.placements import deviation_u
    from calibration.region import predictive_covariance
    desc = load_arm(urdf, tip)
    model = ArmModel(desc, (JointCompliance(),))     # calibrate's default for a URDF whose links carry masses
    art = read_artefacts(root / "artefacts.toml")
    data = {p: make_data(read_points(root / p / "points.csv", desc.n_joints), art, model) for p in places}
    rows = []
    for tr in places:
        with captured_linearisation() as lin:
            res = calibrate(model, data[tr], FitOptions(weights_from_data=True, region_effect=covariance == "region"))
        cov_p = predictive_covariance(res)
        if covariance not in ("posterior", "region"):   # in the fit's scaled unknowns, scaled back by the posterior's
            post, robust = (robust_covariance(c, len(res.free), lin) for c in ("posterior", covariance))
            scale = np.sqrt(np.diag(res.cov) / np.diag(post))
            cov_p = robust * np.outer(scale, scale)
        g, joints = res.discrepancy.growth, res.discrepancy.joints
        check = fold_check(g.e, g.v, joints.c, g.fold)
        fitted = {k: variant_fit(k, g.e, g.v, joints.c, g.fold) for k in ("constant", "per-joint")}
        say(f"{root.name}: {tr}: leave one fold out, mean z^2 / log-likelihood: "
            + "; ".join(f"{k} {x['z2']:.2f} / {x['loglik']:.1f}" for k, x in check.items()))
        (a, b, s), nll_sat = fit_saturating(g.e, g.v, g.d)
        lr = max(2 * (_linear_nll(g) - nll_sat), 0.0)
        train = TrainingPoses.of(desc, data[tr].points.q[res.discrepancy.training_rows])
        fields = discrepancy_fields(res)
        written = GrowingDiscrepancy(fields["model_discrepancy"], fields["discrepancy_growth"] or 0.0, train)
        inputs = default_inputs(desc, has_force=False, probing=res.probing_scatter() or 0.0, discrepancy=0.0)
        play = None
        if noise == "joint-play":
            d = data[tr]
            centres = propagate(model, res.p, d.points.q, d.wrench, d.aux, inputs=inputs).centres
            n_seat = np.array([np.sum(d.points.feature == f) for f in d.points.feature])
            sel = np.isin(d.points.feature, holes)
            play = fit_joint_play(_seat_deviations(centres, d.points.feature, holes)[sel],
                                  joint_blocks(model, res.p, d)[sel], (1.0 - 1.0 / n_seat)[sel])
            inputs = default_inputs(desc, has_force=False, probing=play[1], discrepancy=0.0,
                                    encoder=np.hypot(inputs.encoder, play[0]))
            say(f"{root.name}: {tr}: joint play [urad] {', '.join(f'{x * 1e6:.0f}' for x in play[0])}, isotropic "
                f"{play[1] * 1e6:.0f} um (likelihood ratio over the isotropic alone {play[2]:.1f}); probing "
                f"scatter {(res.probing_scatter() or 0.0) * 1e6:.0f} um")
        for te in places:
            if te == tr:
                continue
            d = data[te]
            prop = propagate(model, res.p, d.points.q, d.wrench, d.aux, inputs=inputs, systematic=True,
                             parameters=ParameterCovariance(tuple(res.free), cov_p))
            dist, shares = travel_shares(desc, d.points.q, train)
            extra = {"none": 0 * dist, "constant": fitted["constant"][0] + 0 * dist,
                     "linear": g.sigma0 ** 2 + (g.growth * dist) ** 2,
                     "per-joint": fitted["per-joint"][0] + shares @ fitted["per-joint"][1],
                     "predictive": g.sigma0 ** 2 + g.u_sigma0 ** 2 + (g.growth ** 2 + g.u_growth ** 2) * dist ** 2,
                     "written": written.sd(desc, d.points.q) ** 2,
                     "saturating": a + s * -np.expm1(-b * dist ** 2 / s)}
            feat = d.points.feature
            dev = _seat_deviations(prop.centres, feat, holes)
            row = {"train": tr, "test": te, "fold_check": check, "sigma0_um": g.sigma0 * 1e6,
                   "covariance": covariance, "noise": noise,
                   "joint_play": None if play is None else {"sd_urad": (play[0] * 1e6).tolist(),
                                                            "isotropic_um": play[1] * 1e6, "lr": play[2]},
                   "growth_um_per_mm": g.growth * 1e3,
                   "u_growth_um_per_mm": g.u_growth * 1e3, "saturation_um": math.sqrt(s) * 1e6, "lr_saturating": lr,
                   "d_max_mm": g.d_max * 1e3, "d_test_median_mm": float(np.median(dist)) * 1e3,
                   "load_r2": _load_r2(desc, d.points.q, feat, dev),
                   "dev_rms_um": (np.sqrt((dev ** 2).mean(axis=0)) * 1e6).tolist()}
            cov = prop.cov
            for name, s2 in extra.items():
                prop.cov = cov + np.einsum("n,ij->nij", s2, np.eye(3))    # the discrepancy: each point's own, per axis
                u, u_dev = prop.u, deviation_u(prop, feat, holes)
                sel = np.isin(feat, holes)
                row[name] = {"inside": float(np.mean(np.abs(dev[sel]) <= 1.96 * u[sel])) * 100,
                             "inside_dev": float(np.mean(np.abs(dev[sel]) <= 1.96 * u_dev[sel])) * 100,
                             "z2_dev": float(np.mean((dev[sel] / u_dev[sel]) ** 2)),
                             "median_u_um": float(np.median(u[sel])) * 1e6, "values": int(sel.sum()) * 3,
                             "mean_u_um": float(np.mean(u[sel])) * 1e6,
                             "mean_u_dev_um": float(np.mean(u_dev[sel])) * 1e6,
                             "inside_dev_axes": (np.mean(np.abs(dev[sel]) <= 1.96 * u_dev[sel], axis=0) * 100).tolist()}
            rows.append(row)
            say(f"{root.name}: {tr} -> {te}: g {row['growth_um_per_mm']:.2f} +- {row['u_growth_um_per_mm']:.2f} um/mm, "
                f"S {row['saturation_um']:.0f} um (LR {lr:.2f}); load R2 {row['load_r2']:.2f}; "
                + "; ".join(f"{k} {row[k]['inside']:.1f} / {row[k]['inside_dev']:.1f} % "
                            f"(u {row[k]['median_u_um']:.0f} um)"
                            for k in VARIANTS))
    return rows


def pooled(rows: list[dict]) -> str:
    """Markdown: per variant, pooled and per-pair coverage (tip's u / the deviation's u), the pairs whose coverage
    of the deviation's u lies in :data:`BAND`, above and below it, the median over the pairs of the deviations' mean
    square in units of their u (1 when u is right), and the median u."""
    out = ["| discrepancy | within 1.96 u, tip's u: pooled (pairs) | the deviation's u: pooled (pairs) "
           f"| pairs in {BAND[0]:.0f}-{BAND[1]:.0f} / above / below | median z² | median u [um] |",
           "|---|---|---|---|---|---|"]
    for k in VARIANTS:
        n = np.array([r[k]["values"] for r in rows])
        a, b = (np.array([r[k][key] for r in rows]) for key in ("inside", "inside_dev"))
        inside = int(np.sum((b >= BAND[0]) & (b <= BAND[1])))
        out.append(f"| {k} | {np.sum(a * n) / n.sum():.1f} % ({a.min():.1f}-{a.max():.1f}) | "
                   f"{np.sum(b * n) / n.sum():.1f} % ({b.min():.1f}-{b.max():.1f}) | "
                   f"{inside} / {int(np.sum(b > BAND[1]))} / {int(np.sum(b < BAND[0]))} | "
                   f"{np.median([r[k]['z2_dev'] for r in rows]):.2f} | "
                   f"{np.median([r[k]['median_u_um'] for r in rows]):.0f} |")
    n_pair = int(np.median([r[VARIANTS[0]]["values"] for r in rows]))
    below, above = band_odds(n_pair)
    out.append(f"\nWith an exact u and independent values, a pair of {n_pair} values lands above "
               f"{BAND[1]:.0f} % with probability {above:.3f}, below {BAND[0]:.0f} % with {below:.4f}.")
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sim", default=None, help="comma-separated simulated robots of scripts/sim_seats_study.py "
                   "(default: the real Panda data)")
    p.add_argument("--parameter-covariance", choices=CHOICES, default="posterior",
                   help="the parameter covariance every variant propagates (default: the fit's posterior; region: "
                        "with the parameters' random effect between regions, as the covariance file of a fit with "
                        "FitOptions(region_effect=True))")
    p.add_argument("--noise", choices=NOISES, default="isotropic",
                   help="the training scatter carried as the fit's probing scatter (default) or as joint play")
    p.add_argument("-o", "--output", type=Path, default=Path("out/seat-uncertainty"), help="output folder")
    args = p.parse_args(argv)
    import json
    say = lambda m: print(m, file=sys.stderr, flush=True)    # noqa: E731
    rows = []
    if args.sim:
        sys.path.insert(0, str(ROOT / "scripts"))
        import sim_seats_study as sim
        known = {r.name: r for r in sim.ROBOTS}
        for name in args.sim.split(","):
            if name not in known:
                p.error(f"unknown robot {name!r} (known: {', '.join(known)})")
            folder = args.output / name
            sim.simulate_robot(known[name], folder)
            rows += study(folder, sim.URDF, sim.TIP, list(sim.PLACES), sim.HOLES, say, args.parameter_covariance,
                          args.noise)
    else:
        data = ROOT / "examples" / "data" / "real-panda-seats"
        rows = study(data, data / "panda-with-inertials.urdf", "ball_link", ["front", "right", "back-high"],
                     ("hole-0", "hole-1"), say, args.parameter_covariance, args.noise)
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
    print(pooled(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
