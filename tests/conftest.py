"""Shared test helpers: paths, the nominal arm, one array comparison that also rejects NaN, the field's robot
set (example-robot-data's URDFs, fetched once into a cache outside the repository)."""
from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
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
#: the field's robot set (tests/test_robot_set.py): the version of the example-robot-data wheel, where its URDFs lie
ROBOT_SET_VERSION = "4.1.0"
_ROBOT_SET_PREFIX = "cmeel.prefix/share/example-robot-data/robots/"
NOMINAL = ROOT / "urdf" / "aacmm7.dh.toml"


def assert_close(actual, expected, atol: float, rtol: float = 0.0, msg: str = "") -> None:
    """np.testing.assert_allclose that also fails on NaN/inf in either side."""
    a, e = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert np.all(np.isfinite(a)), f"non-finite values in actual {msg}"
    assert np.all(np.isfinite(e)), f"non-finite values in expected {msg}"
    np.testing.assert_allclose(a, e, atol=atol, rtol=rtol, err_msg=msg)


def assert_evaluators_agree(model, q, w, p, aux, atol: float = 1e-12) -> None:
    """The model's ball centres by the numpy batch path, its CasADi function and Pinocchio agree to ``atol`` [m]
    at every row of ``q``, ``w`` with the per-point ``aux`` (temperature, torques, time, motion, capture)."""
    from arm_model.model import ArmModel
    batch = model.ball_centres(q, w, p, aux)
    f = model.casadi_function()
    a = ArmModel.aux_matrix(aux, len(q), q.shape[1], len(model.capture_measurements))
    for i in range(len(q)):
        assert_close(np.array(f(q[i], w[i], a[i], p)).ravel(), batch[i], atol=atol)
        row = {k: None if v is None else v[i] for k, v in (("temperature", aux.temperature), ("tau_gravity",
               aux.tau_gravity), ("tau_contact", aux.tau_contact), ("time", aux.time), ("motion", aux.motion),
               ("capture", aux.capture))}
        assert_close(model.pinocchio_ball_centre(q[i], w[i], p, row), batch[i], atol=atol)

def exit_status(argv) -> int:
    """The exit status of ``aacmm argv`` (argparse's refusals raise SystemExit, the commands' return it)."""
    from arm_model.cli import main
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def wait_udp_bound(port: int, timeout: float = 60.0) -> None:
    """Until a UDP socket listens on ``port`` (Linux's /proc/net/udp; elsewhere 1 s): a datagram sent before
    the session binds is lost, however loaded the machine. (Probing by binding the port oneself would race the
    session's own bind.)"""
    import time
    tables = [p for p in ("/proc/net/udp", "/proc/net/udp6") if os.path.exists(p)]
    if not tables:
        time.sleep(1.0)
        return
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for table in tables:
            with open(table) as fh:
                if any(int(row.split()[1].rsplit(":", 1)[1], 16) == port for row in list(fh)[1:]):
                    return
        time.sleep(0.02)


def pin_configuration(model, values) -> np.ndarray:
    """Pinocchio's configuration vector of ``model`` with the named joints at ``values`` ((name, angle or
    length) pairs; a continuous joint as its cos and sin), the others at neutral: the tests' independent route."""
    import math

    import pinocchio as pin
    full = pin.neutral(model)
    for name, v in values:
        jm = model.joints[model.getJointId(name)]
        full[jm.idx_q: jm.idx_q + jm.nq] = [math.cos(v), math.sin(v)] if jm.nq == 2 else [v]
    return full


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
                 "--sigma-probe-um", "2", "--no-plots", *options, "-o", str(out)]) == 0
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


# ---------------------------------------------------------------------------------------------
# the field's robot set: example-robot-data's URDFs, downloaded once outside the repository

def robot_set_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "aacmm-toolkit" / f"example-robot-data-{ROBOT_SET_VERSION}"


def _fetch_robot_set(dest: Path) -> None:
    """Download the wheel with pip and keep its URDFs under ``dest`` (written whole, then renamed)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "pip", "download", f"example-robot-data=={ROBOT_SET_VERSION}", "--no-deps",
               "--only-binary=:all:", "--retries", "1", "--timeout", "30", "-q", "-d", tmp]
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        wheels = list(Path(tmp).glob("*.whl"))
        if run.returncode != 0 or not wheels:
            pytest.skip(f"example-robot-data {ROBOT_SET_VERSION} could not be downloaded (offline?): "
                        f"{(run.stderr or run.stdout).strip().splitlines()[-1:] or 'no wheel'}")
        part = Path(tmp) / "robots"
        with zipfile.ZipFile(wheels[0]) as zf:
            for name in zf.namelist():
                if name.startswith(_ROBOT_SET_PREFIX) and name.endswith(".urdf"):
                    target = part / name[len(_ROBOT_SET_PREFIX):]
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(zf.read(name))
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(part), str(dest))


@pytest.fixture(scope="session")
def robots() -> Path:
    """The folder of the package's URDFs (downloaded once; the lock keeps two test workers from both
    downloading)."""
    cache = robot_set_cache()
    dest = cache / "robots"
    if not dest.is_dir():
        cache.mkdir(parents=True, exist_ok=True)
        with open(cache / ".lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not dest.is_dir():
                _fetch_robot_set(dest)
    return dest


# ---------------------------------------------------------------------------------------------
# The long studies (@pytest.mark.slow: make test-slow, run by hand before merging a change to estimation; CI runs
# make test only) and the test of make test that holds each one's property. "slow only": no fast counterpart.
#  calibration_prior no-bias, 20 campaigns -> test_calibration_prior ..._on_three_campaigns
#  calibration_real TALOS evidence scales -> test_calibration_real ..._lengths_..._on_one_half (one group, one half)
#  calibration_sim acceptance         -> test_calibration_fit truth_within_three_sigma, held_out_..._five_fold
#  calibration_study dask cluster     -> test_calibration_study monte_carlo_local (dask: only the executor)
#  joint_play backlash by the loop, Panda -> test_joint_play sign families build/exist (the loop end to end: slow only)
#  loop_cli residual and --library-only -> test_loop_cross_harmonics ..._built_added_and_recovered,
#                                       test_loop_honesty ..._library_alone
#  loop_cross_harmonics library alone -> test_loop_cross_harmonics ..._built_added_and_recovered; test_loop_honesty
#  loop_cross_harmonics test-set instance gross -> test_loop_cross_harmonics ..._too_small_flag_it_whole (the
#                                       test set's point test, same data), ..._built_added_and_recovered
#  loop_effects other seeds (10)      -> test_loop_effects names_recovers_and_halves (seed 3; seeds 4, 5: slow only)
#  loop_effects thermal (seed 3)      -> test_loop_effects [force_sensor] (a library effect named, recovered, halved);
#                                       test_loop_cli close_loop_writes_the_report; test_model_file calibrate_writes
#                                       (the thermal rate from a drifting campaign)
#  loop_effects eccentricity, probe compliance (seed 3) -> test_loop_cross_harmonics, test_loop_synthesis [lobing];
#                                       test_loop_effects [force_sensor] and its indistinguishable compliance
#  loop_effects joint compliance (seed 3) -> test_model_file tip_with_the_loops_model (j2's, found on this arm beside
#                                       an eccentricity); test_loop_sim_seats hidden compliance, test_loop_real_physics
#                                       compliance injected (robots: found, within 3 sigma, the held-out spread cut)
#  loop_real_physics gain injected    -> test_loop_real_physics compliance injected (the same injection and checks)
#  loop_heldout_verdict UR5 gain      -> test_loop_heldout_verdict three_times_..._u, opt_in_families_offered
#  loop_hidden_effects coupling, 4th harmonic -> test_loop_hidden_effects linear_coupling, structure_tests_see_a_fourth
#  loop_honesty 19 of 20 seeds        -> test_loop_honesty ..._on_seed_1, honesty_study (seed 4); the clean twins of
#                                       test_loop_cross_harmonics and test_loop_synthesis [lobing]
#  loop_honesty third harmonic built  -> test_loop_honesty ..._library_alone (the family, same campaign);
#                                       test_loop_synthesis offers_only_what_the_model_lacks (its harmonics);
#                                       test_loop_cross_harmonics ..._built_added_and_recovered (built, added)
#  loop_real level cannot be reached  -> test_loop_real units_needed, one_placement (the warning: slow only)
#  loop_real_default six pairs vs MUKCa -> test_loop_real_default starts_from_joint_compliance (two of six pairs)
#  loop_real_physics back-high        -> test_loop_real_default (front); test_loop_real_physics compliance injected
#  loop_sim_seats clean seeds 2-4     -> test_loop_sim_seats hidden compliance; test_loop_honesty two seeds
#  loop_synthesis four cases, two links -> test_loop_synthesis [lobing], synthesis_offers_only_what_the_model_lacks
#  packaging wheel installed          -> test_packaging examples_copies, tip_with_arm_by_name (the wheel: slow)
#  readme first measurement, whole section -> test_readme_first_measurement ..._real_panda_prints_what_the_readme_shows
#  robot_set every robot (96 MB download) -> slow only (make test needs no network); test_arm_model_urdf_import
#  sim_mocap robot set (6), coupled   -> test_sim_mocap obvious_commands_on_a_simulated_..., [lift]
#  sim_pose_effects lobing from the CLI -> test_loop_synthesis [lobing]
#  sim_seats_study coaxial, nine robots -> test_loop_pairs (the tie rule by hand); test_loop_sim_seats
#  tracker_talos nil unknowns change no held parameter (TALOS, 4 s) -> test_calibration_identifiability
#                                       held_branch_of_an_exact_ambiguity (a simulated chain: nil columns, orders)
#  thermal_drift loop with and without drift -> test_thermal_drift offered_only_with_time, evaluators (loop: slow only)
#  uncertainty_coverage 12 seeds x 3  -> test_calibration_real panda_heldout_uncertainty_coverage;
#                                       test_uncertainty monte_carlo_agrees_with_linear

# ---------------------------------------------------------------------------------------------
# the order of the tests under pytest-xdist (make test, make test-slow: -n 2 --dist worksteal)

#: seconds of CPU of the tests of at least about 1 s (one process, measured; the file says how): the weights the
#: order below gives the modules; a test not listed counts DEFAULT_SECONDS
DURATIONS = Path(__file__).with_name("durations.tsv")
DEFAULT_SECONDS = 0.1


def _recorded_seconds() -> dict[str, float]:
    rows = (line.split("\t") for line in DURATIONS.read_text().splitlines() if line and not line.startswith("#"))
    return {node: float(s) for s, node in rows}


def balanced_order(items: list, seconds: dict[str, float], default: float = DEFAULT_SECONDS) -> list:
    """``items`` (pytest items) ordered for worksteal on two workers: worksteal hands the first half of the list
    to one worker and the rest to the other, each runs its half from the front, and an idle worker steals from the
    back of the other's. So the modules (kept whole: a module fixture is set up once) are dealt heaviest first to
    the lighter half (the longest tests start first, none starts late), and the halves are then evened in count
    with the lightest modules' tests, which may be stolen."""
    modules: dict[str, list] = {}
    for item in items:
        modules.setdefault(item.nodeid.split("::")[0], []).append(item)
    weight = {m: sum(seconds.get(i.nodeid, default) for i in its) for m, its in modules.items()}
    halves: tuple[list, list] = ([], [])
    load = [0.0, 0.0]
    for m in sorted(modules, key=lambda m: -weight[m]):
        k = 0 if load[0] <= load[1] else 1
        halves[k].extend(modules[m])
        load[k] += weight[m]
    first, second = halves
    cut = len(items) // 2
    if len(first) < cut:                   # the lightest tests of the second half end the first
        k = cut - len(first)
        return first + second[-k:] + second[:-k]
    return first[:cut] + second + first[cut:]


@pytest.hookimpl(trylast=True)        # after -m and -k have deselected
def pytest_collection_modifyitems(config, items):
    if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get("PYTEST_XDIST_WORKER_COUNT") == "2":
        items[:] = balanced_order(items, _recorded_seconds())
