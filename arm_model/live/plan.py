"""The plan of a live session (docs/formats.md §9): which features the operator probes, in which order.

A plan is an artefacts file (docs/formats.md §4) with two more keys: ``points`` in a ``[[feature]]``
(how many contacts it takes before the session moves on to the next feature; the last feature may leave
it out and take every remaining contact) and, at the top, ``measurement`` (the measurement id of the
session's points; default: the session folder's name)::

    measurement = "bench-2026-11-24"

    [[feature]]
    id = "ring"
    kind = "ring"
    diameter_mm = 174.996
    u_diameter_mm = 0.00105
    points = 12

    [[feature]]
    id = "seat-A"
    kind = "seat"
    points = 5

Features are taken in file order. The ``[[distance]]`` tables of an artefacts file (a certified length
between two features' centres) are checked after each point too. The session writes the plan's
features and distances as ``artefacts.toml`` into its folder, so ``aacmm calibrate`` reads the record.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError, parse_toml, read_text
from ..io import Artefacts, Feature, format_artefacts, id_problem, parse_artefacts
from ..toml_lines import toml_key_lines, top_key_line

__all__ = ["PlanFeature", "SessionPlan", "read_plan", "parse_plan", "format_plan", "single_feature_plan",
           "MAX_PLAN_POINTS"]

#: the most contacts one plan entry may ask for
MAX_PLAN_POINTS = 100_000
#: fewest points that give each kind's size and form (a plan asking fewer never fits its feature)
NEEDED_POINTS = {"ring": 4, "cylinder": 4, "sphere": 5, "plane": 3, "seat": 1, "point": 1}


@dataclass(frozen=True)
class PlanFeature:
    """One entry of a plan: the ``feature`` (an :class:`arm_model.io.Feature`) and how many contacts it
    takes (``points``; None: every remaining contact)."""
    feature: Feature
    points: int | None = None


@dataclass(frozen=True)
class SessionPlan:
    """A session's plan: its ``entries`` in order, the certified ``distances`` between features, the
    ``measurement`` id of the points (None: the caller's default) and the file it came from."""
    entries: tuple = ()
    distances: tuple = ()
    measurement: str | None = None
    path: str | None = None

    @property
    def artefacts(self) -> Artefacts:
        """The plan's features and distances as an :class:`~arm_model.io.Artefacts`."""
        return Artefacts(self.path or "<plan>", {e.feature.id: e.feature for e in self.entries}, self.distances)

    def artefacts_text(self) -> str:
        """``artefacts.toml`` of the session folder (docs/formats.md §4)."""
        return format_artefacts([e.feature for e in self.entries], self.distances,
                                "The features of a live session's plan (docs/formats.md §4), for aacmm calibrate.")

    def with_feature(self, feature: Feature, points: int | None = None) -> SessionPlan:
        """This plan with one more entry (an ad hoc feature); its id must be new."""
        if feature.id in {e.feature.id for e in self.entries}:
            raise ValueError(f"feature id '{feature.id}' is already in the plan")
        return SessionPlan(self.entries + (PlanFeature(feature, points),), self.distances, self.measurement, self.path)


def read_plan(path: str | Path) -> SessionPlan:
    """Read a plan file (see the module doc); every error names the file, the line and the key."""
    return parse_plan(read_text(path, "the session plan"), str(path))


def parse_plan(text: str, path: str = "<plan>") -> SessionPlan:
    """Parse a plan's TOML text (see :func:`read_plan`)."""
    art = parse_artefacts(text, path, extra_keys=("measurement",), extra_feature_keys=("points",))
    data = parse_toml(text, path)
    lines = toml_key_lines(text)
    measurement = data.get("measurement")
    if measurement is not None and id_problem(measurement):
        raise InputError(f"'measurement' {id_problem(measurement)}", path, top_key_line(lines, "measurement"),
                         "key 'measurement'")
    entries = []
    tables = data["feature"]
    for i, (t, feature) in enumerate(zip(tables, art.features.values(), strict=True)):
        n = t.get("points")
        where = (path, lines.get(("feature", i, "points")), f"key 'feature[{i + 1}].points'")
        if n is None:
            if i != len(tables) - 1:
                raise InputError(f"feature '{feature.id}' needs 'points' (how many contacts it takes); only the last "
                                 "feature may leave it out and take every remaining contact",
                                 path, lines.get(("feature", i)), f"key 'feature[{i + 1}]'")
        elif isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_PLAN_POINTS:
            raise InputError(f"'points' must be a whole number from 1 to {MAX_PLAN_POINTS}, got {n!r}", *where)
        elif n < NEEDED_POINTS[feature.kind]:
            raise InputError(f"a {feature.kind} needs at least {NEEDED_POINTS[feature.kind]} points for its fit, got "
                             f"{n}: the session would never fit '{feature.id}'", *where)
        entries.append(PlanFeature(feature, n))
    return SessionPlan(tuple(entries), tuple(art.distances), measurement, path)


def format_plan(plan: SessionPlan, comment: str | None = None) -> str:
    """The TOML text of a plan that :func:`parse_plan` reads back: its measurement, its features with their
    ``points``, its distances (lengths in mm)."""
    from ..description import toml_text
    mm = {"diameter": "diameter_mm", "u_diameter": "u_diameter_mm", "form_error": "form_error_mm"}
    doc = {} if plan.measurement is None else {"measurement": plan.measurement}
    doc["feature"] = [{"id": e.feature.id, "kind": e.feature.kind,
                       **{key: getattr(e.feature, name) * 1e3 for name, key in mm.items()
                          if getattr(e.feature, name) is not None},
                       **({} if e.points is None else {"points": e.points})} for e in plan.entries]
    if plan.distances:
        doc["distance"] = [{"between": list(d.between), "length_mm": d.length * 1e3,
                            **({} if d.u_length is None else {"u_length_mm": d.u_length * 1e3})}
                           for d in plan.distances]
    return toml_text(doc, comment or "The plan of a live session (docs/formats.md §9): the features in the order "
                                     "they are probed, how many points each takes.")


def single_feature_plan(spec: str) -> SessionPlan:
    """The plan of ``--feature KIND:ID[:DIAMETER_MM]`` (one ad hoc feature taking every contact)."""
    parts = spec.split(":")
    if len(parts) not in (2, 3) or not parts[1].strip():
        raise InputError(f"--feature must be KIND:ID or KIND:ID:DIAMETER_MM, got {spec!r}")
    text = f'[[feature]]\nid = {_toml_str(parts[1])}\nkind = {_toml_str(parts[0])}\n'
    if len(parts) == 3:
        from ..csv_io import parse_number
        d = parse_number(parts[2])      # the one rule of a number (ASCII, no '_': float() took '2_5' and '١٢')
        if d is None:
            raise InputError(f"--feature: the diameter must be a number in mm, got {parts[2]!r}")
        text += f"diameter_mm = {d!r}\n"
    try:
        return parse_plan(text, "--feature")
    except InputError as exc:
        raise InputError(f"{exc.reason} (in --feature {spec!r})") from None


def _toml_str(text: str) -> str:
    import json
    return json.dumps(text)

