"""Reliability, hostile files (the classes of failure a hostile-input audit of every command found): bytes
that are not text (NUL, classic-Mac line ends), TOML nested beyond the parser's recursion, numbers that are
finite but absurd (1e308 mm, a temperature below absolute zero), a stylus of 1e-320 mm, force-signal
columns the reader ignored, a FIFO or a folder given as a file, a symbolic-link loop at -o. Each gives exit
2, one located message and nothing written; the tables of hostile inputs run in seconds."""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from arm_model import InputError
from arm_model.cli import main
from arm_model.io import read_force_signal
from conftest import NOMINAL, ROOT

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
POINTS = "\n".join((RING / "points.csv").read_text().splitlines()[:6]) + "\n"
ARM = NOMINAL.read_text()
ARTEFACTS = (RING / "artefacts.toml").read_text()
URDF = (ROOT / "urdf" / "aacmm7.urdf").read_text()
CAMPAIGN = 'seed = 1\n[[task]]\nkind = "seat"\narticulations = 3\n'
DEEP = "x = " + "[" * 50_000 + "]" * 50_000 + "\n"


def _cell(text: str, column: str, value: str, row: int = 1) -> str:
    """``text`` (CSV) with the cell of ``column`` in data row ``row`` replaced by ``value``."""
    lines = text.splitlines()
    k = lines[0].split(",").index(column)
    cells = lines[row].split(",")
    cells[k] = value
    lines[row] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _key(text: str, key: str, value: str) -> str:
    """``text`` (TOML) with the first ``key = ...`` line's value replaced by ``value``."""
    return re.sub(rf"(?m)^{re.escape(key)} = .*$", f"{key} = {value}", text, count=1)


def _run(tmp_path: Path, files: dict, argv: list, capsys) -> tuple[int, str]:
    """Run ``aacmm argv`` in ``tmp_path`` holding ``files`` (name -> text or bytes); the exit code and
    stderr, after checking that nothing but the inputs is left."""
    for name, data in files.items():
        (tmp_path / name).write_bytes(data if isinstance(data, bytes) else data.encode())
    before = {p.name for p in tmp_path.iterdir()}
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        code = main(argv)
    finally:
        os.chdir(cwd)
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    if code != 0:
        assert {p.name for p in tmp_path.iterdir()} == before, "something was written"
        assert err.count("error:") == 1, err
    return code, err


TIP = ["tip", "p.csv", "--arm", "arm.toml", "-o", "out.csv"]

# (files replacing the defaults, the message's expected words: file, line/key, reason)
HOSTILE_TIP = [
    ({"p.csv": POINTS.replace("ring-01", "ring\0-01", 1).encode()}, ["p.csv", "line 2", "NUL"]),
    ({"p.csv": POINTS.replace("\n", "\r").encode()}, ["p.csv", "line 1", "carriage return"]),
    ({"arm.toml": ARM.replace("\n", "\r", 3).encode()}, ["arm.toml", "line 1", "carriage return"]),
    ({"p.csv": _cell(POINTS, "q2_deg", "1e308")}, ["p.csv", "line 2", "q2_deg", "plausible angle"]),
    ({"p.csv": _cell(POINTS, "fz_N", "-1e300", 3)}, ["p.csv", "line 4", "fz_N", "plausible force"]),
    ({"arm.toml": DEEP}, ["arm.toml", "nested too deeply"]),
    ({"arm.toml": _key(ARM, "d_mm", "1e308")}, ["arm.toml", "line 11", "d_mm", "plausible length"]),
    ({"arm.toml": _key(ARM, "mass_kg", "1e300")}, ["arm.toml", "mass_kg", "plausible mass"]),
    ({"arm.toml": _key(ARM, "z_mm", "1e-320")}, ["arm.toml", "z_mm", "at least 0.001 mm"]),
    ({"arm.toml": _key(ARM, "name", "1e308")}, ["arm.toml", "'name' must be a non-empty text"]),
]


@pytest.mark.parametrize("files, words", HOSTILE_TIP)
def test_hostile_points_and_descriptions(tmp_path, capsys, files, words):
    code, err = _run(tmp_path, {"p.csv": POINTS, "arm.toml": ARM, **files}, TIP, capsys)
    assert code == 2 and all(w in err for w in words), err


def test_hostile_model_file_effect_value(tmp_path, capsys):
    """An effect parameter of 1e308 urad (it reached the output as inf)."""
    model = (ARM + '\n[[effect]]\nkind = "eccentricity"\nharmonics = [1]\n'
             + "".join(f'[[effect.parameter]]\nname = "j{j}.ecc1_{t}"\nvalue_urad = {"1e308" if j == 2 else "1.0"}\n'
                       for j in range(1, 8) for t in ("cos", "sin")))
    code, err = _run(tmp_path, {"p.csv": POINTS, "arm.toml": model}, TIP, capsys)
    assert code == 2 and "value_urad" in err and "plausible angle" in err, err


@pytest.mark.parametrize("text, words", [
    (_key(ARTEFACTS, "diameter_mm", "1e308"), ["diameter_mm", "plausible length"]),
    (DEEP, ["nested too deeply"]),
])
def test_hostile_artefacts(tmp_path, capsys, text, words):
    code, err = _run(tmp_path, {"p.csv": POINTS, "a.toml": text},
                     ["ring", "p.csv", "a.toml", "--arm", str(NOMINAL), "-o", "out"], capsys)
    assert code == 2 and "a.toml" in err and all(w in err for w in words), err


@pytest.mark.parametrize("text, words", [
    (CAMPAIGN + "[truth]\nlength_error_um = -3.0\n", ["length_error", "must not be negative"]),
    (CAMPAIGN + "[operator]\npoint_cv = 1e308\n", ["point_cv", "plausible ratio"]),
    (CAMPAIGN.replace("articulations = 3", "articulations = 3\nposition_mm = [1e308, 0, 0]"),
     ["position_mm", "plausible length"]),
])
def test_hostile_campaigns(tmp_path, capsys, text, words):
    code, err = _run(tmp_path, {"c.toml": text}, ["simulate", "c.toml", "-o", "out"], capsys)
    assert code == 2 and "c.toml" in err and all(w in err for w in words), err


def test_operator_spread_whose_square_underflows_is_no_spread(tmp_path, capsys):
    """point_cv = 1e-200 (its square is 0): a constant force, not a ZeroDivisionError."""
    code, _ = _run(tmp_path, {"c.toml": CAMPAIGN + "[operator]\npoint_cv = 1e-200\n"},
                   ["simulate", "c.toml", "-o", "out", "-q"], capsys)
    assert code == 0 and (tmp_path / "out" / "points.csv").is_file()


@pytest.mark.parametrize("old, new, words", [
    ('<origin xyz="0.0 0.0 0.2"', '<origin xyz="0.0 0.0 1e308"', ["origin.xyz", "plausible length"]),
    ('<sphere radius="0.002"/>', '<sphere radius="-1"/>', ["sphere.radius", "must not be negative"]),
    ('<mass value="1.0"/>', '<mass value="1_0"/>', ["mass.value", "finite number"]),
    ('<axis xyz="0.0 0.0 1.0"/>', '<axis xyz="1e308 1e308 1e308"/>', ["axis.xyz", "plausible"]),
])
def test_hostile_urdf_numbers(tmp_path, capsys, old, new, words):
    assert old in URDF
    code, err = _run(tmp_path, {"r.urdf": URDF.replace(old, new, 1)},
                     ["urdf", "r.urdf", "--tip-frame", "ball", "-o", "out.urdf"], capsys)
    assert code == 2 and "r.urdf, line" in err and all(w in err for w in words), err


@pytest.mark.parametrize("header, words", [
    ("time_s,f_bend_N,f_axial_N,bogus_mm", ["unknown column 'bogus_mm'"]),
    ("time_s,f_bend_N,f_axial_N,f_axial_N", ["repeated column 'f_axial_N'"]),
    ("time_s,fx_N,fy_N", ["expected force columns"]),
])
def test_force_signal_columns_are_strict(tmp_path, header, words):
    n = len(header.split(","))
    (tmp_path / "s.csv").write_text(header + "\n" + "\n".join(",".join([f"{i * 1e-3:.3f}"] + ["0.5"] * (n - 1))
                                                            for i in range(5)) + "\n")
    with pytest.raises(InputError) as exc:
        read_force_signal(tmp_path / "s.csv")
    assert exc.value.line == 1 and all(w in str(exc.value) for w in words), str(exc.value)


def test_force_signal_value_out_of_range(tmp_path):
    (tmp_path / "s.csv").write_text("time_s,f_bend_N,f_axial_N\n0.0,0,0\n0.001,1e300,0\n")
    with pytest.raises(InputError) as exc:
        read_force_signal(tmp_path / "s.csv")
    assert exc.value.line == 3 and exc.value.column == "f_bend_N" and "plausible force" in str(exc.value)


@pytest.mark.parametrize("make, words", [
    (lambda p: os.mkfifo(p), "not a regular file"),      # reading a FIFO would wait forever
    (lambda p: p.mkdir(), "a folder, not a file"),
    (lambda p: os.symlink(p.name, p), "loop of symbolic links"),     # a link to itself
])
@pytest.mark.parametrize("role", ["points", "arm"])
def test_special_files_as_inputs(tmp_path, capsys, make, words, role):
    make(tmp_path / "bad")
    files = {"p.csv": POINTS, "arm.toml": ARM}
    argv = [a.replace("p.csv" if role == "points" else "arm.toml", "bad") for a in TIP]
    code, err = _run(tmp_path, files, argv, capsys)
    assert code == 2 and "bad" in err and words in err, err


def test_symlink_loop_as_output(tmp_path, capsys):
    os.symlink("loop", tmp_path / "loop")
    code, err = _run(tmp_path, {"p.csv": POINTS, "arm.toml": ARM}, TIP[:-1] + ["loop"], capsys)
    assert code == 2 and "loop of symbolic links" in err, err


def test_nul_in_an_argument(tmp_path, capsys):
    code, err = _run(tmp_path, {"p.csv": POINTS, "arm.toml": ARM}, TIP[:-1] + ["a\0b"], capsys)
    assert code == 2 and "NUL" in err


def test_masses_naming_an_unknown_link_point_at_the_masses_file(tmp_path, capsys):
    masses = '[[link]]\nname = "link_2"\nmass_kg = 0.6\n\n[[link]]\nname = "no_such_link"\nmass_kg = 1.0\n'
    code, err = _run(tmp_path, {"p.csv": POINTS, "r.urdf": URDF, "m.toml": masses},
                     ["tip", "p.csv", "--arm", "r.urdf", "--tip-frame", "ball", "--masses", "m.toml", "-o", "out.csv"],
                     capsys)
    assert code == 2 and "m.toml, line 6" in err and "no_such_link" in err, err
