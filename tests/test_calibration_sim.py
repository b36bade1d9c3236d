"""Acceptance on a simulated campaign (arm_model.sim, examples/campaigns/calibration.toml): the true DH
errors are recovered within 3 sigma of the reported uncertainty, and on held-out measurements the
length error and the articulation spread shrink at least 5x against the nominal model.

The simulator's truth carries a softer probe (the model frees the probe compliances), a force sensor
with gain and offset errors, and noise the model does not know (encoder quantisation, probing
repeatability). The model carries the force-sensor effect: its gains are not separable from the
compliances nor its offsets from the probe offset (the fit finds that and holds them), so the truth
maps onto the kept parameters. Without it, the 0.03 N offset along probe x shifts the ball by
c F = 0.43 um, which j7.a absorbs: about 1.5 of its sigmas, enough to fail the 3-sigma test on some
seeds (seeds 1-6 were checked both ways while writing this test; this one was the worst without it)."""
from __future__ import annotations

from pathlib import Path

import pytest

sim = pytest.importorskip("arm_model.sim")

from arm_model.effects import ForceSensorError  # noqa: E402
from arm_model.model import ArmModel  # noqa: E402
from calibration import FitOptions, Weights, calibrate, make_data, split_holdout  # noqa: E402

CAMPAIGN = Path(__file__).resolve().parents[1] / "examples" / "campaigns" / "calibration.toml"
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def campaign():
    if not CAMPAIGN.exists():
        pytest.skip("no calibration campaign in examples/campaigns")
    camp = sim.load_campaign(CAMPAIGN)
    return camp, sim.simulate(camp, seed=1)


def test_simulated_campaign_acceptance(campaign):
    camp, run = campaign
    model = ArmModel(camp.arm, (ForceSensorError(),))
    data = make_data(run.points, run.artefacts, model, reference=run.reference_points)
    train, test = split_holdout(data, 0.25, seed=1)
    free = ["j*", "probe.x", "probe.y", "probe.z", "probe.compliance_*", "force.*"]
    res = calibrate(model, train, FitOptions(free=free, weights=Weights(probe=2e-6, reference=10e-6)))
    assert res.status.startswith("converged")
    assert 0.7 < res.s0 < 1.4, res.s0
    truth = model.spec.vector({k: v for k, v in run.truth["p"].items() if k in model.spec.names})
    peq = res.equivalent(truth)
    dh = [n for n in res.free if n.startswith("j")]
    assert len(dh) >= 20
    z = {n: (res.value(n) - peq[model.spec.index(n)]) / res.uncertainty(n) for n in dh}
    assert max(abs(v) for v in z.values()) < 3.0, {k: round(v, 2) for k, v in z.items()}
    rows = {r["key"]: r for r in res.compare(test)}
    assert rows["length_error_max"]["ratio"] >= 5.0, rows["length_error_max"]
    assert rows["articulation_2sigma"]["ratio"] >= 5.0, rows["articulation_2sigma"]
    assert rows["articulation_half_range"]["ratio"] >= 5.0
