"""The model file out of a fit (``aacmm calibrate`` and ``aacmm close-loop``): the calibrated
description with every effect and its parameters, the covariance file beside it and the URDF (for an
arm read from a URDF: the user's own file with only the identified joint origins and tool offset changed).

Format: :mod:`arm_model.model_file` and docs/calibration.md ("The model file")."""
from __future__ import annotations

import dataclasses
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from arm_model import InputError
from arm_model.errors import MAX_ID_LENGTH, NumericalError
from arm_model.io import UnreadableOutput, atomic_write_text, guard_output, read_back
from arm_model.model_file import Arm, format_model, write_covariance
from arm_model.output import safe_name
from arm_model.urdf_import import calibrated_urdf_text

from .region import predictive_covariance

__all__ = ["calibrated_name", "model_paths", "fitted_arm", "write_model", "written_covariance", "model_check",
           "refine_torques",
           "check_reproduces", "REPRODUCE_TOL_M", "discrepancy_fields", "session_drift", "without_session_effects",
           "drift_text"]

#: how far beyond :func:`model_check`'s difference (the torques evaluated on the calibrated description, which
#: the summary reports) the model file read back may put a fitted point from the fit's own ball centre [m]:
#: the file's decimal text costs below 1e-12 m
REPRODUCE_TOL_M = 1e-9
#: how far the covariance read back may differ from the fit's, relative to u_i u_k
REPRODUCE_COV_REL = 1e-9
#: how far the covariance of a fitted ball centre from the parameters alone, through the model file and
#: covariance read back, may differ from the fit's own, relative to the point's largest variance: the torques
#: the model file evaluates on its own description (at its static equilibrium) differ from the fit's last
#: refined ones by a little (1.8e-6 measured on a Kinova chain with compliances); the error this check is for,
#: a covariance in the wrong axes, is of the order of the origin angles (2e-3 at 20 mrad)
REPRODUCE_POINT_REL = 1e-4


def session_drift(result) -> list[dict]:
    """The session's effects of ``result`` (:attr:`~arm_model.effects.Effect.session`: a drift of the links in the
    session's time) as the summary and report give them: per effect its name, its reference time ``t_ref`` [s] (the
    geometry written is the one at that time of this session) and its parameters (name, SI unit, value, standard
    uncertainty, state); empty without one."""
    rows = {r["name"]: r for r in result.parameter_rows()}
    out = []
    for e, sl in result.model.effect_slices():
        if e.session:
            names = result.model.spec.names[sl]
            out.append({"effect": e.describe(result.model.desc),
                        "reference_time_s": getattr(e, "reference_time_s", None),
                        "parameters": [{k: rows[n][k] for k in ("name", "unit", "value", "u", "state")}
                                       for n in names]})
    return out


def drift_text(drift: list[dict]) -> str:
    """The session's drift (:func:`session_drift`) in words, for the model file's comment and the report: the model
    file holds the geometry at its reference time and no drift."""
    parts = [(f"{d['effect']} about t_ref = {d['reference_time_s']:.3f} s: " if d["reference_time_s"] is not None
              else f"{d['effect']} (each measurement's artefact displaced from its first point to its last; the "
                   "features fitted where it sits at the middle of the capture): ")
             + ", ".join(f"{p['name']} = {p['value']:.4g} +- {p['u']:.2g} {p['unit']}" for p in d["parameters"])
             for d in drift]
    return ("; ".join(parts) + ". A drift of this session (its time and its room, its fixtures), not of the arm: the "
            "model file holds the geometry at its reference and no drift, so that every --arm applies none to other "
            "data.")


def without_session_effects(result):
    """``result`` with its session's effects (:attr:`~arm_model.effects.Effect.session`) taken out, the rest as
    fitted: the model, parameters, covariance and prior of the others; so the geometry at the effects' reference (a
    drift's reference time). What a model file holds (:func:`write_model`): the session's own values are reported
    beside it (:func:`session_drift`), never applied to other data. ``result`` itself when it has none."""
    model = result.model
    if not any(e.session for e in model.effects):
        return result
    from arm_model.model import ArmModel
    gone = {model.spec.names[i] for e, sl in model.effect_slices() if e.session for i in range(sl.start, sl.stop)}
    keep = [i for i, n in enumerate(model.spec.names) if n not in gone]
    kf = [k for k, n in enumerate(result.free) if n not in gone]

    def part(a, idx):
        return None if a is None else np.asarray(a)[idx]
    return replace(result, model=ArmModel(model.desc, tuple(e for e in model.effects if not e.session)),
                   p=result.p[keep], free=tuple(result.free[k] for k in kf), cov=result.cov[np.ix_(kf, kf)],
                   u=result.u[kf], corr=result.corr[np.ix_(kf, kf)], prior_centre=part(result.prior_centre, keep),
                   prior_sd=part(result.prior_sd, kf), prior_ratio=part(result.prior_ratio, kf),
                   fixed=tuple(f for f in result.fixed if f.name not in gone),
                   held=tuple(n for n in result.held if n not in gone), model_check=None)


def calibrated_name(arm_name: str) -> str:
    """The name of a calibrated model (its model file's ``name``, and its files' names): ``<arm>-calibrated``; an arm
    name so long that this would pass the longest name a reader takes (:data:`arm_model.errors.MAX_ID_LENGTH`) is
    cut, and given a checksum of the whole (the file would be refused by its own read-back)."""
    name = f"{arm_name}-calibrated"
    if len(name) <= MAX_ID_LENGTH:
        return name
    return f"{arm_name[:MAX_ID_LENGTH - 20]}-{zlib.crc32(arm_name.encode('utf-8')):08x}-calibrated"


def model_paths(out_dir, name: str) -> dict:
    """``{"model": <name>.toml, "covariance": <name>-covariance.csv, "urdf": <name>.urdf, "training_poses":
    <name>-training-poses.csv}`` in ``out_dir`` (the name made safe as a file name:
    :func:`arm_model.output.safe_name`)."""
    out = Path(out_dir)
    stem = safe_name(name)
    return {"model": out / f"{stem}.toml", "covariance": out / f"{stem}-covariance.csv",
            "urdf": out / f"{stem}.urdf", "training_poses": out / f"{stem}-training-poses.csv"}


def fitted_arm(result, name: str | None = None, training_poses: Path | None = None) -> Arm:
    """The :class:`~arm_model.model_file.Arm` of a :class:`~calibration.calibrate.CalibrationResult`:
    the base errors folded into the description, the effects with their fitted values, uncertainties (the covariance
    file's: :func:`calibration.region.predictive_covariance`) and states (free / fixed / held), the reference
    instrument's frames and markers (``result.tracker``) and the model discrepancy; its growth away from the training
    poses only with ``training_poses``, the points file of those poses (:func:`write_model` writes it), else the
    discrepancy at the training poses alone (an Arm refuses a growth without the poses it grows away from)."""
    desc = result.described()
    if name:
        desc = replace(desc, name=name)
    model = result.model
    names = model.spec.names[model.base_size:]
    rows = {r["name"]: r for r in result.parameter_rows()}
    fields = discrepancy_fields(result)
    if training_poses is None:
        fields["discrepancy_growth"] = None
    u = dict(zip(result.free, np.sqrt(np.clip(np.diag(predictive_covariance(result)), 0.0, None)), strict=True))
    return Arm(desc, tuple(model.effects), {n: result.value(n) for n in names},
               {n: float(u.get(n, 0.0)) for n in names}, {n: rows[n]["state"] for n in names},
               tracker=result.tracker, training_poses=training_poses if fields["discrepancy_growth"] else None,
               **fields)


def write_model(result, out_dir, name: str, *, inputs=(), written_by: str = "aacmm calibrate",
                comment: str | None = None) -> dict:
    """Write the model file, its covariance file, the URDF of ``result`` and, when its model discrepancy grows
    away from the training poses, their points file into ``out_dir``; returns :func:`model_paths` of the files
    written. ``inputs``: files never to be overwritten. The session's effects (a drift in its time) are not
    written (:func:`without_session_effects`: the geometry at their reference; the comment says so)."""
    drift = session_drift(result)
    if drift:
        comment = (f"{comment}\n" if comment else "") + drift_text(drift)
    if result.model.desc.masses_assumed:
        from .calibrate import ASSUMED_DENSITY
        comment = (f"{comment}\n" if comment else "") + (
            f"The masses (mass_kg) are assumed, not the arm's: its URDF gave its links none; each link is "
            f"a uniform rod of {ASSUMED_DENSITY:g} kg/m from its joint to the next (a tool's given mass added), for "
            "the gravity torques. The joint compliances are per N m of these torques.")
    result = without_session_effects(result)
    files = model_paths(out_dir, name)
    for f in files.values():
        guard_output(f, inputs)
    arm = fitted_arm(result, name, files["training_poses"])
    poses_file = files.pop("training_poses")
    poses = poses_file if _grows(result) else None
    try:
        text = format_model(arm.desc, arm.effects, arm.values, arm.uncertainties, arm.states,
                            covariance=files["covariance"].name, written_by=written_by,
                            probing_scatter=result.probing_scatter(), tracker=arm.tracker, comment=comment,
                            **discrepancy_fields(result), training_poses=None if poses is None else poses.name)
    except ValueError as exc:       # a fitted scatter beyond any arm's (106 mm: two placements under one id), exit 3
        raise NumericalError(f"{exc}: a fit this far from its data describes no arm (are the points of several "
                             "placements under one measurement id, or a column in the wrong unit?)") from None
    names, cov = written_covariance(result)
    spec = result.model.spec
    idx = [spec.index(n) for n in names]
    write_covariance(files["covariance"], names, [spec.units[i] for i in idx], result.p[idx], cov, inputs)
    if poses is not None:
        files["training_poses"] = _write_training_poses(result, poses, inputs)
    atomic_write_text(files["model"], text, inputs)
    atomic_write_text(files["urdf"], calibrated_urdf_text(result.model.desc, arm.desc), inputs)
    check_reproduces(result, read_back(files["model"]), files["model"], urdf=files["urdf"])
    return files


def written_covariance(result) -> tuple[list, np.ndarray]:
    """(names, covariance [SI^2]) of the covariance file of ``result``: the fit's covariance of its free
    parameters for poses it never saw (the posterior plus the parameters' random effect between regions of the joint
    space, :func:`calibration.region.predictive_covariance`) expressed in the parameters of the model file, whose
    description holds the base errors folded in (:func:`arm_model.params.folded_jacobian`: ``T C T^T``; the same as
    the fit's but for a URDF origin's angle errors, which the model file turns about the calibrated origin's own
    axes, the fit about the nominal's). A parameter is written when it is free or, through ``T``, takes a variance
    from one (the other angles of an origin with a fixed one); names in the parameters' order."""
    from arm_model.params import folded_jacobian
    spec, model = result.model.spec, result.model
    idx = [spec.index(n) for n in result.free]
    t = np.eye(spec.size)
    t[: model.base_size, : model.base_size] = folded_jacobian(model.desc, result.p)
    t_free = t[:, idx]
    rows = [i for i in range(spec.size) if i in idx or np.any(t_free[i] != 0.0)]
    cov = t_free[rows] @ predictive_covariance(result) @ t_free[rows].T
    return [spec.names[i] for i in rows], 0.5 * (cov + cov.T)


def discrepancy_fields(result) -> dict:
    """The model discrepancy a result carries (:mod:`calibration.discrepancy`) as the keywords of
    :class:`~arm_model.model_file.Arm` and :func:`~arm_model.model_file.format_model`: ``model_discrepancy`` [m]
    per axis at the training poses and ``discrepancy_growth`` [1], one a joint (:attr:`~calibration.discrepancy.
    Discrepancy.written`: the growing fit's estimates with their uncertainty carried); None without one, no growth
    when it could not be fitted or is floored at 0."""
    d = getattr(result, "discrepancy", None)
    if d is None:
        return {"model_discrepancy": None, "discrepancy_growth": None}
    sigma0, growth = d.written
    return {"model_discrepancy": sigma0, "discrepancy_growth": growth}


def _grows(result) -> bool:
    """Whether the model discrepancy of ``result`` grows away from its training poses (their points file is
    written, and the model file names it)."""
    d = getattr(result, "discrepancy", None)
    return not (d is None or d.written_growth is None or d.training_rows is None)


def _write_training_poses(result, path: Path, inputs) -> Path:
    """The points file of the fit's poses (``measurement``, ``feature``, the joint columns in the description's
    units) that a growing model discrepancy (:func:`_grows`) is measured from."""
    d = result.discrepancy
    pts = result.data.points
    rows = np.asarray(d.training_rows, dtype=int)
    cols = {"measurement": np.asarray(pts.measurement)[rows].astype(object),
            "feature": np.asarray(pts.feature)[rows].astype(object)}
    for k, (suffix, factor) in enumerate(result.model.desc.joint_column_units):
        cols[f"q{k + 1}_{suffix}"] = pts.q[rows, k] * factor
    from arm_model.io import write_csv
    return write_csv(path, cols, inputs, fmt="%.15g")


def check_reproduces(result, back: Arm, path, urdf=None) -> None:
    """The model file read back (``back``: as every ``--arm`` reads it) must reproduce the fit: on every
    fitted point its ball centre within :data:`REPRODUCE_TOL_M` of the fit's own beyond the difference
    :func:`model_check` reports, and its covariance file the fit's covariance of the free parameters
    (:data:`REPRODUCE_COV_REL`). ``urdf``: the URDF written beside it, read with the fitted arm's tip frame (the
    generated ball frame for a description), must give the model file's rigid ball centres. Else
    :class:`~arm_model.io.UnreadableOutput` (a bug: exit 3, nothing written)."""
    pts = result.data.points
    own = result.model.ball_centres(pts.q, result.data.wrench, result.p, result.data.aux)
    _same(back.ball_centres(pts, wrench=result.data.wrench), own,
          REPRODUCE_TOL_M + model_check(result)["max_difference_nm"] * 1e-9, pts,
          "the model file read back does not reproduce the fit", path)
    if urdf is not None:
        from arm_model.kinematics import rigid_centres
        from arm_model.urdf import BALL_FRAME
        from arm_model.urdf_import import load_arm
        try:
            arm = load_arm(urdf, _urdf_tip(urdf, result.model.desc.tip_frame or BALL_FRAME),
                           base_frame=result.model.desc.base_frame, hold=dict(result.model.desc.held_joints) or None)
        except InputError as exc:
            raise UnreadableOutput(f"the URDF written is refused with its tip frame: {exc}", urdf) from None
        _same(rigid_centres(arm, pts.q), rigid_centres(back.desc, pts.q), REPRODUCE_TOL_M, pts,
              "the URDF read back is not the model file's arm", urdf)
    _same_discrepancy(result, back, path)
    if back.covariance is None:
        return
    from arm_model.model_file import read_covariance
    cov = read_covariance(back.covariance)
    names, want = written_covariance(result)
    u = np.sqrt(np.clip(np.diag(want), 0.0, None))
    if list(cov.names) != names or not np.all(np.abs(cov.matrix - want) <= REPRODUCE_COV_REL * np.outer(u, u)):
        raise UnreadableOutput(f"the covariance file read back is not the fit's covariance of its free parameters "
                               f"({', '.join(result.free)}) in the model file's parameters", back.covariance)
    _same_point_covariance(result, back, cov)


def _same_point_covariance(result, back: Arm, cov, n: int = 64) -> None:
    """The covariance of the ball centres from the parameters alone (:func:`arm_model.uncertainty.propagate`),
    on the first ``n`` fitted points: the model file and covariance read back (``cov``) must give the fit's own
    within :data:`REPRODUCE_POINT_REL` of each point's largest, else :class:`~arm_model.io.UnreadableOutput`.
    Both sides are evaluated with the inputs the model file gives (the torques at its static equilibrium): the
    fit's last refined torques differ from them by what :func:`model_check` reports for the centres, which is not
    what this check is for (a covariance in the wrong axes or units); on the loop-demo campaign simulated in
    memory (docs/close-loop.md, Python) that difference alone moved a point's covariance by 1.4e-4 of its largest
    term."""
    from arm_model.uncertainty import InputUncertainty, ParameterCovariance, propagate
    pts, data = result.data.points, result.data
    if not len(pts) or not len(result.free):
        return
    k = slice(0, min(n, len(pts)))
    nj = pts.q.shape[1]
    none = InputUncertainty(np.zeros(nj), np.zeros(3), np.zeros(3), np.zeros(3))
    w = None if data.wrench is None else data.wrench[k]
    aux = back.aux(pts, wrench=data.wrench)
    aux = None if aux is None else aux.select(k)
    own = propagate(result.model, result.p, pts.q[k], w, aux,
                    parameters=ParameterCovariance(tuple(result.free), predictive_covariance(result)), inputs=none).cov
    got = propagate(back.model, back.p, pts.q[k], w, aux,
                    parameters=ParameterCovariance(tuple(cov.names), cov.matrix), inputs=none).cov
    scale = np.max(np.abs(np.einsum("nii->ni", own)), axis=1)[:, None, None]
    if not np.all(np.abs(got - own) <= REPRODUCE_POINT_REL * scale + 1e-30):
        i = int(np.argmax(np.max(np.abs(got - own) / np.maximum(scale, 1e-300), axis=(1, 2))))
        raise UnreadableOutput(f"the model file and covariance file read back do not give the fit's uncertainty of "
                               f"the ball centre of {pts.path}, line {pts.lines[i]}", back.covariance)


def _same_discrepancy(result, back: Arm, path) -> None:
    """The model discrepancy read back must be the fit's (to the 4 digits written; the training poses to 1e-9
    rad or m): else :class:`~arm_model.io.UnreadableOutput`."""
    want = discrepancy_fields(result)
    got = {"model_discrepancy": back.model_discrepancy, "discrepancy_growth": back.discrepancy_growth}
    for key, v in got.items():
        w = want[key]
        vs, ws = (np.atleast_1d(np.asarray(x, dtype=float)) if x is not None else None for x in (v, w))
        if (vs is None) != (ws is None) or (ws is not None and not (
                vs.shape == ws.shape and np.all(np.abs(vs - ws) <= 6e-4 * ws + 1e-15))):
            raise UnreadableOutput(f"the model file read back gives {key} {v!r}, the fit {w!r}", path)
    from arm_model.model_file import training_poses_of
    d = getattr(result, "discrepancy", None)
    want_q = None if d is None or d.written_growth is None else d.training.q
    try:
        got_q = training_poses_of(back)
    except InputError as exc:
        raise UnreadableOutput(f"the training poses read back are refused: {exc}", back.training_poses) from None
    if (got_q is None) != (want_q is None) or (want_q is not None and not (
            got_q.q.shape == want_q.shape and np.allclose(got_q.q, want_q, rtol=0, atol=1e-9))):
        raise UnreadableOutput("the model file read back does not give the fit's training poses", path)


def _urdf_tip(urdf, tip: str) -> str:
    """The tip frame of a calibrated URDF: the link ``<tip>_calibrated`` (``_`` appended while taken) that
    :func:`~arm_model.urdf_import.calibrated_urdf_text` adds for a tool offset no fixed joint could take, else
    ``tip``."""
    import re

    from lxml import etree
    names = [el.get("name") or "" for el in etree.parse(str(urdf)).getroot().findall("link")]
    added = [n for n in names if re.fullmatch(re.escape(tip) + "_calibrated_*", n)]
    return max(added, key=len) if added else tip


def _same(got, want, tol: float, pts, what: str, path) -> None:
    d = np.linalg.norm(got - want, axis=1) if len(pts) else np.zeros(0)
    if len(d) and not d.max() <= tol:
        i = int(np.nanargmax(d)) if np.isfinite(d).any() else 0
        raise UnreadableOutput(f"{what}: the ball centre of {pts.path}, line {pts.lines[i]} moves by "
                               f"{d[i] * 1e9:.3g} nm (at most {tol * 1e9:.3g} nm)", path)


def model_check(result, arm: Arm | None = None) -> dict:
    """How far the written model's ball centres lie from the fit's own on the fitted points [m]: the
    model file recomputes gravity and contact torques from the calibrated description, the fit used
    the nominal one (zero without joint-compliance effects, rounding otherwise). Computed once a fit: the
    check :func:`refine_torques` ended on is the result's ``model_check`` and is returned as it is."""
    if arm is None and result.model_check is not None:
        return result.model_check
    arm = arm or fitted_arm(result)
    pts = result.data.points
    own = result.model.ball_centres(pts.q, result.data.wrench, result.p, result.data.aux)
    out = arm.ball_centres(pts, wrench=result.data.wrench)
    d = np.linalg.norm(out - own, axis=1)
    return {"max_difference_nm": float(d.max() * 1e9) if len(d) else 0.0,
            "rms_difference_nm": float(np.sqrt(np.mean(d ** 2)) * 1e9) if len(d) else 0.0}


def at_equilibrium(model, p, data):
    """``data`` with the gravity and contact torques of ``(model, p)`` evaluated on its own description at the static
    equilibrium its compliances give (:meth:`~arm_model.model.ArmModel.equilibrium_aux`, as the model file
    evaluates them), when the model needs them; else ``data`` (None stays None)."""
    if data is None or not ({"tau_gravity", "tau_contact"} & model.needs()):
        return data
    temperature = None if data.aux is None else data.aux.temperature
    time = None if data.aux is None else data.aux.time
    motion = None if data.aux is None else data.aux.motion
    capture = None if data.aux is None else data.aux.capture
    return replace(data, aux=model.equilibrium_aux(data.points.q, data.wrench, np.asarray(p, float), temperature,
                                                   time=time, motion=motion, capture=capture))


def with_fitted_torques(data, result):
    """``data`` with the torques of the calibrated model of ``result`` at its equilibrium (:func:`at_equilibrium`).
    Held-out data are predicted with these, so that the held-out figures are those ``tip`` gives with the model
    file."""
    return at_equilibrium(result.model, result.p, data)


def refine_torques(result, rounds: int = 5, tol_nm: float = 1.0):
    """The fit refined with the gravity and contact torques evaluated on its calibrated description (the
    fit evaluated them on the nominal one), so that the model file, which evaluates them on the description
    it holds, gives the fit's own ball centres (:func:`model_check`): repeated (a fixed point: each refit
    moves the description a little) until they agree within ``tol_nm`` or ``rounds`` refits are done.

    Only for models with an effect that needs the torques; the same free parameters, started at the
    fit's values, with the fit's own options (``result.options``: covariance, rank_tol, outlier threshold,
    prior) at its final weights; the fixed, held and dropped parameters and points (gross errors too), the
    identifiability analyses and the region effect (:mod:`calibration.region`, estimated once: the refits move the
    parameters by the torques' nanometres, its Monte Carlo test costs seconds a fit) of ``result`` are kept; the
    last round's :func:`model_check` is the result's ``model_check``
    (the writers report it without computing it again)."""
    model = result.model
    if not ({"tau_gravity", "tau_contact"} & model.needs()):
        return result
    from .calibrate import calibrate
    from .options import FitOptions
    data = result.data
    keep = {f: getattr(result, f) for f in ("fixed", "held", "dropped", "gross", "gross_kept", "identifiability",
                                             "evidence", "weights_history", "options", "region")}
    base = replace(result.options or FitOptions(), weights=result.weights, reference=result.reference_mode,
                   min_resolution=None, drop_outliers=False, gross_threshold=None, weights_from_data=False, start=None,
                   prior_scale=result.prior_scales, prior_centre=result.prior_centre, region_effect=False)
    cur = result
    for _ in range(rounds):
        values = dict(zip(model.spec.names, (float(v) for v in cur.p), strict=True))
        cur = dataclasses.replace(calibrate(model, with_fitted_torques(data, cur),
                                            replace(base, free=tuple(cur.free), values=values)), **keep)
        check = model_check(cur)
        cur = dataclasses.replace(cur, model_check=check)
        if check["max_difference_nm"] <= tol_nm:
            break
    return cur
