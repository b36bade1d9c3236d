#!/usr/bin/env python3
"""How much of the parameters' uncertainty of a tracker-only calibration's tips (``aacmm tip``'s ``u_x_mm`` ...,
in the robot's base frame) is the unknown instrument frame and marker offset, which cancel in the instrument's
own coordinates (``x_ref_mm`` ...).

A calibration seen only by a tracker fits the model parameters together with the instrument's frame
``T_ref_base`` and the marker's offset on the tip frame; the covariance file holds the parameters alone (the
frame and the offset are nuisance unknowns, their cross-covariance is not written). A parameter error ``dp``
moves every point by ``J dp`` in the base frame; a frame and an offset fitted on the training poses take up the
part of that motion they can represent (a rigid motion of the whole workspace, and the offset turned by each
pose's tip rotation), fitted by least squares over the training rows. What is left is the parameters' share of
the uncertainty of a prediction in the instrument frame:
``u_ref = sqrt(diag(P J C J^T P^T))``, ``P = I - N (N_t^+)`` restricted, ``N`` the 9 nuisance directions at
every point and ``N_t`` at the training rows. The frame's and offset's own noise-driven share and the noise of
a point are not in it; the script prints the held-out rows' observed errors beside it.

One session and one marker (the case the model file's tables of a single tracker placement describe).

    python scripts/tracker_frame_u_study.py POINTS MODEL_FILE
    # e.g. after docs/own-arm.md's TALOS commands:
    python scripts/tracker_frame_u_study.py ex/data/real-talos-mocap/points.csv talos-cal/talos-calibrated.toml
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def rigid_directions(x: np.ndarray) -> np.ndarray:
    """(3n, 6) the displacements of points ``x`` (n, 3) [m] under a small translation (x, y, z) and rotation."""
    cols = []
    for k in range(3):
        t = np.zeros_like(x)
        t[:, k] = 1.0
        cols.append(t.ravel())
    for k in range(3):
        cols.append(np.cross(np.eye(3)[k], x).ravel())
    return np.array(cols).T


def main() -> int:
    from arm_model.io import read_points
    from arm_model.model_file import load_model, parameters_of, training_poses_of
    from arm_model.tracker import marker_positions, offset_matrix
    from arm_model.uncertainty import default_inputs, propagate

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("points")
    ap.add_argument("model")
    a = ap.parse_args()
    arm = load_model(a.model)
    pts = read_points(a.points, arm.desc.joint_quantities)
    par, train = parameters_of(arm), training_poses_of(arm)
    if arm.tracker is None or arm.tracker.n_markers != 1 or len(arm.tracker.sessions) != 1 or par is None \
            or train is None:
        sys.exit("needs a model file of one tracker session, one marker, a covariance and training poses")
    q, aux = pts.q, arm.aux(pts)
    is_train = np.array([np.any(np.all(np.isclose(train.q, row, rtol=0, atol=1e-12), axis=1)) for row in q])
    m = offset_matrix(arm.model)
    p_marker = arm.p + m @ arm.tracker.offset(0)
    inputs = default_inputs(arm.desc)
    res = propagate(arm.model, p_marker, q, None, aux, parameters=par, inputs=inputs, systematic=True)
    d = res.systematic[:, :len(par.names), :]            # (n, R, 3): the parameters' rows only
    n, r, _ = d.shape
    dd = d.transpose(1, 0, 2).reshape(r, 3 * n)
    tip = propagate(arm.model, arm.p, q, None, aux, parameters=par, inputs=inputs).contributions["parameters"]
    h = 1e-6
    base = arm.model.ball_centres(q, None, p_marker, aux)
    offs = np.array([((arm.model.ball_centres(q, None, p_marker + h * m @ np.eye(3)[k], aux) - base) / h).ravel()
                     for k in range(3)]).T
    rows_t = np.flatnonzero(np.repeat(is_train, 3))

    def left(nuis):
        e = dd - (nuis @ (np.linalg.pinv(nuis[rows_t]) @ dd[:, rows_t].T)).T
        return np.sqrt((e.reshape(r, n, 3) ** 2).sum(0))

    def rms(u, rows):
        return np.sqrt((u[rows] ** 2).mean(0)) * 1e3

    rigid = rigid_directions(base)
    u_marker = np.sqrt((d ** 2).sum(1))
    u_frame, u_both = left(rigid), left(np.hstack([rigid, offs]))
    pred = marker_positions(arm.model, arm.p, q, arm.tracker, [arm.tracker.sessions[0]] * n, aux)[:, 0]
    err = pred - pts.ref[:, 0]
    held = ~is_train
    print(f"{n} rows, {int(is_train.sum())} training, {int(held.sum())} held out; per axis RMS [mm] (x, y, z)")
    print("parameters' u of the tip link in the base frame (tip's u_x_mm ...):",
          np.round(np.sqrt(tip.mean(0)) * 1e3, 3))
    print("parameters' u of the marker in the base frame:                    ", np.round(rms(u_marker, slice(None)), 3))
    print("  less what the frame fitted on the training poses takes up:       ", np.round(rms(u_frame, held), 3))
    print("  less what the frame and the marker offset take up (held out):    ", np.round(rms(u_both, held), 3))
    print("  the same, training rows:                                         ", np.round(rms(u_both, is_train), 3))
    if held.any():
        print("observed error of the held-out rows in the instrument frame:      ",
              np.round(np.sqrt((err[held] ** 2).mean(0)) * 1e3, 3))
    print("observed error of the training rows (the fit's residual):          ",
          np.round(np.sqrt((err[is_train] ** 2).mean(0)) * 1e3, 3))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
