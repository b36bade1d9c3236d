"""Measurement simulator: a virtual arm with a hidden truth, an operator, artefacts, and effects the
model does not declare.

Python API (stable)::

    from arm_model.sim import load_campaign, campaign_from_dict, simulate

    campaign = load_campaign("examples/campaigns/paper-ring.toml")   # or campaign_from_dict({...})
    result = simulate(campaign, seed=7)        # seed: the campaign's unless given
    result.points          # arm_model.io.PointSet, identical to reading the written points.csv
    result.reference_points  # PointSet of the tracker rows (points-ref.csv, with ref), or None
    result.artefacts       # arm_model.io.Artefacts (artefacts.toml)
    result.signals         # {measurement id: arm_model.io.ForceSignal} (signals/<id>.csv)
    result.truth           # dict: "p" (true parameters by name, SI), "model" (core ArmModel),
                           #       "p_vector", "spec", "effects", "noise", "placements", "T_ref_base" ...
    result.true_centres    # (N, 3) [m] true deflected ball centres of the points rows (base frame)
    result.true_q          # (N, J) [rad] true joint angles of the points rows
    result.true_wrench     # (N, 6) true wrench at the ball (probe frame)
    result.write("out/")   # points.csv, points-ref.csv, artefacts.toml, signals/*.csv, truth.toml,
                           # truth-points.csv; atomic, never over an input

A small campaign in Python, without files::

    campaign = campaign_from_dict({"seed": 1, "task": [{"kind": "sphere", "points": 8}]})

The truth is the core's :class:`arm_model.model.ArmModel` with a true parameter vector (base
errors, then the parameters of each effect that is on), so analysis and truth share one physics;
force-sensor cross-talk, encoder quantisation and probing repeatability live here only.
Command line: ``aacmm simulate campaign.toml -o out/``. Reference: docs/simulator.md.
"""
from .campaign import SENSORS, TASK_KINDS, Campaign, Task, campaign_from_dict, load_campaign
from .run import SimResult, simulate
from .truth import Truth, build_truth

__all__ = ["Campaign", "Task", "TASK_KINDS", "SENSORS", "campaign_from_dict", "load_campaign",
           "SimResult", "simulate", "Truth", "build_truth"]
