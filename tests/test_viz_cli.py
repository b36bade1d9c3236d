"""``aacmm view``: pages, artefacts, residuals, serving and stopping, and the errors (bad file, busy
port, missing browser): one clear message, exit code 2, nothing written, no server left."""
from __future__ import annotations

import signal
import socket
import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import least_squares
from test_viz_server import bridge_children, no_server_left, page_commands, transforms, wait_gone  # noqa: F401

from arm_model import ball_centres
from arm_model.cli import main
from conftest import NOMINAL, ROOT

HEADER = "measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + ",fx_N,fy_N,fz_N"
Q0 = np.radians([0, 30, 0, 60, 0, 45, 0])


def reach(desc, target, q0=Q0) -> np.ndarray:
    """Angles [rad] that put the rigid ball centre at ``target`` [m] (least squares from ``q0``)."""
    sol = least_squares(lambda q: ball_centres(desc, q[None])[0] - target, q0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.linalg.norm(sol.fun) < 1e-9
    return sol.x


def write_points(path, rows) -> None:
    lines = [HEADER] + [",".join([m, f, *(f"{v:.10f}" for v in np.degrees(q)), *(f"{v:g}" for v in w)])
                        for m, f, q, w in rows]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory, nominal):
    """A ring measured in one row and a sphere pair on a bar, reached by IK, with a residuals file."""
    d = tmp_path_factory.mktemp("view")
    rows = []
    centre, r = np.array([-0.55, 0.05, 0.35]), (0.174996 - 0.004) / 2
    for k in range(8):
        a = 2 * np.pi * k / 8
        target = centre + r * np.array([np.cos(a), np.sin(a), 0])
        rows.append(("ring-01", "ring", reach(nominal, target), 6.0 * np.array([-np.cos(a), -np.sin(a), 0.3])))
    dirs = np.array([[0, 0, 1], [1, 0, 1], [-1, 0, 1], [0, 1, 1], [0, -1, 1.0]])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    for fid, c in (("sphere-A", [-0.45, -0.3, 0.2]), ("sphere-B", [-0.45, 0.3, 0.2])):
        for u in dirs:
            rows.append(("bar-01", fid, reach(nominal, np.array(c) + 0.0145 * u), 4.0 * u))
    rows.append(("bar-01", "seat", Q0, np.zeros(3)))
    write_points(d / "points.csv", rows)
    (d / "artefacts.toml").write_text(
        '[[feature]]\nid = "ring"\nkind = "ring"\ndiameter_mm = 174.996\n'
        '[[feature]]\nid = "sphere-A"\nkind = "sphere"\ndiameter_mm = 25.0\n'
        '[[feature]]\nid = "sphere-B"\nkind = "sphere"\ndiameter_mm = 25.0\n'
        '[[feature]]\nid = "seat"\nkind = "seat"\n'
        '[[distance]]\nbetween = ["sphere-A", "sphere-B"]\nlength_mm = 600.0\n')
    (d / "residuals.csv").write_text("measurement,feature,x_mm,y_mm,z_mm,rx_um,ry_um,rz_um\n"
                                     "ring-01,ring,-462.5,50,350,1.5,0,0\nring-01,ring,-550,137.5,350,0,-2.0,0.5\n")
    return d


def run_view(*args) -> int:
    return main(["view", *map(str, args)])


def test_page_of_a_point(campaign, nominal, capsys, tmp_path):
    out = tmp_path / "pose.html"
    assert run_view(campaign / "points.csv", "--arm", NOMINAL, "--measurement", "ring-01", "--point", 3,
                    "--html", out) == 0
    text = capsys.readouterr().out
    q, w = reach(nominal, np.array([-0.55, 0.05 + (0.174996 - 0.004) / 2, 0.35])), 6.0 * np.array([0, -1, 0.3])
    d_um = np.linalg.norm(ball_centres(nominal, q[None], w[None]) - ball_centres(nominal, q[None])) * 1e6
    assert "8 point(s)" in text and "measurement 'ring-01'" in text and "line 4" in text
    # default scale from the data: 85.2 um wants x704 for a 60 mm arrow; the nearest 1-2-5 number is 500
    assert f"deflection {d_um:.2f} um, drawn {d_um * 0.5:.1f} mm long" in text
    assert "drawn x500" in text and "serving" not in text           # --html alone does not serve
    page = out.read_text()
    assert "drawn x500" in page and "<title>aacmm7: AACMM viewer</title>" in page
    ball = transforms(page_commands(page))["/meshcat/aacmm/arm/visuals/ball_0"][:3, 3]
    assert np.linalg.norm(ball - ball_centres(nominal, q[None], w[None])[0]) < 1e-8   # 1e-10 deg rounding


def test_artefacts_and_residuals(campaign, capsys, tmp_path):
    out = tmp_path / "all.html"
    assert run_view(campaign / "points.csv", "--arm", NOMINAL, "--artefacts", campaign / "artefacts.toml",
                    "--residuals", campaign / "residuals.csv", "--residual-scale", 5000, "--animate",
                    "--html", out) == 0
    text = capsys.readouterr().out
    assert "blue: 4 artefact feature(s)" in text          # ring, two spheres, the seat
    assert "2 residual vector(s), drawn x5000" in text and "animated through 19 points" in text
    cmds = page_commands(out.read_text())
    tf = transforms(cmds)
    ring = tf["/meshcat/aacmm/artefacts/ring-01/ring"]
    assert np.linalg.norm(ring[:3, 3] - [-0.55, 0.05, 0.35]) < 1e-3        # deflected centres: ~0.1 mm off
    assert abs(ring[2, 1]) > 0.999                                         # axis vertical
    bar = tf["/meshcat/aacmm/artefacts/bar-01/sphere-A--sphere-B"]
    assert np.linalg.norm(bar[:3, 3] - [-0.45, 0.0, 0.2]) < 1e-3
    assert any(c["type"] == "set_animation" for c in cmds)


def test_too_few_points_are_reported_not_dropped(campaign, capsys, tmp_path):
    assert run_view(campaign / "points.csv", "--arm", NOMINAL, "--artefacts", campaign / "artefacts.toml",
                    "--html", tmp_path / "x.html", "--measurement", "bar-01") == 0
    assert "blue: 3 artefact feature(s)" in capsys.readouterr().out


def test_serves_until_sigterm_and_leaves_no_server(campaign):
    proc = subprocess.Popen([sys.executable, "-m", "arm_model.cli", "view", str(campaign / "points.csv"),
                             "--arm", str(NOMINAL), "--open-seconds", "60"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        while not any(line.startswith("serving") for line in lines):
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            lines.append(line)
        url = next(line.split(": ", 1)[1].strip() for line in lines if line.startswith("meshcat server:"))
        port = int(url.rsplit(":", 1)[1].split("/")[0])
        with socket.create_connection(("127.0.0.1", port), timeout=5):
            pass
        bridge = bridge_children(proc.pid)
        assert len(bridge) == 1
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
        assert wait_gone(bridge[0])
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# --- errors: one message, exit 2, nothing written ---------------------------------------------------

def _no_output(tmp_path):
    return sorted(p.name for p in tmp_path.iterdir()) == []


def _cell(text: str, line: int, column: int, value: str) -> str:
    lines = text.splitlines()
    cells = lines[line - 1].split(",")
    cells[column] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("edit, expect", [
    (lambda t: _cell(t, 5, 2, "oops"), "line 5, column 'q1_deg': expected a number, got 'oops'"),
    (lambda t: _cell(t, 7, 11, "nan"), "line 7, column 'fz_N'"),
    (lambda t: t.replace("q7_deg", "q8_deg"), "missing q7"),
    (lambda t: "", "the file is empty"),
])
def test_bad_points_file(campaign, tmp_path, capsys, edit, expect):
    bad = tmp_path / "in" / "bad.csv"
    bad.parent.mkdir()
    bad.write_text(edit((campaign / "points.csv").read_text()))
    out = tmp_path / "out"
    out.mkdir()
    assert run_view(bad, "--arm", NOMINAL, "--html", out / "x.html", "--screenshot", out / "x.png") == 2
    err = capsys.readouterr().err
    assert err.startswith(f"aacmm view: error: {bad}") and expect in err, err
    assert _no_output(out)


def test_unknown_residuals_column_is_an_error(campaign, tmp_path, capsys):
    """An unknown column of the residuals file: exit 2, file, line 1 and the column named, nothing written."""
    bad = tmp_path / "in" / "residuals.csv"
    bad.parent.mkdir()
    text = (campaign / "residuals.csv").read_text().splitlines()
    bad.write_text("\n".join([text[0] + ",note"] + [r + ",x" for r in text[1:]]) + "\n")
    out = tmp_path / "out"
    out.mkdir()
    assert run_view(campaign / "points.csv", "--arm", NOMINAL, "--residuals", bad, "--html", out / "x.html") == 2
    err = capsys.readouterr().err
    assert f"{bad}, line 1, column 'note': unknown column 'note'" in err, err
    assert _no_output(out)


@pytest.mark.parametrize("extra, expect", [
    (["--measurement", "nope"], "column 'measurement': no measurement 'nope' (the file has: ring-01, bar-01)"),
    (["--point", "20"], "--point 20: the selection has 19 point(s)"),
    (["--screenshot", "{out}/x.png", "--browser", "/nonexistent/chromium"], "no browser at '/nonexistent/chromium'"),
    (["--html", "{points}"], "refusing to write the output over an input file"),
])
def test_bad_options(campaign, tmp_path, capsys, extra, expect):
    extra = [e.format(out=tmp_path, points=campaign / "points.csv") for e in extra]
    args = [campaign / "points.csv", "--arm", NOMINAL, *extra]
    if "--html" not in extra:
        args += ["--html", tmp_path / "x.html"]
    before = (campaign / "points.csv").read_bytes()
    assert run_view(*args) == 2
    assert expect in capsys.readouterr().err
    assert _no_output(tmp_path) and (campaign / "points.csv").read_bytes() == before


def test_busy_port(campaign, tmp_path, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert run_view(campaign / "points.csv", "--arm", NOMINAL, "--port", port, "--html", tmp_path / "x.html") == 2
    assert f"port {port} on 127.0.0.1 is in use: choose another with --port" in capsys.readouterr().err
    assert _no_output(tmp_path)


def test_help_is_useful(capsys):
    with pytest.raises(SystemExit):
        main(["view", "--help"])
    text = capsys.readouterr().out
    for word in ("--html", "--animate", "--scale", "--artefacts", "--residuals", "--port", "--open-seconds",
                 "headless", "127.0.0.1"):
        assert word in text


#: the calibration campaign of examples/ at about a third of its size (every kind of task kept: ball bar, seat,
#: sphere, plane, tracker nests); the whole campaign is simulated and calibrated by test_calibration_sim (slow)
SMALLER = {"positions = 24": "positions = 8", "articulations = 30": "articulations = 10", "points = 25": "points = 12",
           "points = 30": "points = 12", "nests = 25": "nests = 8"}


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """The calibration campaign of examples/ made smaller (:data:`SMALLER`), simulated (points, reference points,
    artefacts, truth)."""
    sim = tmp_path_factory.mktemp("sim")
    text = (ROOT / "examples" / "campaigns" / "calibration.toml").read_text()
    for old, new in SMALLER.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    campaign = tmp_path_factory.mktemp("campaign") / "calibration-smaller.toml"
    campaign.write_text(text)
    assert main(["simulate", str(campaign), "-o", str(sim), "--no-signals", "-q"]) == 0
    return sim


def test_a_simulated_campaign_is_drawn_where_the_truth_is(simulated, tmp_path, capsys, nominal):
    """End to end with the simulator: each ball-bar sphere is drawn at its true centre moved by the
    nominal arm's errors at that sphere's points (the simulated true arm differs from the nominal one by
    up to ~0.4 mm), as a fit at the known radius propagates them to first order: within 20 um."""
    import csv
    import tomllib

    from arm_model import read_points

    sim = simulated
    capsys.readouterr()
    out = tmp_path / "view.html"
    assert run_view(sim / "points.csv", "--arm", NOMINAL, "--artefacts", sim / "artefacts.toml", "--html", out) == 0
    assert "note:" not in capsys.readouterr().out          # every feature could be placed
    tf = transforms(page_commands(out.read_text()))
    pts = read_points(sim / "points.csv", 7)
    rows = [r for r in csv.DictReader((sim / "truth-points.csv").read_text().splitlines()[1:])
            if r["file"] == "points.csv"]
    true_centres = np.array([[float(r[f"{a}_true_mm"]) for a in "xyz"] for r in rows]) * 1e-3
    model_error = ball_centres(nominal, pts.q, pts.wrench) - true_centres
    positions = tomllib.loads((sim / "truth.toml").read_text())["artefact"]["bar"]["positions"]
    assert len(positions) == 8
    worst = 0.0
    for pos in positions:
        for end in "AB":
            drawn = tf[f"/meshcat/aacmm/artefacts/{pos['measurement']}/bar-{end}"][:3, 3]
            group = (pts.measurement == pos["measurement"]) & (pts.feature == f"bar-{end}")
            normals = true_centres[group] - pos[f"{end}_m"]
            normals /= np.linalg.norm(normals, axis=1)[:, None]
            shift = np.linalg.lstsq(normals, np.sum(normals * model_error[group], axis=1), rcond=None)[0]
            assert np.linalg.norm(drawn - (pos[f"{end}_m"] + shift)) < 20e-6, (pos["measurement"], end)
            worst = max(worst, float(np.linalg.norm(drawn - pos[f"{end}_m"])))
    assert 50e-6 < worst < 2e-3     # the test is not vacuous: the nominal arm is measurably off


def test_residuals_of_aacmm_calibrate(simulated, tmp_path, capsys):
    """The residuals.csv that aacmm calibrate writes is drawn as it is: each vector from the ball centre
    of its points-file line (with the calibrated arm), the tracker rows of the other file counted. The seat
    first in the points file: its lines are those of the tracker's seats (nests) in points-ref.csv, a point is
    its file and line (named by line and kind alone, residuals.csv was refused by its reader: exit 3)."""
    import csv

    from arm_model import load_description, read_points

    lines = (simulated / "points.csv").read_text().splitlines(keepends=True)
    seat = [r for r in lines[1:] if r.startswith("seat-")]
    points = tmp_path / "points.csv"
    points.write_text("".join([lines[0], *seat, *(r for r in lines[1:] if r not in seat)]))
    cal = tmp_path / "cal"
    assert main(["calibrate", str(points), str(simulated / "artefacts.toml"), "--arm",
                 str(NOMINAL), "--reference-points", str(simulated / "points-ref.csv"), "--no-plots",
                 "-o", str(cal)]) == 0
    arm = next(cal.glob("*-calibrated.toml"))
    capsys.readouterr()
    out = tmp_path / "view.html"
    assert run_view(points, "--arm", arm, "--residuals", cal / "residuals.csv",
                    "--residual-scale", 2000, "--ellipsoids", "--ellipsoid-scale", 3000, "--html", out) == 0
    text = capsys.readouterr().out
    desc = load_description(arm)
    pts = read_points(points, desc.n_joints)
    rows = list(csv.DictReader((cal / "residuals.csv").read_text().splitlines()))
    here = [r for r in rows if r["file"] == str(points)]
    assert {r["file"] for r in rows} == {str(points), str(simulated / "points-ref.csv")}
    assert here == [r for r in rows if r["measurement"] in set(pts.measurement)]   # not the tracker file's nests
    shared = {(r["line"], r["kind"]) for r in here} & {(r["line"], r["kind"]) for r in rows if r not in here}
    assert shared and 0 < len(here) < len(rows)     # seats of both files on the same lines
    assert f"magenta lines: {len(here)} residual vector(s), drawn x2000" in text
    assert f"note: {len(rows) - len(here)} residual(s)" in text
    cmds = page_commands(out.read_text())
    seg = next(c for c in cmds if c["path"] == "/meshcat/aacmm/residuals x2000/vectors")
    xyz = np.frombuffer(seg["object"]["geometries"][0]["data"]["attributes"]["position"]["array"].data,
                        dtype=np.float32).reshape(-1, 2, 3)
    i = np.searchsorted(pts.lines, [int(r["line"]) for r in here])
    start = ball_centres(desc, pts.q[i], pts.wrench[i])
    vec = np.array([[float(r[f"d{a}_um"]) for a in "xyz"] for r in here]) * 1e-6
    assert np.allclose(xyz[:, 0], start, atol=1e-6) and np.allclose(xyz[:, 1], start + 2000 * vec, atol=1e-6)
    # the 95 % ellipsoids of the calibrated model (its covariance file, its probing scatter): every vertex
    # of point i at Mahalanobis distance 3000 k from its corrected centre, with the covariance that
    # aacmm tip --covariance writes for the same points (k^2 = 7.8147, chi-square table, 3 dof, 95 %)
    n = len(pts)
    assert f"yellow: {n} 95 % uncertainty ellipsoid(s) of the corrected ball centres (k = 2.795" in text
    assert "drawn x3000" in text and "aacmm7-calibrated-covariance.csv" in text
    ell = next(c for c in cmds if c["type"] == "set_object"
               and c["path"] == "/meshcat/aacmm/uncertainty ellipsoids 95% x3000")
    geo = ell["object"]["geometries"][0]["data"]
    v = np.frombuffer(geo["attributes"]["position"]["array"].data, dtype=np.float32).reshape(n, -1, 3)
    tips = tmp_path / "tips.csv"
    assert main(["tip", str(points), "--arm", str(arm), "--covariance", "-o", str(tips)]) == 0
    t = np.genfromtxt(tips, delimiter=",", names=True, dtype=None, encoding="utf-8")
    cov = np.empty((n, 3, 3))
    for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        cov[:, a, b] = cov[:, b, a] = t[f"cov_{'xyz'[a]}{'xyz'[b]}_um2"] * 1e-12
    centre = np.column_stack([t["x_mm"], t["y_mm"], t["z_mm"]]) * 1e-3
    d = v - centre[:, None, :]
    m2 = np.einsum("nvi,nvi->nv", d, np.linalg.solve(cov, d.transpose(0, 2, 1)).transpose(0, 2, 1))
    assert np.allclose(np.sqrt(m2) / 3000, np.sqrt(7.8147), rtol=2e-3)


def test_default_arrow_scale_draws_the_deflection_outside_the_marker():
    """By hand: 10 um wants x6000 for a 60 mm arrow -> 5000 (50 mm); 100 um -> 500; 142 um -> 500
    (71 mm); nothing deflected -> 1000. The drawn median arrow is always longer than the 12 mm marker radius."""
    from viz.cli import arrow_scale
    assert arrow_scale([10.0]) == 5000.0
    assert arrow_scale([100.0, 0.0, 100.0]) == 500.0
    assert arrow_scale([142.0]) == 500.0
    assert arrow_scale([0.0, 0.0]) == 1000.0
    for d in (0.3, 2.0, 7.7, 33.0, 250.0, 1900.0):
        assert 0.03 < arrow_scale([d]) * d * 1e-6 < 0.12
