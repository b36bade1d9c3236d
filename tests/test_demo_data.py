"""The bundled data are exactly what the simulator writes for their campaign (not stale)."""
from __future__ import annotations

from arm_model.sim import load_campaign, simulate
from conftest import ROOT


def test_bundled_ring_campaign_is_regenerable(tmp_path):
    result = simulate(load_campaign(ROOT / "examples" / "campaigns" / "paper-ring-xyz.toml"))
    result.write(tmp_path)
    for name in ("points.csv", "artefacts.toml"):
        assert (tmp_path / name).read_bytes() == (ROOT / "examples" / "data" / "paper-ring-xyz" / name).read_bytes(), (
            f"examples/data/paper-ring-xyz/{name} is stale: regenerate it with "
            "aacmm simulate examples/campaigns/paper-ring-xyz.toml -o DIR --no-signals")
