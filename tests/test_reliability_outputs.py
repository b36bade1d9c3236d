"""Reliability, outputs: every command writes its whole output or nothing, nothing outside ``-o``,
never over an input, no stale file of an earlier run, no mixing of concurrent runs; names built from
input text cannot leave the output folder; the top-level handler never shows a traceback."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from hypothesis import given, strategies as st

from arm_model import InputError
from arm_model.cli import main
from arm_model.output import MARKER, output_file, output_folder, safe_name
from conftest import NOMINAL, ROOT

POINTS = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"
CAMPAIGN = """name = "tiny"
seed = 3
arm = "{arm}"
sensor = "xyz"
[[task]]
kind = "ring"
id = "{task}"
measurements = 2
diameter_mm = 174.996
centre_mm = [700.0, 0.0, 50.0]
axis = [0.0, 0.0, 1.0]
depths_mm = [5.0, 12.0, 19.0]
points_per_row = 4
"""


def tree(d: Path) -> set[str]:
    """Every path under ``d`` (hidden ones too), relative."""
    return {str(p.relative_to(d)) for p in d.rglob("*")}


def campaign(tmp_path: Path, task: str = "ring") -> Path:
    src = tmp_path / "in" / "tiny.toml"
    src.parent.mkdir(exist_ok=True)
    src.write_text(CAMPAIGN.format(arm=NOMINAL, task=task))
    return src


# ---------------------------------------------------------------------------------------------
# the mechanism

def test_folder_published_whole_and_only_at_the_end(tmp_path):
    final = tmp_path / "out"
    with output_folder(final, (), "demo") as out:
        (out.dir / "a.txt").write_text("a")
        assert not final.exists()                       # nothing visible before the end
    assert tree(final) == {"a.txt", MARKER}
    assert (final / MARKER).read_text() == "aacmm demo\n"
    with output_folder(final, (), "demo") as out:       # a second run replaces the first as a whole
        (out.dir / "b.txt").write_text("b")
    assert tree(final) == {"b.txt", MARKER}
    assert tree(tmp_path) == {"out", "out/b.txt", f"out/{MARKER}"}


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt, InputError])
def test_folder_absent_after_a_failure(tmp_path, exc):
    final = tmp_path / "deep" / "er" / "out"
    with pytest.raises(exc):
        with output_folder(final, (), "demo") as out:
            (out.dir / "half.txt").write_text("x")
            raise exc("boom")
    assert tree(tmp_path) == set()                      # not even the parents it created


def test_failure_keeps_the_earlier_output(tmp_path):
    final = tmp_path / "out"
    with output_folder(final, (), "demo") as out:
        (out.dir / "old.txt").write_text("old")
    with pytest.raises(RuntimeError):
        with output_folder(final, (), "demo") as out:
            (out.dir / "new.txt").write_text("new")
            raise RuntimeError
    assert tree(final) == {"old.txt", MARKER}
    assert tree(tmp_path) == {"out", "out/old.txt", f"out/{MARKER}"}


def test_concurrent_runs_never_mix(tmp_path):
    final = tmp_path / "out"
    barrier = threading.Barrier(4)
    errors = []

    def run(k: int) -> None:
        try:
            with output_folder(final, (), "demo") as out:
                for i in range(20):
                    (out.dir / f"f{i}.txt").write_text(str(k))
                barrier.wait()
        except Exception as exc:            # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    contents = {(final / f"f{i}.txt").read_text() for i in range(20)}
    assert len(contents) == 1                           # one run's files, all of them
    assert tree(tmp_path) == {"out", f"out/{MARKER}"} | {f"out/f{i}.txt" for i in range(20)}


def test_refusals(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    inp = data / "points.csv"
    inp.write_text("x")
    afile = tmp_path / "afile"
    afile.write_text("keep")
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    other = tmp_path / "other"
    with output_folder(other, (), "simulate"):
        pass
    cases = [(data, [inp], "holds the input"), (inp, [inp], "over an input"),
             (afile, [], "a file of that name exists"), (afile / "sub", [], "below a file"),
             (foreign, [], "not an earlier output of aacmm"), (other, [], "an output of 'aacmm simulate'")]
    for final, inputs, msg in cases:
        before = tree(tmp_path)
        with pytest.raises(InputError, match=msg):
            with output_folder(final, inputs, "calibrate"):
                raise AssertionError("must not start")
        assert tree(tmp_path) == before
    assert afile.read_text() == "keep" and (foreign / "thesis.tex").read_text() == "precious"


def test_refuses_the_current_folder(tmp_path, monkeypatch):
    work = tmp_path / "work"
    with output_folder(work, (), "demo"):
        pass
    monkeypatch.chdir(work)
    with pytest.raises(InputError, match="current folder"):
        with output_folder(".", (), "demo"):
            pass


def test_file_output(tmp_path):
    final = tmp_path / "sub" / "out.csv"
    with pytest.raises(RuntimeError):
        with output_file(final) as tmp:
            tmp.write_text("half")
            raise RuntimeError
    assert tree(tmp_path) == set()
    with output_file(final) as tmp:
        tmp.write_text("whole")
    assert final.read_text() == "whole" and tree(tmp_path) == {"sub", "sub/out.csv"}
    (tmp_path / "adir").mkdir()
    with pytest.raises(InputError, match="a folder of that name exists"):
        with output_file(tmp_path / "adir"):
            pass


# ---------------------------------------------------------------------------------------------
# names from input text

SAFE = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._+-")


@given(st.text(max_size=300))
def test_safe_name_is_one_plain_name_inside_its_folder(text):
    name = safe_name(text, ".csv")
    assert "/" not in name and "\\" not in name and "\0" not in name
    assert not name.startswith(".") and name not in ("", ".", "..")
    assert len(name.encode("utf-8")) <= 255
    assert name == safe_name(text, ".csv")              # a reader finds what a writer wrote
    base = Path("/x/signals")
    assert (base / name).resolve().parent == base
    if text and set(text) <= SAFE and not text.startswith(".") and len(text) <= 120:
        assert name == text + ".csv"                    # ordinary ids are kept as they are


@pytest.mark.parametrize("name", ["../../x", "/tmp/abs", "a\"b<joint name='x'/>", "..", ".hidden", "a/../../b"])
def test_calibrate_arm_name_stays_in_the_output(tmp_path, name):
    from calibration.model_output import model_paths
    out = tmp_path / "out"
    for p in model_paths(out, f"{name}-calibrated").values():
        assert p.resolve().parent == out.resolve()


def test_measurement_id_cannot_make_ring_read_outside_signals(tmp_path):
    from arm_model.io import parse_points
    from correction.models import measurement_forces

    sig = tmp_path / "signals"
    sig.mkdir()
    (tmp_path / "x.csv").write_text("time_s,fx_N,fy_N,fz_N\n0,1,0,0\n0.001,2,0,0\n0.002,1,0,0\n")
    pts = parse_points("measurement,feature,q1_deg\n../x,,0\n", "p.csv")
    with pytest.raises(InputError, match=r"no force signal for measurement '\.\./x'") as e:
        measurement_forces(pts, "../x", sig)
    assert str(sig / "_._x.csv") in str(e.value)


def test_simulate_task_id_cannot_write_outside(tmp_path, capsys):
    src = campaign(tmp_path, task="../../evil")
    before = tree(tmp_path)
    assert main(["simulate", str(src), "-o", str(tmp_path / "o" / "sim"), "--quiet"]) == 2
    assert "line 7, key 'task[1].id'" in capsys.readouterr().err
    assert tree(tmp_path) == before


# ---------------------------------------------------------------------------------------------
# commands: stale files, failures, -o problems

def test_simulate_leaves_no_stale_signals(tmp_path, capsys):
    src = campaign(tmp_path)
    out = tmp_path / "sim"
    assert main(["simulate", str(src), "-o", str(out), "-q"]) == 0
    assert (out / "signals").is_dir()
    assert main(["simulate", str(src), "-o", str(out), "-q", "--no-signals"]) == 0
    assert not (out / "signals").exists()               # ring --signals cannot pair new points with old signals
    capsys.readouterr()


def test_interrupt_while_writing_leaves_nothing(tmp_path, monkeypatch, capsys):
    import arm_model.sim.run as run

    src = campaign(tmp_path)
    out = tmp_path / "sim"
    real = run.atomic_write_text
    calls = []

    def flaky(path, text, inputs=()):
        calls.append(path)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(path, text, inputs)

    monkeypatch.setattr(run, "atomic_write_text", flaky)
    before = tree(tmp_path)
    assert main(["simulate", str(src), "-o", str(out), "-q"]) == 130
    assert "interrupted; nothing written" in capsys.readouterr().err
    assert tree(tmp_path) == before


@pytest.mark.parametrize("make, msg", [
    (lambda p: p.mkdir(), "a folder of that name exists"),
    (lambda p: (p.parent / "f").write_text("x"), "below a file"),
])
def test_tip_output_problems_are_clear_errors(tmp_path, capsys, make, msg):
    target = tmp_path / "out.csv"
    make(target)
    if msg == "below a file":
        target = tmp_path / "f" / "out.csv"
    before = tree(tmp_path)
    assert main(["tip", str(POINTS), "--arm", str(NOMINAL), "-o", str(target)]) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err
    assert tree(tmp_path) == before


def test_folder_output_problems_are_clear_errors(tmp_path, capsys):
    afile = tmp_path / "report"
    afile.write_text("keep")
    assert main(["paper", "-o", str(afile)]) == 2
    assert "a file of that name exists" in capsys.readouterr().err
    assert main(["paper", "-o", str(afile / "below")]) == 2
    assert "below a file" in capsys.readouterr().err
    assert afile.read_text() == "keep" and tree(tmp_path) == {"report"}


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in read-only folders")
def test_read_only_output_folder(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert main(["tip", str(POINTS), "--arm", str(NOMINAL), "-o", str(ro / "x.csv")]) == 2
        assert "cannot write the output file" in capsys.readouterr().err
    finally:
        ro.chmod(0o755)


def test_unwritable_place_is_a_clear_error(capsys):
    assert main(["tip", str(POINTS), "--arm", str(NOMINAL), "-o", "/proc/aacmm-test/x.csv"]) == 2
    err = capsys.readouterr().err
    assert "aacmm tip: error:" in err and "Traceback" not in err


# ---------------------------------------------------------------------------------------------
# the top-level handler

def test_internal_error_asks_for_a_report(tmp_path, monkeypatch, capsys):
    import arm_model.commands as commands

    def bug(*a, **k):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(commands, "tip_table", bug)
    out = tmp_path / "t.csv"
    assert main(["tip", str(POINTS), "--arm", str(NOMINAL), "-o", str(out)]) == 3
    err = capsys.readouterr().err
    assert "internal error (ZeroDivisionError" in err and "please report it" in err and "Traceback" not in err
    assert main(["tip", str(POINTS), "--arm", str(NOMINAL), "-o", str(out), "--debug"]) == 3
    assert "Traceback" in capsys.readouterr().err
    assert tree(tmp_path) == set()


def test_os_error_is_one_message(tmp_path, monkeypatch, capsys):
    import arm_model.commands as commands

    def full(*a, **k):
        raise OSError(28, "No space left on device", str(tmp_path / "t.csv"))

    monkeypatch.setattr(commands, "format_csv", full)       # tip writes block by block
    assert main(["tip", str(POINTS), "--arm", str(NOMINAL), "-o", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and "Traceback" not in err
    assert tree(tmp_path) == set()


def test_closed_stdout_is_quiet(tmp_path):
    out = tmp_path / "t.csv"
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from arm_model.cli import main; sys.exit(main())",
                             "tip", str(POINTS), "--arm", str(NOMINAL), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    proc.stdout.close()                                 # like `| head -0`
    err = proc.stderr.read().decode()
    proc.wait(timeout=120)
    assert "BrokenPipe" not in err and "Traceback" not in err, err
    assert proc.returncode in (0, 141)
    assert out.is_file()


def test_files_named_by_the_arm_are_inputs_too(tmp_path, capsys):
    """A model file's covariance file and a --masses file are inputs: no output is written over them."""
    real = ROOT / "examples" / "data" / "real-panda-seats"
    cal = tmp_path / "cal"
    assert main(["calibrate", str(real / "front" / "points.csv"), str(real / "artefacts.toml"), "--arm",
                 str(real / "panda-with-inertials.urdf"), "--tip-frame", "ball_link", "--no-plots",
                 "-o", str(cal)]) == 0
    model = next(cal.glob("*-calibrated.toml"))
    cov = next(cal.glob("*-covariance.csv"))
    before = cov.read_bytes()
    capsys.readouterr()
    assert main(["tip", str(real / "front" / "points.csv"), "--arm", str(model), "-o", str(cov)]) == 2
    assert "input" in capsys.readouterr().err
    assert cov.read_bytes() == before
    masses = tmp_path / "masses.toml"
    masses.write_text('[[link]]\nname = "panda_link1"\nmass_kg = 1.0\n', encoding="utf-8")
    assert main(["tip", str(real / "front" / "points.csv"), "--arm", str(real / "panda.urdf"), "--tip-frame",
                 "ball_link", "--masses", str(masses), "-o", str(masses)]) == 2
    assert masses.read_text(encoding="utf-8").startswith("[[link]]")
