"""Installed use: --version, shipped arms by name, `aacmm examples`, provenance (a calibrate summary's:
tests/test_calibration_baseline.py, with the arm by name), and (slow) a wheel built and run from another folder
without the checkout."""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from arm_model import InputError
from arm_model.cli import main
from arm_model.shipped import SHIPPED_ARMS, arm_path, provenance, shipped_path, version
from conftest import NOMINAL, ROOT


def test_version_option(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.strip() == f"aacmm-toolkit {version()}" and version()[0].isdigit()


def test_shipped_arm_by_name_is_the_nominal_file():
    assert arm_path("aacmm7").read_bytes() == NOMINAL.read_bytes()
    assert set(SHIPPED_ARMS) == {"aacmm7"}
    assert arm_path("some/arm.toml") == Path("some/arm.toml")


def test_load_description_takes_a_shipped_arm_by_name(tmp_path, monkeypatch):
    from arm_model.description import load_description
    monkeypatch.chdir(tmp_path)                      # no urdf/ here: the name must find the shipped file
    by_name, by_path = load_description("aacmm7"), load_description(NOMINAL)
    assert by_name.joints == by_path.joints and by_name.probe == by_path.probe
    (tmp_path / "aacmm7").write_text("not toml [")  # an existing file of that name is read as given
    with pytest.raises(InputError, match="not valid TOML"):
        load_description("aacmm7")


def test_missing_arm_file_names_the_shipped_arms(tmp_path, monkeypatch, capsys):
    pts = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"
    monkeypatch.chdir(tmp_path)                      # as after a pip install: no urdf/ folder here
    assert main(["tip", str(pts), "--arm", "urdf/aacmm7.dh.toml", "-o", "a.csv"]) == 2
    err = capsys.readouterr().err
    assert "urdf/aacmm7.dh.toml" in err and "--arm aacmm7" in err and "Traceback" not in err
    assert not (tmp_path / "a.csv").exists()


def test_tip_with_arm_by_name_from_another_folder(tmp_path, monkeypatch, capsys):
    pts = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"
    monkeypatch.chdir(tmp_path)
    assert main(["tip", str(pts), "--arm", "aacmm7", "-o", "a.csv"]) == 0
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", "b.csv"]) == 0
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


def test_examples_copies_campaigns_data_docs_and_licence(tmp_path, capsys):
    dest = tmp_path / "ex"
    assert main(["examples", str(dest)]) == 0
    lic = dest / "data" / "real-panda-seats" / "LICENSE-MUKCa.txt"
    assert lic.read_bytes() == (ROOT / "examples" / "data" / "real-panda-seats" / "LICENSE-MUKCa.txt").read_bytes()
    for name in ("points.csv", "LICENSE-figaroh.txt", "README.md"):      # the tracker walkthrough's campaign
        talos = ROOT / "examples" / "data" / "real-talos-mocap" / name
        assert (dest / "data" / "real-talos-mocap" / name).read_bytes() == talos.read_bytes()
    assert not list((dest / "data" / "real-talos-mocap").glob("*.urdf"))
    assert (dest / "docs" / "formats.md").is_file()
    # the guides link to ../README.md (calibration.md, own-arm.md: "the README's first own measurement")
    assert (dest / "README.md").read_bytes() == (ROOT / "README.md").read_bytes()
    own = tmp_path / "project"                   # `aacmm examples .` in a folder with its own README: kept, no refusal
    own.mkdir()
    (own / "README.md").write_text("mine")
    assert main(["examples", str(own)]) == 0 and (own / "README.md").read_text() == "mine"
    assert (own / "docs" / "formats.md").is_file()
    assert (dest / "arms" / "aacmm7.dh.toml").read_bytes() == NOMINAL.read_bytes()
    for c in (ROOT / "examples" / "campaigns").glob("*.toml"):
        assert (dest / "campaigns" / c.name).read_bytes() == c.read_bytes()
    # a copied campaign finds its arm (by name) wherever it lies
    from arm_model.sim.campaign import load_campaign
    camp = load_campaign(dest / "campaigns" / "paper-ring.toml")
    assert camp.arm.name == "aacmm7" and camp.arm_path == shipped_path("urdf/aacmm7.dh.toml")
    # never over existing files: exit 2, nothing changed
    lic.write_text("mine")
    assert main(["examples", str(dest)]) == 2
    assert lic.read_text() == "mine"


def test_provenance_hashes_files_and_folders(tmp_path):
    a = tmp_path / "a.csv"
    a.write_bytes(b"x,y\n")
    d = tmp_path / "sig"
    d.mkdir()
    (d / "m1.csv").write_bytes(b"1\n")
    p = provenance({"points": a, "signals": d, "none": None})
    assert p["aacmm_version"] == version()
    assert p["input_sha256"] == {str(a): hashlib.sha256(b"x,y\n").hexdigest(),
                                 str(d / "m1.csv"): hashlib.sha256(b"1\n").hexdigest()}


def test_pyproject_licence_is_an_spdx_string():
    import tomllib
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert meta["project"]["license"] == "MIT"
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    req = meta["build-system"]["requires"]
    assert any(r.replace(" ", "").startswith("setuptools>=7") and int(r.split(">=")[1]) >= 77 for r in req)


@pytest.mark.slow
def test_wheel_installed_use_without_the_checkout(tmp_path):
    """Build the wheel, install it (no deps: they are in this venv) into a folder that shadows the
    checkout, and run from an unrelated folder: --version, --arm aacmm7, aacmm examples."""
    wheels = tmp_path / "wheels"
    # built from a copy: setuptools leaves build/ and *.egg-info in the folder it builds
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "build", "out", "*.egg-info",
                                                             "__pycache__", ".*_cache"))
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(wheels)],
                       capture_output=True, text=True, timeout=600)
    if r.returncode != 0 and ("Could not find a version" in r.stderr or "connection" in r.stderr.lower()):
        pytest.skip("no package index to build the wheel: " + r.stderr[-200:])
    assert r.returncode == 0, r.stderr
    assert "warning" not in r.stderr.lower().replace("byte-compiling is disabled", "")
    whl = next(wheels.glob("aacmm_toolkit-*.whl"))
    names = zipfile.ZipFile(whl).namelist()
    assert "arm_model/_shipped/urdf/aacmm7.dh.toml" in names
    assert "arm_model/_shipped/README.md" in names and "arm_model/_shipped/docs/own-arm.md" in names
    assert "arm_model/_shipped/examples/data/real-panda-seats/LICENSE-MUKCa.txt" in names
    assert "arm_model/_shipped/examples/data/real-talos-mocap/LICENSE-figaroh.txt" in names
    assert any(n.endswith("licenses/examples/data/real-talos-mocap/LICENSE-figaroh.txt") for n in names)
    assert not any("talos" in n and n.endswith(".urdf") for n in names)       # PAL's licence: never shipped
    assert any(n.endswith("licenses/LICENSE") for n in names)
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(whl)],
                   check=True, capture_output=True, timeout=600)
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = dict(os.environ, PYTHONPATH=str(site))

    def aacmm(*args):
        return subprocess.run([sys.executable, "-c", "import sys; from arm_model.cli import main; sys.exit(main())",
                               *args], cwd=work, env=env, capture_output=True, text=True, timeout=300)

    r = aacmm("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"aacmm-toolkit {version()}", r.stderr
    probe = subprocess.run([sys.executable, "-c", "import arm_model; print(arm_model.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True)
    assert probe.stdout.startswith(str(site)), probe.stdout
    r = aacmm("examples", "ex")
    assert r.returncode == 0, r.stderr
    r = aacmm("tip", "ex/data/paper-ring-xyz/points.csv", "--arm", "aacmm7", "-o", "tips.csv")
    assert r.returncode == 0, r.stderr
    assert (work / "tips.csv").read_text().count("\n") == 1225
