"""No message names an option that does not exist, and the solver does what it takes to converge from the
nominal: a restart from the best point when an attempt runs out of iterations, a continuation in the prior's scale when
a fit with the prior does not converge."""
from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

import numpy as np
import pytest

from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, Weights, calibrate, make_data

ROOT = Path(__file__).resolve().parents[1]
SPEC = SynthSpec(ballbars=6, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=10, rings=0,
                 ring_points=0, planes=0, plane_points=0, reference_points=0, force=0.0, noise=5e-6,
                 reference_noise=5e-6)


def _options() -> set[str]:
    """Every option string of every aacmm subcommand (and of the top-level parser)."""
    from arm_model.cli import build_parser
    out = set()

    def walk(parser):
        for action in parser._actions:
            out.update(action.option_strings)
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    walk(sub)
    walk(build_parser())
    return out


def _strings(path: Path):
    """(line, text) of every string constant of a module (f-strings' literal parts included)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.lineno, node.value


def test_every_option_a_message_names_exists():
    """A ``--option`` named in any string of the calibration package or the arm model (error messages, help,
    console lines) is an option of some aacmm command; the bare ``max_iter`` of "raise max_iter" is gone."""
    known = _options() | {"--out", "--no-live"}       # python -m arm_model.demo's own options
    bad = []
    for path in sorted((ROOT / "calibration").glob("*.py")) + sorted((ROOT / "arm_model").rglob("*.py")):
        for line, text in _strings(path):
            for m in re.finditer(r"(?<![\w-])(--[a-z][A-Za-z0-9-]*[A-Za-z0-9])(-[*<]|-$)?", text):
                if m.group(1) not in known and not m.group(2):          # --mpe-*-um: a family of options
                    bad.append(f"{path.relative_to(ROOT)}:{line}: {m.group(1)}")
            if re.search(r"raise max_iter|raise rank_tol\b", text):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {text[:60]!r}")
    assert not bad, bad


@pytest.fixture(scope="module")
def campaign(nominal):
    model = ArmModel(nominal)
    p = random_truth(model, np.random.default_rng(4), length=0.2e-3, angle=1e-3, probe=0.2e-3)
    c = make_campaign(model, SPEC, seed=4, p_true=p)
    return model, make_data(c.points, c.artefacts, model)


def test_a_fit_that_runs_out_of_iterations_restarts_from_its_best_point(campaign):
    """Each attempt allowed 4 iterations: the restarts from the best point and its damping reach the same
    solution as one long attempt (to 1e-6 of each parameter's uncertainty) in no more iterations than it took
    (measured: 9 and 9), and the iterations counted are all of them."""
    from calibration.solver import RESTARTS
    model, data = campaign
    full = calibrate(model, data, FitOptions(weights=Weights(5e-6, 5e-6), prior_scale=1.0))
    assert full.iterations > 4
    short = calibrate(model, data, FitOptions(weights=Weights(5e-6, 5e-6), prior_scale=1.0, max_iter=4,
                                              free=full.free))
    assert short.status.startswith("converged") and 4 < short.iterations <= min(full.iterations + 2, 4 * (RESTARTS + 1))
    idx = [model.spec.index(n) for n in full.free]
    assert np.max(np.abs(short.p[idx] - full.p[idx]) / full.u) < 1e-6


def test_no_convergence_names_no_option(campaign):
    """One iteration an attempt cannot converge: the error says what happened and what to check, and names
    no option."""
    from arm_model import NumericalError
    model, data = campaign
    with pytest.raises(NumericalError) as exc:
        calibrate(model, data, FitOptions(weights=Weights(5e-6, 5e-6), prior_scale=None, max_iter=1))
    text = str(exc.value)
    assert "did not converge" in text and "restarts from its best point" in text and "max_iter" not in text
    assert "--" not in text


def test_a_fit_that_does_not_converge_continues_from_a_narrow_prior(campaign, monkeypatch):
    """When the fit with the prior fails (here: made to fail once), the continuation in the prior's scale
    (narrow, then wider, then the prior itself) reaches the fit's own solution."""
    import importlib
    cal = importlib.import_module("calibration.calibrate")
    from arm_model import NumericalError
    model, data = campaign
    options = FitOptions(weights=Weights(5e-6, 5e-6), prior_scale=1.0)
    direct = calibrate(model, data, options)
    real = cal.levenberg_marquardt
    calls = {"n": 0}

    def failing_once(prob, p, states, **kw):
        if kw.get("prior") is not None and len(prob.free) and calls["n"] == 0:
            calls["n"] += 1
            raise NumericalError("made to fail")
        return real(prob, p, states, **kw)
    monkeypatch.setattr(cal, "levenberg_marquardt", failing_once)
    cont = calibrate(model, data, options)
    assert calls["n"] == 1 and cont.free == direct.free
    idx = [model.spec.index(n) for n in direct.free]
    assert np.max(np.abs(cont.p[idx] - direct.p[idx]) / direct.u) < 1e-6
