"""Campaign files, the written outputs, determinism and ``aacmm simulate``."""
from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError, check_features, read_artefacts, read_points
from arm_model.cli import main
from arm_model.shipped import version
from arm_model.sim import campaign_from_dict, load_campaign, simulate
from conftest import ROOT, assert_close

EXAMPLES = sorted((ROOT / "examples" / "campaigns").glob("*.toml"))
SMALL = {"seed": 4, "sensor": "xyz", "noise": {"probing_repeatability_um": 2.0, "force_noise_N": 0.01},
         "truth": {"eccentricity": [{"joint": "j3", "amplitude_arcsec": 5.0}]},
         "task": [{"kind": "ring", "measurements": 2, "points_per_row": 4},
                  {"kind": "ballbar", "positions": 3, "points_per_sphere": 3},
                  {"kind": "tracker", "nests": 3, "articulations": 2}]}


@pytest.fixture(scope="module")
def small():
    return simulate(campaign_from_dict(SMALL))


def _digest(files: dict) -> str:
    h = hashlib.sha256()
    for name in sorted(files):
        h.update(name.encode())
        h.update(files[name] if isinstance(files[name], bytes) else files[name].encode())
    return h.hexdigest()


def _read_dir(path: Path) -> dict:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def test_same_seed_same_bytes(small, tmp_path):
    again = simulate(campaign_from_dict(SMALL))
    a, b = tmp_path / "a", tmp_path / "b"
    small.write(a)
    again.write(b)
    assert _digest(_read_dir(a)) == _digest(_read_dir(b))
    assert set(_read_dir(a)) >= {"points.csv", "points-ref.csv", "artefacts.toml", "truth.toml",
                                 "truth-points.csv", "signals/ring-01.csv", "signals/bar-pos-03.csv"}
    other = simulate(campaign_from_dict(SMALL), seed=5)
    assert other.texts["points.csv"] != small.texts["points.csv"]
    assert other.campaign.seed == 5
    assert simulate(campaign_from_dict(dict(SMALL, seed=5))).texts == other.texts


def test_written_files_read_back_by_the_core_readers(small, tmp_path):
    small.write(tmp_path)
    pts = read_points(tmp_path / "points.csv", 7)
    for name in ("measurement", "feature", "q", "force", "temperature", "time"):
        a, b = getattr(pts, name), getattr(small.points, name)
        assert (a == b).all(), name
    art = read_artefacts(tmp_path / "artefacts.toml")
    assert art.features.keys() == small.artefacts.features.keys()
    assert art.features["ring"].diameter == pytest.approx(174.996e-3, abs=1e-15)
    assert art.distances[0].between == ("bar-A", "bar-B") and art.distances[0].length == pytest.approx(0.6)
    check_features(pts, art)
    ref = read_points(tmp_path / "points-ref.csv", 7)
    check_features(ref, art)
    assert ref.ref is not None and (ref.ref == small.reference_points.ref).all()
    assert len(pts) == 2 * 12 + 3 * 6 and len(ref) == 3 * 2
    truth = tomllib.loads((tmp_path / "truth.toml").read_text())
    assert (tmp_path / "truth.toml").read_text().startswith("# TRUTH")
    assert truth["seed"] == 4 and "eccentricity(j3)" in truth["effects_on"]


def test_tracker_reference_is_a_rigid_transform_of_the_truth(small):
    ref = small.reference_points.ref[:, 0]
    T = small.truth["T_ref_base"]["nest"]
    expected = small.ref_true_centres @ T[:3, :3].T + T[:3, 3]
    err = ref - expected
    assert np.abs(err).max() < 6 * 10e-6 and np.std(err) > 2e-6          # 10 um tracker noise
    assert_close(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.norm(T[:3, 3]) == pytest.approx(3.0)


def test_ballbar_positions_spread_over_the_volume():
    r = simulate(campaign_from_dict({"seed": 9, "signals": {"enabled": False},
                                     "task": [{"kind": "ballbar", "positions": 20, "points_per_sphere": 1}]}))
    pos = r.truth["placements"]["bar"]["positions"]
    assert len(pos) == 20 and len(r.points.measurements()) == 20
    a, b = np.array([p["A_m"] for p in pos]), np.array([p["B_m"] for p in pos])
    assert_close(np.linalg.norm(b - a, axis=1), np.full(20, 0.6), atol=1e-12)
    centre = (a + b) / 2
    az = np.degrees(np.arctan2(centre[:, 1], centre[:, 0]))
    assert np.ptp(az) > 300                     # all around the arm
    assert np.ptp(centre[:, 2]) > 0.3           # low and high
    d = (b - a) / 0.6
    assert np.abs(d[:, 2]).max() > 0.7 and np.abs(d[:, 2]).min() < 0.3   # vertical and horizontal bars


def test_example_campaigns_load_and_run_small(tmp_path):
    assert {p.name for p in EXAMPLES} >= {"paper-ring.toml", "paper-ring-xyz.toml", "calibration.toml",
                                         "hidden-eccentricity.toml"}
    for path in EXAMPLES:
        c = load_campaign(path)
        tasks = tuple(replace(t, measurements=1, opts=dict(t.opts, **{k: min(v, 2) for k, v in t.opts.items()
                                                                       if k in ("positions", "nests")}))
                      for t in c.tasks)
        r = simulate(replace(c, tasks=tasks, signals=dict(c.signals, enabled=False)))
        assert len(r.points) > 0 and r.stats["truth_residual_max_m"] < 1e-9, path.name
    paper = load_campaign(ROOT / "examples" / "campaigns" / "paper-ring.toml")
    ring = paper.tasks[0]
    assert paper.sensor == "two-channel" and ring.measurements == 17
    assert ring.opts["points_per_row"] * len(ring.opts["depths"]) == 72
    assert ring.opts["diameter"] == pytest.approx(174.996e-3)


# ---------------------------------------------------------------------------------------------
# bad input: one clear error naming file, line and key; nothing written

def _write(tmp_path, text, name="c.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text, line, key, words", [
    ('seed = 1\n[[task]]\nkind = "ring"\ndiameter = 175.0\n', 4, "task[1].diameter", "unit suffix"),
    ('seed = 1\n[[task]]\nkind = "ring"\ndiameter_N = 175.0\n', 4, "task[1].diameter_N", "length"),
    ('seed = 1\n[[task]]\nkind = "cone"\n', 3, "task[1].kind", "ring, sphere"),
    ('seed = 1\n[operator]\nforce_mean_N = 1.0\nfriction = 0.1\n[[task]]\nkind = "seat"\n', 4,
     "operator.friction", "unknown key"),
    ('seed = 1\n[[truth.eccentricity]]\njoint = "j9"\namplitude_deg = 0.001\n[[task]]\nkind = "seat"\n', 3,
     "truth.eccentricity[1].joint", "unknown joint"),
    ('seed = 1\n[truth.errors]\n"j2.d_deg" = 1.0\n[[task]]\nkind = "seat"\n', 3, "truth.errors.j2.d_deg", "length"),
    ('seed = "x"\n[[task]]\nkind = "seat"\n', 1, "seed", "whole number"),
    ('seed = 1\narm = "nowhere.toml"\n[[task]]\nkind = "seat"\n', 2, "arm", "not found"),
])
def test_bad_campaign_names_line_and_key(tmp_path, text, line, key, words):
    p = _write(tmp_path, text)
    with pytest.raises(InputError) as exc:
        load_campaign(p)
    e = exc.value
    assert e.path == str(p) and e.line == line and key in e.column and words in str(e), str(e)


def test_bad_toml_and_empty_campaign(tmp_path):
    with pytest.raises(InputError, match="not valid TOML") as exc:
        load_campaign(_write(tmp_path, "seed = \n"))
    assert exc.value.line == 1
    with pytest.raises(InputError, match="no \\[\\[task\\]\\]"):
        load_campaign(_write(tmp_path, "seed = 1\n"))


def test_cli_writes_and_summarises(tmp_path, capsys):
    c = _write(tmp_path, 'seed = 3\nsensor = "two-channel"\n[[task]]\nkind = "ring"\npoints_per_row = 4\n')
    assert main(["simulate", str(c), "-o", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "12 points in 1 measurement "  in out and "two-channel" in out and "truth check" in out
    assert (tmp_path / "out" / "signals" / "ring-01.csv").exists()
    # summary.json: version and the campaign's SHA-256 (computed here independently), as every command
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["aacmm_version"] == version()
    assert summary["input_sha256"][str(c)] == hashlib.sha256(c.read_bytes()).hexdigest()
    assert summary["seed"] == 3 and summary["points"] == {"points": 12, "measurements": 1}
    assert "summary.json" not in summary["files"] and "points.csv" in summary["files"]
    assert main(["simulate", str(c), "-o", str(tmp_path / "out2"), "--no-signals", "--seed", "8"]) == 0
    assert not (tmp_path / "out2" / "signals").exists()
    assert "seed 8" in capsys.readouterr().out


def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys):
    c = _write(tmp_path, 'seed = 3\n[[task]]\nkind = "ring"\ndepths_mm = "deep"\n')
    assert main(["simulate", str(c), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "line 4" in err and "depths_mm" in err
    assert not (tmp_path / "out").exists()


def test_never_writes_over_an_input(tmp_path):
    c = _write(tmp_path, 'seed = 3\n[[task]]\nkind = "seat"\narticulations = 2\n', name="truth.toml")
    before = c.read_text()
    with pytest.raises(InputError, match="over an input"):
        simulate(load_campaign(c)).write(tmp_path)
    assert c.read_text() == before and not (tmp_path / "points.csv").exists()


@settings(max_examples=25, deadline=None)
@given(st.floats(1.0, 100.0), st.sampled_from([("mm", 1e-3), ("um", 1e-6), ("m", 1.0)]),
       st.sampled_from([("deg", np.pi / 180), ("arcsec", np.pi / 648000), ("rad", 1.0)]))
def test_units_are_read_from_the_key_names(value, length, angle):
    c = campaign_from_dict({"seed": 1, "truth": {"eccentricity": [{"joint": "j2", f"amplitude_{angle[0]}": value}]},
                            "task": [{"kind": "sphere", f"diameter_{length[0]}": value}]})
    assert c.tasks[0].opts["diameter"] == pytest.approx(value * length[1], rel=1e-15)
    assert c.truth["eccentricity"][0]["amplitude"] == pytest.approx(value * angle[1], rel=1e-15)


def test_other_arm_conventions(tmp_path, nominal):
    """Modified DH and URDF-chain arms: the inverse kinematics and the truth use the core chain of
    any convention."""
    import re
    tasks = [{"kind": "sphere", "points": 4, "centre_mm": [450.0, 200.0, 150.0]},
             {"kind": "seat", "articulations": 4, "position_mm": [450.0, -200.0, 100.0]}]
    truth = {"eccentricity": [{"joint": "j2", "amplitude_deg": 0.002}], "thermal": {"alpha_per_K": 1e-5}}
    mdh = simulate(campaign_from_dict({"seed": 1, "truth": truth, "task": tasks},
                                      arm=replace(nominal, convention="mdh")))
    assert mdh.stats["truth_residual_max_m"] < 1e-9 and len(mdh.points) == 8
    # a URDF chain: the nominal arm's URDF up to the flange, a fixed ball 85 mm further
    text = (ROOT / "urdf" / "aacmm7.urdf").read_text()
    head = text[: text.index('<link name="stylus_root"')]
    head = re.sub(r'<joint name="(stylus_root_joint|probe_bend_y|probe_bend_x|probe_axial|ball_joint)".*?</joint>',
                  "", head, flags=re.S)
    (tmp_path / "arm.urdf").write_text(
        head + '<link name="ball"/><joint name="ball_joint" type="fixed"><parent link="flange"/>'
        '<child link="ball"/><origin xyz="0 0 0.085" rpy="0 0 0"/></joint></robot>')
    c = _write(tmp_path, 'seed = 2\narm = "arm.urdf"\ntip_frame = "ball"\n[truth.thermal]\nalpha_per_K = 1e-5\n'
               '[[task]]\nkind = "seat"\narticulations = 4\nposition_mm = [450.0, -200.0, 100.0]\n')
    r = simulate(load_campaign(c))
    assert r.campaign.arm.convention == "urdf" and "j1.origin_x" in r.truth["p"]
    assert r.stats["truth_residual_max_m"] < 1e-9
    with pytest.raises(InputError, match="tip_frame"):
        load_campaign(_write(tmp_path, 'arm = "arm.urdf"\n[[task]]\nkind = "seat"\n'))


def test_cone_directions_uniform_on_the_cap():
    """The simulator's one cap sampler (the full campaign's and the fast path's sphere normals, styli): unit
    vectors within the half angle, and uniform on the cap: the same distribution as rejection sampling from
    the uniform sphere (an independent reference; two-sample KS on cos theta and on the azimuth, seeded)."""
    from scipy import stats

    from arm_model.geometry import cone_directions, perpendicular_basis
    rng = np.random.default_rng(7)
    axis = np.array([0.3, -0.4, 0.866])
    axis /= np.linalg.norm(axis)
    half = np.arccos(0.2)
    v = cone_directions(rng, axis, half, 4000)
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    assert (v @ axis >= np.cos(half) - 1e-12).all()
    ref = rng.normal(size=(40000, 3))
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    ref = ref[ref @ axis >= np.cos(half)][:4000]
    e1, e2 = perpendicular_basis(axis)
    assert stats.ks_2samp(v @ axis, ref @ axis).pvalue > 0.01
    assert stats.ks_2samp(np.arctan2(v @ e2, v @ e1), np.arctan2(ref @ e2, ref @ e1)).pvalue > 0.01
    # and not a different cap: half the angle is told apart
    assert stats.ks_2samp(cone_directions(rng, axis, half / 2, 4000) @ axis, ref @ axis).pvalue < 1e-6
