"""A live session against independent references: the simulator's campaign it streams (every contact
found, each point at its capture's angles, the over-force points and no other flagged), ``aacmm tip`` on
the session's own record (byte for byte), the ring pipeline's peak finder on the same signals, and
synthetic force signals whose contacts are known (light touches over noise, a sensor offset that
drifts, a spike, noise alone)."""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from arm_model.cli import main
from arm_model.io import check_features, read_artefacts, read_points
from arm_model.live import ContactOptions, Session, read_status
from arm_model.live.plan import format_plan
from arm_model.sim import simulate
from arm_model.sim.campaign import load_campaign
from arm_model.sim.stream import sample_stream, stream_plan
from conftest import ROOT

CAMPAIGN = ROOT / "examples" / "live" / "campaign.toml"
Q0 = np.radians([10.0, 35.0, -5.0, 70.0, 3.0, 40.0, 8.0])


def rows(path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module", params=[19, 26])
def replay(request, tmp_path_factory):
    """A simulated campaign (the bundled live campaign with another seed), its stream replayed by
    ``aacmm live --speed 0``, and ``aacmm tip`` on the session's points."""
    d = tmp_path_factory.mktemp(f"replay{request.param}")
    result = simulate(load_campaign(CAMPAIGN), seed=request.param)
    (d / "samples.csv").write_text(sample_stream(result, request.param))
    (d / "plan.toml").write_text(format_plan(stream_plan(result)))
    out = d / "session"
    assert main(["live", str(d / "samples.csv"), "--arm", "aacmm7", "--plan", str(d / "plan.toml"), "-o", str(out),
                 "--speed", "0", "-q"]) == 0
    assert main(["tip", str(out / "points.csv"), "--arm", "aacmm7", "--uncertainty", "-o", str(d / "tip.csv"),
                 "-q"]) == 0
    return result, out, d


def test_replay_finds_every_contact_at_its_capture(replay):
    result, out, _ = replay
    sim = result.points
    got = read_points(out / "points.csv", 7)
    assert len(got) == len(sim)
    sg = result.campaign.signals
    # each point lies in its own contact (its pulse), held at the capture's encoder readings
    assert np.all(got.time >= sim.time - sg["rise"]) and np.all(got.time <= sim.time + sg["decay"])
    assert np.array_equal(got.q, sim.q)
    # its force is the capture's reading within the sensor's noise (the peak may be a noisy neighbour)
    noise = result.truth["noise"]["force_noise"]
    assert np.max(np.abs(got.force - sim.force)) < 6 * noise
    assert list(got.feature) == list(sim.feature)


def test_replay_points_are_aacmm_tip_byte_for_byte(replay):
    _, out, d = replay
    assert (out / "tips.csv").read_bytes() == (d / "tip.csv").read_bytes()
    status = read_status(out)
    assert status["status"] == "complete" and status["closed"]
    assert status["reproduce"].startswith("aacmm tip points.csv --arm aacmm7 --uncertainty")


def test_replay_over_force_events_are_the_true_ones(replay):
    result, out, _ = replay
    limit = 13.0
    read = np.linalg.norm(result.points.force, axis=1)
    true = np.linalg.norm(result.true_wrench[:, :3], axis=1)
    # the seeds are such that no point is near the limit, where the sensor's noise decides
    assert np.all(np.abs(read - limit) > 0.3) and np.all(np.abs(true - limit) > 0.3)
    expected = set(np.flatnonzero(true > limit) + 1)
    assert expected, "the campaign must press beyond the probe's range at least once"
    contacts = rows(out / "contacts.csv")
    flagged = {int(c["contact"]) for c in contacts if c["over_force"] == "1"}
    assert flagged == expected
    events = [e for e in rows(out / "events.csv") if e["kind"] == "over_force"]
    assert len(events) == len(expected)
    for e, c in zip(events, sorted(expected), strict=True):         # each event during its contact, before its end
        row = contacts[c - 1]
        assert float(row["start_s"]) <= float(e["time_s"]) <= float(row["end_s"])


def test_replay_record_reads_back(replay):
    result, out, _ = replay
    pts = read_points(out / "points.csv", 7)
    art = read_artefacts(out / "artefacts.toml")
    check_features(pts, art)
    assert set(art.features) == set(result.artefacts.features)
    fits = rows(out / "features.csv")
    assert [int(r["point"]) for r in fits if r["kind"] != "distance"] == list(range(1, len(pts) + 1))
    ring = [r for r in fits if r["feature"] == "ring" and r["size_mm"]]
    assert ring and abs(float(ring[-1]["size_mm"]) - 50.0) < 0.2
    samples = (out / "samples.csv").read_text().splitlines()
    assert len(samples) - 1 == json.loads((out / "session.json").read_text())["counts"]["samples"]


def test_trigger_contacts_give_the_same_points(replay, tmp_path):
    result, _, d = replay
    out = tmp_path / "trigger"
    assert main(["live", str(d / "samples.csv"), "--arm", "aacmm7", "--contact", "trigger", "-o", str(out),
                 "--speed", "0", "-q"]) == 0
    got = read_points(out / "points.csv", 7)
    assert len(got) == len(result.points) and np.array_equal(got.q, result.points.q)


def test_peaks_are_the_ring_pipelines(replay):
    """The session's peak of each contact is the sample the ring pipeline's peak finder takes in the
    measurement's force signal (one peak finder: arm_model.peaks)."""
    from correction.signals import find_point_forces
    result, out, _ = replay
    peaks = np.array([float(c["peak_s"]) for c in rows(out / "contacts.csv")])
    expected = []
    for mid, sig in result.signals.items():
        n = int(np.sum(result.points.measurement == mid))
        expected += list(find_point_forces(sig, n, mid).time)
    assert np.allclose(peaks, expected, atol=1e-9, rtol=0)


# -- synthetic streams through the Python API ------------------------------------------------------

def pulses(peaks, *, noise=0.03, offset=(0.0, 0.0, 0.0), drift=0.0, period=0.6, width=0.2, rate=1000.0,
           seed=0, direction=(0.3, -0.2, 0.93)):
    """(t, force (S, 3)) of touches of the given peak magnitudes [N] along ``direction``, each a half
    sine ``width`` s long, one every ``period`` s, plus an offset drifting by ``drift`` N/s and white
    noise per channel."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round((len(peaks) + 1) * period * rate))) / rate
    mag = np.zeros_like(t)
    for i, p in enumerate(peaks):
        c = (i + 1) * period
        x = (t - (c - width / 2)) / width
        inside = (x >= 0) & (x <= 1)
        mag[inside] = p * np.sin(np.pi * x[inside])
    u = np.asarray(direction, float) / np.linalg.norm(direction)
    f = mag[:, None] * u + np.asarray(offset) + drift * t[:, None] + rng.normal(0, noise, (len(t), 3))
    return t, f


def run(t, f, **kw) -> tuple[Session, list]:
    s = Session("aacmm7", **kw)
    out = []
    for ti, fi in zip(t, f, strict=True):
        out += s.push(float(ti), Q0, fi)
    out += s.close()
    return s, out


def test_light_touches_over_noise_are_found():
    peaks = [0.15, 0.5, 0.2, 3.0, 0.15, 1.0, 8.0, 0.3]
    t, f = pulses(peaks, noise=0.03, seed=1)
    s, _ = run(t, f)
    assert s.counts["points"] == len(peaks) and s.counts["bumps"] == 0
    got = np.array([p.contact.peak_force for p in s.points])
    assert np.all(np.abs(got - peaks) < 0.15)
    assert s.counts["over_force"] == 0


def test_a_drifting_offset_is_followed():
    peaks = [0.5] * 10
    t, f = pulses(peaks, noise=0.02, offset=(0.25, -0.3, 0.2), drift=0.01, seed=2)
    s, _ = run(t, f)
    assert s.counts["points"] == len(peaks)


def test_noise_alone_gives_nothing():
    rng = np.random.default_rng(3)
    t = np.arange(30000) / 1000.0
    for sigma in (0.03, 0.1):
        f = rng.normal(0, sigma, (len(t), 3)) + [0.1, 0.05, -0.08]
        s, _ = run(t, f)
        assert s.counts["points"] == 0 and s.counts["bumps"] == 0, sigma
    # the thresholds rose to the noisier sensor
    assert s.thresholds()["on"] > ContactOptions().on


def test_a_spike_is_an_over_force_but_not_a_point():
    t, f = pulses([1.0, 1.0], seed=4)
    f[100] = [0.0, 0.0, 50.0]
    s, out = run(t, f)
    assert s.counts["points"] == 2 and s.counts["bumps"] == 1 and s.counts["over_force"] == 1
    ev = [o for o in out if getattr(o, "kind", None) == "over_force"]
    assert len(ev) == 1 and ev[0].time == pytest.approx(0.1)


def test_over_force_is_one_event_a_contact_and_matches_the_point():
    t, f = pulses([14.0, 2.0, 13.5, 12.0], noise=0.03, seed=5)
    s, _ = run(t, f)
    assert [p.over_force for p in s.points] == [True, False, True, False]
    assert s.counts["over_force"] == 2


def test_dropped_and_late_samples_are_counted():
    t, f = pulses([1.0, 1.0, 1.0], seed=6)
    keep = np.ones(len(t), bool)
    keep[500:505] = False              # 5 samples lost
    keep[1500:1503] = False            # 3 more
    idx = list(np.flatnonzero(keep))
    idx[1000], idx[1001] = idx[1001], idx[1000]      # one out of order
    s, out = run(t[idx], f[idx])
    # the sample that came late was missing when it was due: a gap of one, and late (skipped)
    assert s.counts["dropped"] == 9 and s.counts["late"] == 1
    assert sorted(e.count for e in out if getattr(e, "kind", None) == "dropped") == [1, 3, 5]
    assert s.counts["points"] == 3


def test_the_period_is_learnt_before_gaps_are_judged():
    t, f = pulses([1.0], seed=7)
    idx = [0, 1, 2, 3, 10] + list(range(11, len(t)))            # 6 samples lost among the first intervals
    s, _ = run(t[idx], f[idx])
    assert s.counts["dropped"] == 6


def test_joint_limit_events(nominal):
    lo = nominal.joints[1].lower
    s = Session(nominal)
    out = []
    for k, q2 in enumerate([lo + 0.1, lo - 0.01, lo - 0.02, lo + 0.1, lo - 0.01]):
        q = Q0.copy()
        q[1] = q2
        out += s.push(k * 0.001, q, [0.0, 0.0, 0.0])
    assert s.counts["joint_limit"] == 2
    assert all(e.kind == "joint_limit" and "j2" in e.message for e in out)


def test_python_session_record_is_tip_byte_for_byte(tmp_path):
    t, f = pulses([0.5, 2.0, 14.0, 1.0], seed=8)
    s, _ = run(t, f, folder=tmp_path / "s")
    assert s.counts["points"] == 4
    assert main(["tip", str(tmp_path / "s" / "points.csv"), "--arm", "aacmm7", "--uncertainty", "-o",
                 str(tmp_path / "tip.csv"), "-q"]) == 0
    assert (tmp_path / "s" / "tips.csv").read_bytes() == (tmp_path / "tip.csv").read_bytes()
    # the record replays to the same session
    assert main(["live", str(tmp_path / "s" / "samples.csv"), "--arm", "aacmm7", "-o", str(tmp_path / "r"),
                 "--speed", "0", "--measurement", "s", "-q"]) == 0
    assert (tmp_path / "r" / "tips.csv").read_bytes() == (tmp_path / "s" / "tips.csv").read_bytes()


def test_the_reproduce_line_keeps_a_given_model_discrepancy(tmp_path, monkeypatch):
    """``aacmm live --u-model-discrepancy-um 7``: session.json's reproduce command (run in the session folder)
    writes the session's tips.csv byte for byte, and the 7 um per axis are in it (u above the session without)."""
    t, f = pulses([2.0, 5.0], seed=5)
    s, _ = run(t, f, folder=tmp_path / "s")
    u0 = np.array([p.u for p in s.points])
    out = tmp_path / "r"
    assert main(["live", str(tmp_path / "s" / "samples.csv"), "--arm", "aacmm7", "-o", str(out), "--speed", "0",
                 "--u-model-discrepancy-um", "7", "-q"]) == 0
    cmd = read_status(out)["reproduce"].split()
    assert cmd[:2] == ["aacmm", "tip"] and "--u-model-discrepancy-um" in cmd
    monkeypatch.chdir(out)
    assert main(cmd[1:] + ["-q"]) == 0
    assert (out / "tips.csv").read_bytes() == (out / "tips-again.csv").read_bytes()
    u = np.array([[float(r[f"u_{a}_mm"]) * 1e-3 for a in "xyz"] for r in rows(out / "tips.csv")])
    np.testing.assert_allclose(u ** 2 - u0 ** 2, (7e-6) ** 2, rtol=0, atol=2 * 10e-6 * 0.5e-9)   # u written to 1 nm


def test_torque_temperature_and_a_model_file(tmp_path, nominal):
    """Every effect of a model file applies (a thermal effect reads the temperature column, a joint
    compliance the contact torques); the points equal aacmm tip's."""
    from arm_model.effects import JointCompliance, ThermalGrowth
    from arm_model.model_file import format_model
    effects = (ThermalGrowth(), JointCompliance(joints=(1, 3)))
    model = tmp_path / "arm-model.toml"
    model.write_text(format_model(nominal, effects, {"links.thermal_alpha": 2.3e-5, "j2.compliance": 4e-6,
                                                     "j4.compliance": 2e-6}))
    t, f = pulses([2.0, 5.0], seed=9)
    s = Session(model, tmp_path / "s")
    for k, (ti, fi) in enumerate(zip(t, f, strict=True)):
        s.push(float(ti), Q0, np.r_[fi, 0.01, -0.02, 0.005], temperature=22.5 + 1e-4 * k)
    s.close()
    assert s.counts["points"] == 2
    assert main(["tip", str(tmp_path / "s" / "points.csv"), "--arm", str(model), "--uncertainty", "-o",
                 str(tmp_path / "tip.csv"), "-q"]) == 0
    assert (tmp_path / "s" / "tips.csv").read_bytes() == (tmp_path / "tip.csv").read_bytes()
    rigid = Session(nominal)
    for ti, fi in zip(t, f, strict=True):
        rigid.push(float(ti), Q0, np.r_[fi, 0.01, -0.02, 0.005], temperature=22.5)
    rigid.close()
    assert np.linalg.norm(s.points[0].corrected - rigid.points[0].corrected) > 1e-7   # the effects moved it


def _sphere_cap(rng, centre, radius, n):
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.3
    return centre + radius * d / np.linalg.norm(d, axis=1)[:, None]


def _tracker(kind_rows):
    from arm_model.io import Distance, Feature
    from arm_model.live import FeatureTracker, PlanFeature, SessionPlan
    entries = tuple(PlanFeature(Feature(fid, kind, d, 1e-6 if d else None, None, {}), n)
                    for fid, kind, d, n in kind_rows)
    dist = (Distance(("A", "B"), 0.05, 5e-7),) if any(r[0] == "B" for r in kind_rows) else ()
    return FeatureTracker(SessionPlan(entries, dist), ball_diameter=0.004)


def test_fits_against_exact_geometry_and_a_monte_carlo():
    """Exact ball centres give the certified sizes; the reported u of a size matches the spread of refits
    of noisy points (an independent Monte Carlo), and an error all points share does not change a
    distance."""
    from arm_model.geometry import fit_sphere
    rng = np.random.default_rng(10)
    sigma = 2e-6
    cov = np.eye(3) * sigma ** 2
    c0 = np.array([0.6, 0.1, 0.2])
    sphere = _sphere_cap(rng, c0, (0.0254 + 0.004) / 2, 12)
    ang = np.linspace(0, 2 * np.pi, 9)[:-1] + rng.uniform(-0.05, 0.05, 8)
    ring = c0 + np.column_stack([(0.05 - 0.004) / 2 * np.cos(ang), (0.05 - 0.004) / 2 * np.sin(ang), np.zeros(8)])
    seats = [c0 + [0.0, -0.025, 0.0], c0 + [0.0, 0.025, 0.0]]
    tr = _tracker([("S", "sphere", 0.0254, 12), ("R", "ring", 0.05, 8), ("P", "plane", None, 4),
                   ("A", "seat", None, 3), ("B", "seat", None, 3)])
    shared = np.array([[1e-6, -2e-6, 3e-6]])        # one error every point shares (R = 1)
    cov = cov + shared.T @ shared                     # a point's whole covariance holds it
    for p in sphere:
        fit = tr.add("S", p, cov, shared)[0]
    assert fit.size == pytest.approx(0.0254, abs=1e-12) and fit.agrees
    sizes = [2 * fit_sphere(sphere + rng.normal(0, sigma, sphere.shape)).radius - 0.004 for _ in range(400)]
    assert fit.u_size == pytest.approx(np.std(sizes), rel=0.15)
    for p in ring:
        fit = tr.add("R", p, cov, shared)[0]
    assert fit.size == pytest.approx(0.05, abs=1e-12) and fit.form == pytest.approx(0.0, abs=1e-12)
    for p in c0 + rng.uniform(-0.05, 0.05, (4, 3)) * [1, 1, 0]:
        fit = tr.add("P", p, cov, shared)[0]
    assert fit.form == pytest.approx(0.0, abs=1e-12) and fit.u_form > 0
    for seat, fid in zip(seats, "AB", strict=True):
        for _ in range(3):
            fits = tr.add(fid, seat, cov, shared)
    dist = fits[-1]
    assert dist.kind == "distance" and dist.size == pytest.approx(0.05, abs=1e-12)
    # the shared error moves both seats alike: only each seat's own scatter, sigma sqrt(2/3) along the bar
    assert dist.u_size == pytest.approx(sigma * math.sqrt(2 / 3), rel=1e-6)
    assert tr.current == ""


def test_ad_hoc_features_from_python(tmp_path):
    t, f = pulses([1.0] * 5, seed=12)
    s = Session("aacmm7", tmp_path / "s")
    s.begin_feature("ball", "sphere", diameter=0.0254, points=2)
    for ti, fi in zip(t, f, strict=True):
        s.push(float(ti), Q0, fi)
    s.close()
    pts = read_points(tmp_path / "s" / "points.csv", 7)
    assert list(pts.feature) == ["ball", "ball", "", "", ""]
    assert "ball" in s.fits and "need" in s.fits["ball"].note
    with pytest.raises(ValueError, match="already"):
        s.begin_feature("ball", "seat")


def test_the_bundled_example_is_its_generator_output(tmp_path):
    """examples/live/samples.csv and plan.toml are what `aacmm simulate examples/live/campaign.toml
    --samples` writes (the bundled session is reproducible). The plan byte for byte; the samples' times and
    triggers exactly, their readings to within 3 encoder steps (3e-4 deg) and 1e-5 N: the simulator's inverse
    kinematics stops at 1e-9 and where a 7-joint arm's redundancy settles follows the linear algebra library's
    rounding, so across numpy/LAPACK versions a reading can round to the next step (numpy 2.4.6 against the file's
    build: at most 2 steps, 6e-6 N)."""
    assert main(["simulate", str(CAMPAIGN), "--samples", "-o", str(tmp_path / "sim"), "-q"]) == 0
    made, shipped = tmp_path / "sim", ROOT / "examples" / "live"
    assert (made / "plan.toml").read_bytes() == (shipped / "plan.toml").read_bytes()
    lines = [(d / "samples.csv").read_text().splitlines() for d in (made, shipped)]
    assert lines[0][0] == lines[1][0] and len(lines[0]) == len(lines[1])
    cols = lines[0][0].split(",")
    a, b = (np.array([[float(v) for v in row.split(",")] for row in rows[1:]]) for rows in lines)
    exact = [i for i, c in enumerate(cols) if c in ("time_s", "trigger")]
    deg = [i for i, c in enumerate(cols) if c.endswith("_deg")]
    force = [i for i, c in enumerate(cols) if c.endswith("_N")]
    assert len(exact) == 2 and len(deg) == 7 and len(force) == 3 and len(cols) == 12
    np.testing.assert_array_equal(a[:, exact], b[:, exact])
    np.testing.assert_allclose(a[:, deg], b[:, deg], rtol=0, atol=3e-4 + 1e-9)
    np.testing.assert_allclose(a[:, force], b[:, force], rtol=0, atol=1e-5)


@given(st.lists(st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=64), st.integers(-10**6, 10**6),
                          st.text(max_size=8)), min_size=1, max_size=6),
       st.sampled_from(["%.6f", "%.17g", "%.3f"]))
def test_format_row_is_format_csv_of_one_row(values, fmt):
    """The row a session appends is the row format_csv (aacmm tip's writer) makes of the same values."""
    from arm_model.csv_io import format_csv, format_row
    cols = {f"c{k}": np.array([v]) if not isinstance(v, str) else np.array([v], dtype=object)
            for k, v in enumerate(values)}
    row = {k: v[0] for k, v in cols.items()}
    assert format_row(row, fmt).encode() == format_csv(cols, fmt, header=False)


def test_a_growing_model_discrepancy_is_added_as_tip_adds_it(tmp_path, nominal):
    """A model file whose discrepancy grows away from its one training pose (Q0; sigma0 5 um, 20 um per mm): the
    Python session (no inputs given) and ``aacmm live`` add it to every point as ``aacmm tip`` does (the
    session's tips.csv is tip's byte for byte: u to 1 nm), and by hand: a point whose joint 1 is turned by dq from
    Q0 lies d = r dq from it (r the ball's distance from joint 1's vertical axis), so its variance per axis exceeds
    that of the same point on the plain description by sigma0^2 + (g d)^2 (1e-9 relative)."""
    from arm_model.kinematics import ball_centres
    from conftest import NOMINAL
    cols = ",".join(f"q{k + 1}_rad" for k in range(7))
    (tmp_path / "poses.csv").write_text(f"measurement,feature,{cols}\nm,seat,{','.join(map(repr, Q0.tolist()))}\n")
    model = tmp_path / "m.toml"
    model.write_text(NOMINAL.read_text() + "\n[calibration]\nmodel_discrepancy_um = 5.0\n"
                     "model_discrepancy_growth_um_per_mm = 20.0\ntraining_poses = \"poses.csv\"\n")
    t, f = pulses([2.0, 5.0, 1.0, 8.0], seed=4, period=0.6)
    grown, plain = Session(model, tmp_path / "s"), Session(nominal)
    for ti, fi in zip(t, f, strict=True):
        q = Q0.copy()
        q[0] += 0.002 * math.floor(ti / 0.6)            # pulse k (centred at (k + 1) 0.6 s) at dq = 0.002 (k + 1)
        for s in (grown, plain):
            s.push(float(ti), q, fi)
    for s in (grown, plain):
        s.close()
    assert grown.counts["points"] == plain.counts["points"] == 4
    for k, (a, b) in enumerate(zip(grown.points, plain.points, strict=True)):
        qa = np.array(a.contact.peak.q)
        assert qa[0] - Q0[0] == pytest.approx(0.002 * (k + 1), abs=1e-12)
        d = np.hypot(*ball_centres(nominal, qa)[:2]) * (qa[0] - Q0[0])
        np.testing.assert_allclose(np.diag(a.cov) - np.diag(b.cov), (5e-6) ** 2 + (0.02 * d) ** 2, rtol=1e-9)
    assert main(["tip", str(tmp_path / "s" / "points.csv"), "--arm", str(model), "--uncertainty", "-o",
                 str(tmp_path / "tip.csv"), "-q"]) == 0
    assert (tmp_path / "s" / "tips.csv").read_bytes() == (tmp_path / "tip.csv").read_bytes()
    assert main(["live", str(tmp_path / "s" / "samples.csv"), "--arm", str(model), "-o", str(tmp_path / "r"),
                 "--speed", "0", "--measurement", "s", "-q"]) == 0
    assert (tmp_path / "r" / "tips.csv").read_bytes() == (tmp_path / "s" / "tips.csv").read_bytes()
