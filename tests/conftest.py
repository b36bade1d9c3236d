"""Shared test helpers: paths, the nominal arm, one array comparison that also rejects NaN."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# property tests draw the same examples on every run (seeded, reproducible CI); a local
# exploration run can pass --hypothesis-profile=explore
settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]
NOMINAL = ROOT / "urdf" / "aacmm7.dh.toml"


def assert_close(actual, expected, atol: float, rtol: float = 0.0, msg: str = "") -> None:
    """np.testing.assert_allclose that also fails on NaN/inf in either side."""
    a, e = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert np.all(np.isfinite(a)), f"non-finite values in actual {msg}"
    assert np.all(np.isfinite(e)), f"non-finite values in expected {msg}"
    np.testing.assert_allclose(a, e, atol=atol, rtol=rtol, err_msg=msg)


def fd_jacobian(fun, x, eps: float = 1e-6) -> np.ndarray:
    """Central finite-difference Jacobian of fun: R^n -> R^m at x."""
    x = np.asarray(x, dtype=float)
    cols = []
    for k in range(x.size):
        dx = np.zeros_like(x)
        dx[k] = eps
        cols.append((np.asarray(fun(x + dx)) - np.asarray(fun(x - dx))) / (2 * eps))
    return np.column_stack(cols)


@pytest.fixture(scope="session")
def nominal():
    from arm_model import load_description
    return load_description(NOMINAL)


@pytest.fixture(scope="session")
def pin_arm(nominal):
    from arm_model import PinocchioArm
    return PinocchioArm(nominal)


def simulate_and_close_loop(tmp_path: Path, campaign: str, *options: str) -> tuple[Path, Path, dict]:
    """``aacmm simulate`` of the campaign TOML text, then ``aacmm close-loop`` on what it wrote with the
    nominal arm, ``--sigma-probe-um 2`` and ``options``, both through the command line: (simulation folder,
    loop folder, the loop's summary.json)."""
    import json

    from arm_model.cli import main
    (tmp_path / "campaign.toml").write_text(campaign)
    sim, out = tmp_path / "sim", tmp_path / "loop"
    assert main(["simulate", str(tmp_path / "campaign.toml"), "-o", str(sim)]) == 0
    assert main(["close-loop", str(sim / "points.csv"), str(sim / "artefacts.toml"), "--arm", str(NOMINAL),
                 "--sigma-probe-um", "2", *options, "-o", str(out)]) == 0
    return sim, out, json.loads((out / "summary.json").read_text())


def seat_figures_of(res, desc, points) -> dict:
    """:func:`calibration.placements.seat_figures` of a fit's ball centres of ``points`` of the real seat
    data (two holes 50 mm apart), the gravity and contact torques (if the fit's model needs them) from the
    nominal description ``desc``, as the fit had them."""
    from arm_model import PinocchioArm
    from arm_model.model import AuxData
    from calibration.placements import seat_figures
    m = res.model
    aux = None
    if m.needs():
        g, c = PinocchioArm(desc).torques(points.q, points.wrench)
        aux = AuxData(None, g, c)
    return seat_figures(m.ball_centres(points.q, points.wrench, res.p, aux), points.feature, ("hole-0", "hole-1"),
                        0.05)


def loop_fit_options():
    """The options of ``close-loop``'s own fits (no prior; the practical-resolution rule holds weak parameters):
    plain ``calibrate`` compared with the loop at the same estimation."""
    from calibration.loop import LEGACY_RESOLUTION
    from calibration.options import FitOptions
    return FitOptions(weights_from_data=True, prior_scale=None, min_resolution=LEGACY_RESOLUTION)
