"""Reliability, round 11: what a hostile-input audit of every subcommand found after round 10 (each test named after
its finding; all fast: no fit, a few points). The audit's driver fed TOML files with 64-bit-overflowing integers,
dates, mixed arrays and nested inline tables; CSV files with Unicode line and paragraph separators, NEL, non-breaking
and other Unicode spaces, BOM, CRLF, UTF-16; URDFs as shipped by others (xacro leftovers, package:// meshes, mimic,
floating, planar and prismatic joints, two roots, zero and non-unit axes, 1e308 angles); hand-edited model and
covariance files; live streams over TCP and UDP (silent clients, 100 MB lines, resets, NaN, out-of-order and
duplicated samples); outputs on a full and a read-only file system, through links, hard links and `..`; Ctrl-C at
every instant of the start-up; 10^6-row inputs; and every numeric option with nan, inf, 1e308, 1e-320, -1, 0 and a
400-digit integer."""
from __future__ import annotations

import pytest

from arm_model import InputError
from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SAMPLES = ROOT / "examples" / "live" / "samples.csv"
HUGE = "1" + "0" * 400


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    return rc, capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# a TOML integer beyond 64 bits

@pytest.mark.parametrize("text, key, line", [
    (f"a = 1\n[t]\nd_mm = {HUGE}\n", "t.d_mm", 3),
    (f"[[feature]]\nid = 'x'\n[[feature]]\nid = 'y'\nlength_mm = -{HUGE}\n", "feature[2].length_mm", 5),
    (f"centre_mm = [1.0, {2 ** 63}, 3.0]\n", "centre_mm[2]", 1),
    (f"feature = [\n  {{ id = 'a', points = {HUGE} }},\n]\n", "feature[1].points", 2)])
def test_a_toml_integer_beyond_64_bits_is_refused_at_its_key(text, key, line):
    """A 400-digit integer (or 2**63) where a number is expected was taken by Python's TOML reader and then met
    float() as an OverflowError: exit 3 (an internal error) in the arm description, the artefacts, the campaign,
    the plan and the masses file. TOML 1.0 says such an integer is an error: now exit 2 at its line and key, for
    every TOML reader (errors.parse_toml)."""
    import re

    from arm_model.errors import parse_toml
    with pytest.raises(InputError, match=rf"f.toml, line {line}, key '{re.escape(key)}': not valid TOML: an integer "
                                         r"beyond 64 bits"):
        parse_toml(text, "f.toml")
    assert parse_toml(f"a = {2 ** 63 - 1}\nb = {-2 ** 63}\n", "f.toml") == {"a": 2 ** 63 - 1, "b": -2 ** 63}


def test_a_huge_integer_in_an_artefacts_file_is_exit_2(tmp_path, capsys):
    art = tmp_path / "a.toml"
    art.write_text((RING / "artefacts.toml").read_text().replace("diameter_mm = 174.996", f"diameter_mm = {HUGE}"))
    rc, err = _run(["ring", RING / "points.csv", art, "--arm", "aacmm7", "--no-plots", "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "a.toml, line 5, key 'feature[1].diameter_mm': not valid TOML: an integer beyond" in err, err
    assert not (tmp_path / "o").exists()
