"""Deflection-aware kinematic model of a portable measuring arm (AACMM).

One description (:class:`ArmDescription`, read from the TOML of docs/formats.md §2) feeds three
evaluators that agree to 1e-12 m: the batch path (:func:`ball_centres`), Pinocchio
(:class:`PinocchioArm`, built from the generated URDF) and CasADi (:func:`casadi_ball_centre`).
Conventions: docs/CONVENTIONS.md.
"""
# Every public name loads on first use (PEP 562), so `aacmm --help` and `import arm_model.cli` do not
# import numpy, the readers or the URDF writer: name -> the submodule that defines it.
_HOME = {
    "AacmmError": "errors", "InputError": "errors", "NumericalError": "errors", "read_text": "errors",
    "QUANTITY_OF_UNIT": "units", "UNIT_FACTORS": "units", "split_unit": "units", "to_si": "units",
    "ArmDescription": "description", "JointRow": "description", "Probe": "description",
    "load_description": "description", "parse_description": "description", "format_description": "description",
    "ParamSpec": "params", "param_spec": "params", "split_params": "params", "apply_params": "params",
    "ball_centres": "kinematics", "rigid_centres": "kinematics",
    "PointSet": "io", "Artefacts": "io", "Feature": "io", "Distance": "io", "ForceSignal": "io",
    "read_points": "io", "read_artefacts": "io", "read_force_signal": "io", "check_features": "io",
    "atomic_write_text": "io", "write_csv": "io", "csv_records": "io",
    "urdf_text": "urdf", "load_arm": "urdf_import", "description_from_urdf": "urdf_import",
    "PinocchioArm": "pinocchio_model", "casadi_ball_centre": "casadi_model",
    "Tracker": "tracker", "marker_positions": "tracker",
}

__all__ = [
    "AacmmError", "InputError", "NumericalError", "read_text",
    "QUANTITY_OF_UNIT", "UNIT_FACTORS", "split_unit", "to_si",
    "ArmDescription", "JointRow", "Probe", "load_description", "parse_description", "format_description",
    "ParamSpec", "param_spec", "split_params", "apply_params",
    "ball_centres", "rigid_centres",
    "PointSet", "Artefacts", "Feature", "Distance", "ForceSignal", "read_points", "read_artefacts",
    "read_force_signal", "check_features", "atomic_write_text", "write_csv", "csv_records",
    "urdf_text", "load_arm", "description_from_urdf", "PinocchioArm", "casadi_ball_centre",
    "Tracker", "marker_positions",
]


def __getattr__(name):
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'arm_model' has no attribute '{name}'")
    import importlib
    value = getattr(importlib.import_module(f".{home}", __name__), name)
    globals()[name] = value             # once loaded, a plain attribute
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
