"""Deflection-aware kinematic model of a portable measuring arm (AACMM).

One description (:class:`ArmDescription`, read from the TOML of docs/formats.md §2) feeds three
evaluators that agree to 1e-12 m: the batch path (:func:`ball_centres`), Pinocchio
(:class:`PinocchioArm`, built from the generated URDF) and CasADi (:func:`casadi_ball_centre`).
Conventions: docs/CONVENTIONS.md.
"""
from ._errors import AacmmError, InputError, NumericalError, read_text
from ._units import QUANTITY_OF_UNIT, UNIT_FACTORS, split_unit, to_si
from .description import ArmDescription, JointRow, Probe, load_description, parse_description, format_description
from .params import ParamSpec, param_spec, split_params, apply_params
from .kinematics import ball_centres, rigid_centres
from .io import (PointSet, Artefacts, Feature, Distance, ForceSignal, read_points, read_artefacts,
                 read_force_signal, check_features, atomic_write_text, write_csv, csv_records)
from .urdf import urdf_text
from .urdf_import import load_arm, description_from_urdf

__all__ = [
    "AacmmError", "InputError", "NumericalError", "read_text",
    "QUANTITY_OF_UNIT", "UNIT_FACTORS", "split_unit", "to_si",
    "ArmDescription", "JointRow", "Probe", "load_description", "parse_description", "format_description",
    "ParamSpec", "param_spec", "split_params", "apply_params",
    "ball_centres", "rigid_centres",
    "PointSet", "Artefacts", "Feature", "Distance", "ForceSignal", "read_points", "read_artefacts",
    "read_force_signal", "check_features", "atomic_write_text", "write_csv", "csv_records",
    "urdf_text", "load_arm", "description_from_urdf", "PinocchioArm", "casadi_ball_centre",
]


def __getattr__(name):  # heavy backends load on first use, not at import
    if name == "PinocchioArm":
        from .pinocchio_model import PinocchioArm
        return PinocchioArm
    if name == "casadi_ball_centre":
        from .casadi_model import casadi_ball_centre
        return casadi_ball_centre
    raise AttributeError(name)
