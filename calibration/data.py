"""Calibration data: the captured points, the artefacts and the per-point inputs of the model's
effects, split by measurement (never by point) into training and held-out sets."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from arm_model import InputError
from arm_model.checks import repeated_readings
from arm_model.io import Artefacts, PointSet, check_features
from arm_model.model import ArmModel, AuxData, capture_columns, points_motion
from arm_model.tracker import DEFAULT_SESSION, Tracker

__all__ = ["Weights", "SIGMA_DEFAULT", "CalibrationData", "make_data", "merge_points", "split_holdout", "NO_ARTEFACTS",
           "MARKER_OFFSETS"]

#: the artefacts of a campaign without an artefacts file (tracker points only)
NO_ARTEFACTS = Artefacts("<no artefacts file>", {}, ())
#: how the reference instrument's markers sit on the tip frame: "fit" (each at an unknown offset, estimated)
#: or "zero" (the instrument sees the tip point itself: a tracker's reflector in the probe's place)
MARKER_OFFSETS = ("fit", "zero")


#: the standard uncertainty [m] of a probed ball centre and of a reference coordinate that nobody stated: a starting
#: value (``--sigma-probe-um``, ``--sigma-ref-um`` not given; ``Weights()`` without ``probe`` or ``reference``); to the
#: bit what ``--sigma-probe-um 10`` gives (10 um * 1e-6), so a default and the same value stated weight alike
SIGMA_DEFAULT = 10.0 * 1e-6


@dataclass(frozen=True)
class Weights:
    """Standard uncertainties that weight the residuals (each residual is divided by its own).

    Attributes:
        probe: of one probed ball centre, per axis [m] (points on seats, spheres, rings, planes).
        reference: of one reference-instrument coordinate, per axis [m]. A reference point on a seat
            (a tracker nest) ties the seat's centre to the instrument (weight ``reference``); on a free
            point it ties the ball centre (weight ``hypot(probe, reference)``).
        length: of a certified length whose artefact gives no ``u_length_mm`` [m] (None: ``probe``).
        factors: ``((group, factor), ...)``: every row of a group (a point kind: "seat", "sphere", "ring",
            "cylinder", "plane", "reference"; or "length") has its uncertainty multiplied by the factor
            (the variance components estimated from a fit, :func:`calibration.calibrate.calibrate`).
        defaulted: which of "probe" and "reference" the user did not state: starting values, never a statement
            to judge a residual against (:meth:`stated_sigma_of`). ``probe`` or ``reference`` not given (None) is
            :data:`SIGMA_DEFAULT` and named here, as the command line does for a ``--sigma-*-um`` not given, so
            ``Weights()`` states nothing and ``Weights(probe=2e-6)`` states the probe's sigma only.
    """
    probe: float
    reference: float
    length: float | None
    factors: tuple
    defaulted: tuple = field(compare=False)

    def __init__(self, probe: float | None = None, reference: float | None = None, length: float | None = None,
                 factors: tuple = (), defaulted: tuple = ()):
        given = {"probe": probe, "reference": reference}
        for name, v in given.items():
            object.__setattr__(self, name, SIGMA_DEFAULT if v is None else v)
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "factors", factors)
        if any(k not in given for k in defaulted):
            raise ValueError(f"defaulted names sigmas of {tuple(given)}, got {tuple(defaulted)!r}")
        unstated = tuple(defaulted) + tuple(k for k, v in given.items() if v is None)
        object.__setattr__(self, "defaulted", tuple(k for k in given if k in unstated))
        self.__post_init__()

    def __post_init__(self):
        for name in ("probe", "reference", "length"):
            v = getattr(self, name)
            if v is not None and (not np.isfinite(v) or v <= 0):
                raise ValueError(f"weight {name} must be a finite positive uncertainty [m], got {v!r}")
        object.__setattr__(self, "factors", tuple(sorted((str(g), float(f)) for g, f in dict(self.factors).items())))
        for g, f in self.factors:
            if not np.isfinite(f) or f <= 0:
                raise ValueError(f"weight factor of '{g}' must be finite and positive, got {f!r}")

    def factor(self, group: str) -> float:
        """The factor of a row group (1 if not estimated)."""
        return dict(self.factors).get(group, 1.0)

    def scaled(self, factors: dict) -> Weights:
        """These weights with the group factors multiplied by ``factors``."""
        new = dict(self.factors)
        for g, f in factors.items():
            new[g] = new.get(g, 1.0) * float(f)
        return Weights(self.probe, self.reference, self.length, tuple(new.items()), self.defaulted)

    def sigma_of(self, group: str) -> float | None:
        """The uncertainty [m] of a point of a group, factor applied (None for "length": per artefact)."""
        if group == "length":
            return None
        return (self.reference if group == "reference" else self.probe) * self.factor(group)

    def stated_sigma_of(self, group: str) -> float | None:
        """:meth:`sigma_of` when the user stated it; None when it is a default (:attr:`defaulted`)."""
        return None if ("reference" if group == "reference" else "probe") in self.defaulted else self.sigma_of(group)

    @property
    def reference_sigma(self) -> float:
        """Of a reference residual on a free point (the arm's ball and the instrument's view) [m]."""
        return float(np.hypot(self.probe, self.reference))

    def length_sigma(self, u_length: float | None) -> float:
        if u_length is not None and u_length > 0:
            return float(u_length)
        return float(self.length if self.length is not None else self.probe)


@dataclass(frozen=True)
class CalibrationData:
    """Points (``arm_model.io.PointSet``), their artefacts and the per-point aux inputs
    (``AuxData``: temperature, gravity and contact torques) that the model's effects need.

    ``points`` may join several files (:func:`merge_points`: e.g. the artefact points and the tracker
    points); ``points.ref`` is NaN on rows without reference coordinates and ``files`` names each
    row's file (for messages, with ``points.lines``).

    Reference coordinates (:mod:`arm_model.tracker`): a row carries one marker's (``marker``: its
    0-based marker, None: marker 0 everywhere; :func:`make_data` turns a row of K markers into K rows);
    ``marker_offsets`` says whether the markers sit at unknown offsets on the tip frame ("fit") or the
    instrument sees the tip point itself ("zero"); ``tracker``: frames and offsets held at given values
    (a prediction with those of another fit, :meth:`with_tracker`), None: estimated. ``left_out_lengths``: the
    certified lengths of the artefacts not fitted in one measurement each, ``(measurement, (feature a, feature
    b))`` (a gross error left out, :meth:`without_length`).
    """
    points: PointSet
    artefacts: Artefacts
    aux: AuxData | None = None
    files: np.ndarray | None = None
    marker: np.ndarray | None = None
    marker_offsets: str = "zero"
    tracker: Tracker | None = None
    left_out_lengths: tuple = ()

    def __post_init__(self):
        if self.marker_offsets not in MARKER_OFFSETS:
            raise ValueError(f"marker_offsets must be one of {MARKER_OFFSETS}, got {self.marker_offsets!r}")

    def file_of(self, i: int) -> str:
        return str(self.files[i]) if self.files is not None else self.points.path

    @property
    def point_files(self) -> np.ndarray:
        """(N,) object: the points file of each point (``files``, else the points' own path)."""
        return self.files if self.files is not None else np.full(len(self), self.points.path, dtype=object)

    def where(self, i: int) -> str:
        """``file line N`` of point ``i`` for messages."""
        line = None if self.points.lines is None else int(self.points.lines[i])
        return f"{self.file_of(i)}" + (f" line {line}" if line is not None else "")

    def __len__(self) -> int:
        return len(self.points)

    def measurements(self) -> list[str]:
        return self.points.measurements()

    @property
    def sessions(self) -> np.ndarray:
        """(N,) the session of each row (:data:`~arm_model.tracker.DEFAULT_SESSION` without a session column)."""
        s = self.points.session
        return np.full(len(self), DEFAULT_SESSION, dtype=object) if s is None else s

    @property
    def motion(self) -> np.ndarray:
        """(N, J) the sign of each joint's last move onto each point: the data's own (``aux.motion``), else the
        points' (their ``q1_move_sign`` ... columns, else their rule: :func:`arm_model.model.points_motion`)."""
        return points_motion(self.points, None if self.aux is None else self.aux.motion)

    @property
    def markers(self) -> np.ndarray:
        """(N,) the 0-based marker of each row's reference coordinates."""
        return np.zeros(len(self), int) if self.marker is None else self.marker

    @property
    def reference(self) -> np.ndarray | None:
        """(N, 3) each row's reference coordinates (of its marker) [m], NaN where it has none; None without
        reference columns."""
        ref = self.points.ref
        return None if ref is None else ref[np.arange(len(self)), self.markers]

    def counts(self) -> dict[str, int]:
        """``n_rows``: the rows of the points files these data hold (a row of several markers once); ``n_points``:
        the distinct readings among them, as the fit counts them (a row that repeats an earlier reading exactly,
        :func:`arm_model.checks.repeated_readings`, counts once: :class:`calibration.problem.Problem`)."""
        files = self.point_files
        lines = self.points.lines if self.points.lines is not None else np.arange(1, len(self) + 1)
        first = repeated_readings(self.points, (self.markers,)) < 0
        rows = list(zip(files.tolist(), np.asarray(lines).tolist(), strict=True))
        return {"n_points": len({r for r, keep in zip(rows, first.tolist(), strict=True) if keep}),
                "n_rows": len(set(rows))}

    def for_model(self, model: ArmModel) -> CalibrationData:
        """These data with the per-point inputs ``model.needs()`` attached (the aux inputs already given are
        kept; temperatures from the points, gravity and contact torques of the nominal description); an
        :class:`InputError` when the points' joint count is not the model's."""
        if self.points.n_joints != model.desc.n_joints:
            raise InputError(f"{self.points.n_joints} joint columns, but the arm has {model.desc.n_joints} joints",
                             self.points.path)
        return replace(self, aux=_aux_inputs(model, self, self.point_files))

    def with_tracker(self, tracker: Tracker | None) -> CalibrationData:
        """These data with the reference frames and marker offsets held at ``tracker``'s (a session it has
        no frame for keeps its frame unknown)."""
        return replace(self, tracker=tracker)

    @property
    def wrench(self) -> np.ndarray:
        """(N, 6) wrench at the ball, probe frame [N, N m] (zeros without force columns)."""
        w = self.points.wrench
        return np.zeros((len(self), 6)) if w is None else w

    def select(self, mask) -> CalibrationData:
        """The rows where ``mask`` holds (bool array or indices), file order kept."""
        return CalibrationData(self.points.select(mask), self.artefacts,
                               None if self.aux is None else self.aux.select(mask),
                               None if self.files is None else self.files[mask],
                               None if self.marker is None else self.marker[mask], self.marker_offsets, self.tracker,
                               self.left_out_lengths)

    def without_length(self, measurement: str, between: tuple) -> CalibrationData:
        """These data with the certified length between the features ``between`` not fitted in ``measurement``."""
        return replace(self, left_out_lengths=(*self.left_out_lengths, (str(measurement), tuple(between))))

    def with_measurements(self, ids) -> CalibrationData:
        """Only the measurements ``ids``."""
        ids = set(ids)
        return self.select(np.array([m in ids for m in self.points.measurement], bool))


def merge_points(*given: PointSet | None) -> tuple[PointSet, np.ndarray]:
    """Join point sets (file order kept, one after the other; None: none) into one; returns it and the file of
    each row. Absent force/torque columns are zero, absent reference coordinates (and markers beyond a
    file's own), temperature and time are NaN, an absent session column is the default session; where one file
    gives each joint's last move (``q1_move_sign`` ...), a file without takes its own points' rule
    (:func:`arm_model.model.points_motion` of that file alone)."""
    sets = [s for s in given if s is not None]
    if len(sets) == 1:
        return sets[0], np.full(len(sets[0]), sets[0].path, dtype=object)
    jn = {s.n_joints for s in sets}
    if len(jn) != 1:
        raise InputError(f"the point files have different joint counts: "
                         f"{', '.join(f'{s.path}: {s.n_joints}' for s in sets)}", sets[-1].path)

    def stack(attr, width, fill):
        if all(getattr(s, attr) is None for s in sets):
            return None
        parts = []
        for s in sets:
            v = getattr(s, attr)
            parts.append(np.full((len(s),) + width, fill, dtype=object if isinstance(fill, str) else float)
                         if v is None else v)
        return np.concatenate(parts)

    k = max(s.n_markers for s in sets)
    ref = None if not k else np.concatenate(
        [np.concatenate([s.ref, np.full((len(s), k - s.n_markers, 3), np.nan)], axis=1) if s.ref is not None
         else np.full((len(s), k, 3), np.nan) for s in sets])
    kinds = {s.force_kind for s in sets if s.force_kind is not None}
    merged = PointSet(
        path=sets[0].path, measurement=np.concatenate([s.measurement for s in sets]),
        feature=np.concatenate([s.feature for s in sets]), q=np.vstack([s.q for s in sets]),
        force=stack("force", (3,), 0.0), torque=stack("torque", (3,), 0.0),
        force_kind=None if not kinds else (kinds.pop() if len(kinds) == 1 else "mixed"),
        temperature=stack("temperature", (), np.nan), time=stack("time", (), np.nan),
        ref=ref, session=stack("session", (), DEFAULT_SESSION),
        lines=np.concatenate([s.line_numbers for s in sets]),
        motion=None if all(s.motion is None for s in sets) else np.vstack([points_motion(s) for s in sets]))
    files = np.concatenate([np.full(len(s), s.path, dtype=object) for s in sets])
    return merged, files


def make_data(points: PointSet, artefacts: Artefacts | None, model: ArmModel | None = None,
              aux: AuxData | None = None, reference: PointSet | None = None,
              marker_offsets: str | None = None, heldout: PointSet | None = None) -> CalibrationData:
    """Check the points against the artefacts and attach the aux inputs ``model.needs()``.

    ``artefacts``: None without an artefacts file (a tracker campaign: every row a free point with
    reference coordinates). ``reference``: a second points file with reference coordinates (e.g. the
    tracker nests of ``aacmm simulate``'s ``points-ref.csv``), joined after ``points``. A row with K
    markers (``x1_ref_mm`` ... ``xK_ref_mm``) becomes K rows, one a marker (``marker``), on the same line.
    ``marker_offsets`` (:data:`MARKER_OFFSETS`): None chooses "fit" without an artefacts file (a robot's
    markers sit where nobody measured them) and "zero" with one (the instrument sees the probe's ball
    itself); several markers need "fit". ``heldout``: a points file of poses kept out of the fit (a stated
    validation set), joined last: its rows are those whose ``files`` entry is its path (:func:`heldout_mask`).

    Temperatures come from the points' ``temperature_C`` column; gravity and contact torques, when
    an effect needs them and ``aux`` does not give them, from ``PinocchioArm(model.desc).torques``
    at the measured angles and wrenches with the nominal description.
    """
    for name, value, kind in (("points", points, PointSet), ("artefacts", artefacts, Artefacts),
                              ("model", model, ArmModel), ("reference", reference, PointSet),
                              ("heldout", heldout, PointSet)):
        if not isinstance(value, kind) and (value is not None or name == "points"):
            what = f"{'an' if kind.__name__[0] in 'AEIOU' else 'a'} {kind.__name__}" + ("" if name == "points" else
                                                                                    " or None")
            raise TypeError(f"make_data: {name} must be {what} (arm_model.read_points, read_artefacts, ArmModel), "
                            f"got {type(value).__name__}")
    check_features(points, artefacts)
    if heldout is not None:
        check_features(heldout, artefacts)
    if reference is not None:
        check_features(reference, artefacts)
        if reference.ref is None:
            raise InputError("the reference points file has no reference columns (x_ref_mm, y_ref_mm, z_ref_mm)",
                             reference.path, 1)
    if artefacts is None and reference is None and points.ref is None:
        raise InputError("no artefacts file and no reference columns (x_ref_mm, y_ref_mm, z_ref_mm): nothing to "
                         "calibrate on; give the artefacts the points touch, or the reference instrument's "
                         "coordinates", points.path, 1)
    offsets = marker_offsets or ("fit" if artefacts is None else "zero")
    if offsets not in MARKER_OFFSETS:
        raise ValueError(f"marker_offsets must be one of {MARKER_OFFSETS}, got {offsets!r}")
    points, files = merge_points(points, reference, heldout)
    points, files, marker = _one_marker_a_row(points, files, offsets)
    artefacts = NO_ARTEFACTS if artefacts is None else artefacts
    data = CalibrationData(points, artefacts, aux, files, marker, offsets)
    return data if model is None else data.for_model(model)


def _one_marker_a_row(points: PointSet, files: np.ndarray, offsets: str):
    """``(points, files, marker)``: every row with K > 1 markers repeated K times, one a marker (file order
    kept; ``marker`` None with one marker). Markers sit on the tip frame: a row on an artefact feature (a
    tracker nest on a seat) has one reference point, that of the feature."""
    k = points.n_markers
    if k <= 1:
        return points, files, None
    if offsets != "fit":
        raise InputError(f"{k} markers (x1_ref_mm ... x{k}_ref_mm) at the tip point itself (marker offsets "
                         "'zero'): several markers sit at their own offsets; let them be estimated (--marker-offset "
                         "fit)", points.path, 1, f"x{k}_ref_mm")
    ref = points.ref
    assert ref is not None, "k > 1 markers come with reference columns"
    on_feature = np.flatnonzero((points.feature != "") & np.any(np.isfinite(ref[:, :, 0]), axis=1))
    if len(on_feature):
        i = on_feature[0]
        raise InputError(f"a row on the feature '{points.feature[i]}' with {k} markers: a reference point on an "
                         "artefact feature (a tracker nest) is the feature's own; give it as marker 1 only, or "
                         "leave the feature cell empty", files[i], None if points.lines is None
                         else int(points.lines[i]), "feature")
    has = np.any(np.isfinite(ref[:, :, 0]), axis=1)
    reps = np.where(has, k, 1)
    rows = np.repeat(np.arange(len(points)), reps)
    marker = np.concatenate([np.arange(n) for n in reps])
    return points.select(rows), files[rows], marker


def _aux_inputs(model: ArmModel, data: CalibrationData, files: np.ndarray) -> AuxData | None:
    """The per-point inputs ``model.needs()``: ``data.aux``'s, else the temperatures, times and last moves
    (:attr:`CalibrationData.motion`) of the points, the gravity and contact torques of the nominal description and each
    point's place in its measurement's capture (:func:`arm_model.model.capture_columns`)."""
    points, aux = data.points, data.aux
    needs = model.needs()
    temperature = None if aux is None else aux.temperature
    tau_g = None if aux is None else aux.tau_gravity
    tau_c = None if aux is None else aux.tau_contact
    time = None if aux is None else aux.time
    motion = data.motion if "motion" in needs else (None if aux is None else aux.motion)
    if "time" in needs and time is None:
        if points.time is None or not np.all(np.isfinite(points.time)):
            bad = 0 if points.time is None else int(np.flatnonzero(~np.isfinite(points.time))[0])
            raise InputError("the model's effects need the points' time: add a 'time_s' column", files[bad], None,
                             "time_s")
        time = points.time
    if "temperature" in needs and temperature is None:
        if points.temperature is None or not np.all(np.isfinite(points.temperature)):
            bad = 0 if points.temperature is None else int(np.flatnonzero(~np.isfinite(points.temperature))[0])
            raise InputError("the model's effects need the arm temperature: add a 'temperature_C' column",
                             files[bad], None, "temperature_C")
        temperature = points.temperature
    if ({"tau_gravity", "tau_contact"} & needs) and (tau_g is None or tau_c is None):
        from arm_model import PinocchioArm
        g, c = PinocchioArm(model.desc).torques(points.q, points.wrench)
        tau_g = g if tau_g is None else tau_g
        tau_c = c if tau_c is None else tau_c
    capture = None if aux is None else aux.capture
    if "capture" in needs and capture is None:
        capture = capture_columns(model.capture_measurements, points.measurement, points.time)
    if temperature is None and tau_g is None and tau_c is None and time is None and motion is None and capture is None:
        return None
    return AuxData(temperature, tau_g, tau_c, time, motion, capture)


#: what to change when a --holdout leaves the held-out set empty (calibrate, close-loop)
EMPTY_HOLDOUT_REMEDY = "name the measurements to hold out (--holdout ID,ID) or give more measurements"


def split_holdout(data: CalibrationData, holdout, seed: int = 0,
                  remedy: str = EMPTY_HOLDOUT_REMEDY) -> tuple[CalibrationData, CalibrationData]:
    """Split by measurement into (training, held-out).

    Args:
        holdout: a list of measurement ids, or a fraction in (0, 1) of the measurements drawn at
            random (seeded) within each feature kind, so that every kind stays in training.
        seed: for the random draw.
        remedy: what the message of an empty held-out set tells the user to change.
    """
    ids = data.measurements()
    if isinstance(holdout, (float, int)) and not isinstance(holdout, bool):
        frac = float(holdout)
        if not 0.0 < frac < 1.0:
            raise InputError(f"--holdout fraction must be in (0, 1), got {frac}")
        rng = np.random.default_rng(seed)
        # stratify by the set of feature kinds a measurement touches
        groups: dict[tuple, list[str]] = {}
        rows_of = data.points.measurement_rows()
        for m in ids:
            feats = set(data.points.feature[rows_of[m]])
            kinds = tuple(sorted(data.artefacts.features[f].kind if f else "free" for f in feats))
            groups.setdefault(kinds, []).append(m)
        chosen = []
        for members in groups.values():
            k = int(round(frac * len(members)))
            if k >= len(members):
                k = len(members) - 1
            chosen += list(rng.choice(members, size=k, replace=False)) if k > 0 else []
        held = set(chosen)
    else:
        held = set(holdout)
        unknown = held - set(ids)
        if unknown:
            raise InputError(f"held-out measurement(s) not in the points file: {', '.join(sorted(unknown))}",
                             data.points.path, None, "measurement")
    if not held:
        raise InputError(f"the held-out set is empty ({len(ids)} measurement(s): "
                         f"{', '.join(ids[:6])}{' ...' if len(ids) > 6 else ''}); {remedy}", data.points.path, None,
                         "measurement")
    if held == set(ids):
        raise InputError("every measurement is held out: nothing left to calibrate on", data.points.path, None,
                         "measurement")
    mask = np.array([m in held for m in data.points.measurement], bool)
    return data.select(~mask), data.select(mask)


def concat(a: CalibrationData, b: CalibrationData) -> CalibrationData:
    """``a``'s rows then ``b``'s (same artefacts and marker setting), files, markers and aux inputs kept."""
    pts, _ = merge_points(a.points, b.points)
    files = np.concatenate([a.point_files, b.point_files])
    aux = None
    if a.aux is not None or b.aux is not None:
        def join(name, width):
            va = None if a.aux is None else getattr(a.aux, name)
            vb = None if b.aux is None else getattr(b.aux, name)
            if va is None and vb is None:
                return None
            if va is None or vb is None:
                raise ValueError(f"aux input '{name}' is given for one part only")
            return np.concatenate([va, vb])
        aux = AuxData(join("temperature", ()), join("tau_gravity", None), join("tau_contact", None), join("time", ()),
                      join("motion", None), join("capture", None))
    marker = None if a.marker is None and b.marker is None else np.concatenate([a.markers, b.markers])
    return CalibrationData(pts, a.artefacts, aux, files, marker, a.marker_offsets, a.tracker,
                           tuple(dict.fromkeys(a.left_out_lengths + b.left_out_lengths)))


def split_poses(data: CalibrationData, fraction: float, keep=None) -> np.ndarray:
    """Held-out mask (N,) of a share ``fraction`` of the poses (points) of every artefact instance (a
    feature within a measurement; the reference points as one instance): the poses of the instance in
    :func:`pose_order`, and of them the ones at evenly spaced ranks (:func:`spread`), so the held-out poses
    span the instance's range of poses and are a function of the poses alone (not of their order in the file
    or of a seed). An instance keeps at least ``keep[kind]`` points (default the fewest its fit needs, plus
    one) outside the mask, so that its centre (axis, plane) can still be fitted on the rest; smaller
    instances are never held.
    """
    from .kinds import MIN_POINTS
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"the held-out share of poses must be in (0, 1), got {fraction}")
    keep = keep or {k: v[0] + 1 for k, v in MIN_POINTS.items()}
    out = np.zeros(len(data), bool)
    for kind, rows in pose_groups(data):
        n = len(rows)
        k = min(int(round(fraction * n)), n - keep.get(kind, 1))
        if k >= 1:
            out[rows[pose_order(data.points.q[rows])][spread(n, k)]] = True
    return out


def pose_order(q: np.ndarray) -> np.ndarray:
    """Order (indices) of poses ``q`` (n, joints) [rad] along their main direction of variation: the first
    principal axis of the joint angles, its sign fixed so that its largest component is positive; equal
    projections in their given order. Dealt in turn along this order, every part of a split spans the range
    of the poses, and the split depends on the poses, not on the order of the rows."""
    q = np.asarray(q, dtype=float)
    x = q - q.mean(axis=0)
    if len(q) < 2 or not np.any(x):
        return np.arange(len(q))
    axis = np.linalg.svd(x, full_matrices=False)[2][0]
    axis = axis * np.sign(axis[np.argmax(np.abs(axis))])
    return np.argsort(x @ axis, kind="stable")


def blocked_folds(q: np.ndarray, k: int) -> np.ndarray:
    """Fold (0..k-1) of every pose ``q`` (n, J) [rad]: blocks of the joint space by recursive bisection along the
    principal directions (:func:`~calibration.data.pose_order` of the part at hand, the angles taken about each
    joint's circular mean, :func:`centred_angles`): the poses split at the rank that gives the two sides
    ``floor(k/2)`` and ``ceil(k/2)`` folds' shares, each side split again along its own main direction, until one
    fold a part. The folds are near equal in size and contiguous in joint space, so that a held-out pose's nearest
    training pose lies across a block's border rather than beside it. No seed: a function of the poses."""
    a = centred_angles(q)
    out = np.zeros(len(a), dtype=int)

    def split(rows: np.ndarray, first: int, parts: int) -> None:
        if parts < 2 or len(rows) < 2:
            out[rows] = first
            return
        low = parts // 2
        order = rows[pose_order(a[rows])]
        cut = int(round(len(rows) * low / parts))
        split(order[:cut], first, low)
        split(order[cut:], first + low, parts - low)

    split(np.arange(len(a)), 0, k)
    return out


def centred_angles(q: np.ndarray) -> np.ndarray:
    """Joint angles ``q`` (n, J) [rad] measured from each joint's circular mean, in (-pi, pi]: a range across +-pi
    is one interval."""
    q = np.asarray(q, dtype=float)
    centre = np.angle(np.mean(np.exp(1j * q), axis=0))
    return np.angle(np.exp(1j * (q - centre)))


def spread(n: int, k: int) -> np.ndarray:
    """``k`` of ``n`` ranks evenly spaced (the middle of each of ``k`` equal parts): ``floor((j + 1/2) n / k)``."""
    return np.floor((np.arange(k) + 0.5) * n / k).astype(int)


def heldout_mask(data: CalibrationData, path: str) -> np.ndarray:
    """The rows of ``data`` (:func:`make_data` with ``heldout``) that come from the held-out points file
    ``path`` (as read: its ``PointSet.path``), (N,)
    bool; each must lie on an artefact instance (a feature within a measurement; the reference points) that the
    training rows fit, with at least the fewest points that fit needs, else an InputError naming the held-out
    file's line."""
    from .kinds import MIN_POINTS
    mask = np.asarray(data.files == path, bool)
    kind_of = {}
    for kind, rows in pose_groups(data):
        for i in rows:
            kind_of[i] = kind
    train_count: dict[tuple, int] = {}
    keys = {}
    for i in range(len(data.points)):
        kind = kind_of.get(i)
        if kind is None:
            continue
        keys[i] = ("*", "") if kind == "reference" else (data.points.measurement[i], data.points.feature[i])
        if not mask[i]:
            train_count[keys[i]] = train_count.get(keys[i], 0) + 1
    for i in (int(k) for k in np.flatnonzero(mask)):
        kind = kind_of.get(i)
        if kind is None:
            raise InputError("a held-out pose that nothing measures: no feature and no reference coordinates",
                             path, int(data.points.line_numbers[i]), "feature")
        need = 3 if kind == "reference" else MIN_POINTS[kind][0]
        have = train_count.get(keys[i], 0)
        if have < need:
            what = ("the reference points" if kind == "reference" else
                    f"the {kind} '{keys[i][1]}' of measurement '{keys[i][0]}'")
            raise InputError(f"a held-out pose on {what}, which the training points fit on {have} point(s): a "
                             f"held-out pose is predicted against its feature as fitted on the training points, "
                             f"which needs {need}", path, int(data.points.line_numbers[i]),
                             "measurement" if kind != "reference" else None)
    return mask


def pose_groups(data: CalibrationData) -> list[tuple[str, np.ndarray]]:
    """``(kind, point indices)`` of every artefact instance (a feature within a measurement) and of the
    reference points (one group, kind "reference"), in file order; unused points are in none."""
    pts, arte = data.points, data.artefacts
    xref = data.reference
    ref = np.all(np.isfinite(xref), axis=1) if xref is not None else np.zeros(len(pts), bool)
    groups: dict[tuple, list[int]] = {}
    for i in range(len(pts)):
        f = pts.feature[i]
        kind = arte.features[f].kind if f else ("reference" if ref[i] else None)
        if kind is not None:
            key = ("*", "", "reference") if kind == "reference" else (pts.measurement[i], f, kind)
            groups.setdefault(key, []).append(i)
    return [(key[2], np.array(rows)) for key, rows in groups.items()]
