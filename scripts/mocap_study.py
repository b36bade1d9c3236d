#!/usr/bin/env python3
"""Held-out postures of a motion-capture (tracker) campaign: fit ``calibrate`` on some postures, predict the
others with the training fit's instrument frame and marker offset, report the RMS and max of the markers' 3D
errors [mm], for the like-for-like nominal (frame and marker fitted, nothing else) and for each model asked.

Splits (a posture is one measurement of the points file): ``--holdout ID,ID`` (the data's own split, if it
states one), random halves (``--halves`` seeds), and random subsamples of ``--sizes`` postures (``--seeds``
seeds each), the rest held out. Seeds are numpy's default_rng; the same seeds give the same splits.

``--floor`` also says how much of a held-out error is the instrument's noise: each model fitted on every
posture (its residual RMS per axis of the instrument and in 3D, and that 3D figure with the fit's degrees of
freedom counted: the noise floor no prediction of a posture beats) and each posture predicted from all the
others (the leave-one-out RMS: the held-out error with as much data as the campaign has).

``--exact N`` also says how much of a held-out error the model itself would leave if it were exact: each model
fitted on every posture is taken as the truth, its predicted markers plus Gaussian noise of the noise floor's
size per axis (N draws, seeds 0...) make N campaigns it describes exactly, and the same splits are fitted and
predicted on them (a parametric bootstrap: the held-out RMS of an exact model at this noise and design).

``--compare-halves`` also fits each random half's complement (the held-out postures as training) and compares the
two fits' parameters: for those both estimate, the difference over its standard uncertainty (both fits' u
combined), their RMS and how many lie beyond 2, and the parameters only one fit estimates (the other held them):
whether the halves tell different geometries or the same one within its uncertainty.

    python scripts/mocap_study.py ../shared/data/real-talos-mocap/points.csv \\
        --arm ../shared/data/real-talos-mocap/talos_full_v2.urdf --tip-frame gripper_left_base_link \\
        --holdout pose-02,pose-04,...  --effects none,joint_compliance
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from arm_model.effects import effect_from_name  # noqa: E402
from arm_model.io import read_points  # noqa: E402
from arm_model.model import ArmModel  # noqa: E402
from arm_model.tracker import marker_positions  # noqa: E402
from arm_model.urdf_import import load_arm  # noqa: E402
from calibration import FitOptions, calibrate, make_data  # noqa: E402
from calibration.calibrate import nominal_baseline  # noqa: E402
from calibration.data import split_holdout  # noqa: E402
from calibration.model_output import refine_torques, with_fitted_torques  # noqa: E402


def splits(ids: list, holdout: list | None, halves: int, sizes: list, seeds: int) -> list:
    """(name, held-out ids) of every split asked."""
    out = [("stated", list(holdout))] if holdout else []
    for s in range(halves):
        train = set(np.random.default_rng(100 + s).choice(ids, len(ids) // 2 + len(ids) % 2, replace=False))
        out.append((f"half{s}", [m for m in ids if m not in train]))
    for n in sizes:
        for s in range(seeds):
            train = set(np.random.default_rng(1000 * n + s).choice(ids, n, replace=False))
            out.append((f"n{n}s{s}", [m for m in ids if m not in train]))
    return out


def error_vectors(res, test) -> np.ndarray:
    """Each posture's marker error (N, 3) [mm] along the instrument's axes, frame and marker offset of the fit."""
    x = marker_positions(res.model, res.p, test.points.q, res.tracker, test.sessions, test.aux)[:, 0]
    return (x - test.reference) * 1e3


def errors(res, test) -> np.ndarray:
    """Each held-out posture's marker 3D error [mm], frame and marker offset of the training fit."""
    return np.linalg.norm(error_vectors(res, test), axis=1)


#: the options of every fit (``--prior-groups`` sets its prior groups)
FIT = FitOptions(weights_from_data=True)


def fitted(model, train):
    """``calibrate``'s default fit of ``model`` on ``train`` as ``aacmm calibrate`` makes it: the noise from the
    data, the torques refined on the calibrated description."""
    return refine_torques(calibrate(model, train, FIT))


def predicted(res, test) -> np.ndarray:
    """The held-out postures' 3D errors [mm] of the fit ``res`` (their torques refined as the fit's)."""
    return errors(res, with_fitted_torques(test, res))


def noise_floor(model, data, ids: list) -> dict:
    """The fit of ``model`` on every posture of ``data``: its residual RMS per axis [mm] and in 3D, the 3D
    figure times sqrt(residuals / degrees of freedom) (the noise floor), and the leave-one-out RMS [mm] over
    the postures ``ids``, each predicted from all the others."""
    res = fitted(model, data)
    e = error_vectors(res, with_fitted_torques(data, res))
    loo = np.concatenate([predicted(fitted(model, train), test)
                          for train, test in (split_holdout(data, [m]) for m in ids)])
    rms3 = float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))
    return {"fit_rms_axes_mm": np.sqrt(np.mean(e ** 2, axis=0)).tolist(), "fit_rms_mm": rms3,
            "floor_mm": rms3 * float(np.sqrt(res.n_residuals / res.dof)), "dof": int(res.dof),
            "loo_rms_mm": float(np.sqrt(np.mean(loo ** 2))), "loo_errors_mm": loo.tolist()}


def exact_campaigns(model, pts, data, draws: int) -> tuple[float, list]:
    """The noise floor per axis [m] of ``model`` fitted on every posture of ``data``, and ``draws`` copies of the
    points ``pts`` whose markers are that fit's predictions (its frame, marker offset and torques) plus Gaussian
    noise of that size per axis (numpy default_rng seeds 0, 1, ...): campaigns the model describes exactly."""
    if pts.ref is None or pts.ref.shape[1] != 1 or len(data.points) != len(pts):
        raise ValueError("exact campaigns need one marker a row, every row a reference point")
    res = fitted(model, data)
    at = with_fitted_torques(data, res)
    x = marker_positions(res.model, res.p, at.points.q, res.tracker, at.sessions, at.aux)[:, 0]
    sigma = float(np.sqrt(np.mean((x - at.reference) ** 2) * res.n_residuals / res.dof))
    return sigma, [dataclasses.replace(pts, ref=(x + np.random.default_rng(s).normal(0.0, sigma, x.shape))[:, None, :])
                   for s in range(draws)]


def compare_fits(a, b) -> dict:
    """The parameters of two fits ``a``, ``b`` (:class:`~calibration.CalibrationResult`): for those both estimate,
    ``z = (a - b) / hypot(u_a, u_b)``, with each fit's state (free, prior-dominated); the largest |z| first."""
    common = [n for n in a.free if n in b.free]
    rows = sorted(({"name": n, "z": (a.value(n) - b.value(n)) / float(np.hypot(a.uncertainty(n), b.uncertainty(n))),
                    "states": [a.state(n), b.state(n)]} for n in common), key=lambda r: -abs(r["z"]))
    z = np.array([r["z"] for r in rows])
    return {"z_rms": float(np.sqrt(np.mean(z ** 2))) if len(z) else None, "beyond_2": int(np.sum(np.abs(z) > 2)),
            "common": len(common), "only_first": sorted(set(a.free) - set(b.free)),
            "only_second": sorted(set(b.free) - set(a.free)), "parameters": rows}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("points", type=Path, help="points file: one measurement a posture, reference coordinates")
    p.add_argument("--arm", type=Path, required=True, help="the robot's URDF")
    p.add_argument("--tip-frame", required=True, help="the link the marker is fixed on")
    p.add_argument("--holdout", default="", help="the data's own held-out postures (comma-separated ids)")
    p.add_argument("--halves", type=int, default=5, help="random halves (seeds 100...)")
    p.add_argument("--sizes", default="17,25,45", help="sizes of the random training subsamples")
    p.add_argument("--seeds", type=int, default=3, help="seeds of each subsample size")
    p.add_argument("--effects", default="none,joint_compliance",
                   help="models to compare: 'none' (geometry) or effect names joined by '+', comma-separated")
    p.add_argument("--floor", action="store_true",
                   help="also the noise floor (each model fitted on every posture) and the leave-one-out RMS")
    p.add_argument("--exact", type=int, default=0,
                   help="also N campaigns each model describes exactly (its fit on every posture plus noise)")
    p.add_argument("--compare-halves", action="store_true",
                   help="also fit each random half's held-out postures and compare the two fits' parameters")
    p.add_argument("--prior-groups", choices=("separate", "pooled"), default="separate",
                   help="the prior's groups of every fit (FitOptions.prior_groups; default separate)")
    p.add_argument("-o", "--output", type=Path, default=None, help="write the results as JSON here")
    args = p.parse_args(argv)
    global FIT
    FIT = dataclasses.replace(FIT, prior_groups=args.prior_groups)
    if args.exact < 0:
        p.error("--exact: a number of draws, 0 or more")
    desc = load_arm(args.arm, args.tip_frame)
    pts = read_points(args.points, desc.n_joints)
    ids = list(dict.fromkeys(pts.measurement.tolist()))
    models = {name: ArmModel(desc, tuple(effect_from_name(e) for e in name.split("+") if e != "none"))
              for name in args.effects.split(",")}
    data = {name: make_data(pts, None, m) for name, m in models.items()}
    sizes = [int(v) for v in args.sizes.split(",") if v]
    exact = {name: [make_data(sim, None, m) for sim in exact_campaigns(m, pts, data[name], args.exact)[1]]
             for name, m in models.items()} if args.exact else {}
    results = {}
    for split, held in splits(ids, [h for h in args.holdout.split(",") if h], args.halves, sizes, args.seeds):
        row = {}
        first = next(iter(models))
        train, test = split_holdout(data[first], held)
        row["nominal"] = errors(nominal_baseline(models[first], train, FIT), test)
        compared = {}
        for name, m in models.items():
            train, test = split_holdout(data[name], held)
            res = fitted(m, train)
            row[name] = predicted(res, test)
            if args.compare_halves and split.startswith("half"):
                other = fitted(m, split_holdout(data[name], [i for i in ids if i not in held])[0])
                compared[name] = compare_fits(res, other)
                c = compared[name]
                print(f"{split:8s} {name}: the halves' {c['common']} common parameters, z RMS {c['z_rms']:.2f}, "
                      f"{c['beyond_2']} beyond 2 (" + ", ".join(f"{r['name']} {r['z']:+.2f}"
                                                            for r in c["parameters"][:3]) + f"); only one half: "
                      f"{len(c['only_first']) + len(c['only_second'])}", flush=True)
        for name, sims in exact.items():       # (the held-out errors of every draw together)
            row[f"{name} exact"] = np.concatenate([predicted(fitted(models[name], tr), te)
                                                   for tr, te in (split_holdout(d, held) for d in sims)])
        results[split] = {k: {"rms_mm": float(np.sqrt(np.mean(e ** 2))), "max_mm": float(e.max()),
                              "errors_mm": e.tolist()} for k, e in row.items()}
        for name, c in compared.items():
            results[split][name]["halves_compared"] = c
        print(f"{split:8s} train {len(ids) - len(held):3d}  " + "  ".join(
            f"{k} {v['rms_mm']:.3f}" for k, v in results[split].items()), flush=True)
    if args.floor:
        results["floor"] = {name: noise_floor(m, data[name], ids) for name, m in models.items()}
        for name, f in results["floor"].items():
            print(f"{name}: fitted on all {len(ids)} postures {f['fit_rms_mm']:.3f} mm RMS 3D (per axis " +
                  ", ".join(f"{v:.3f}" for v in f["fit_rms_axes_mm"]) + f"), noise floor {f['floor_mm']:.3f} mm "
                  f"(dof {f['dof']}); leave-one-out {f['loo_rms_mm']:.3f} mm", flush=True)
    if args.output:
        args.output.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
