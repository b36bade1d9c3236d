"""Reliability, round 7: a hostile-input audit of what rounds 1-6 did not look at, and the rules they left
inconsistent: a certified distance to a ring or cylinder (refused at its line by the reader, not at fit time),
joint values beyond the declared limits (warned alike whether measured or held), numerical failure (its own exit
status, 4), `study montecarlo` (--holdout 0, a run's input error, --scheduler). Each test is named after what it
checks; all are fast (no fit, or one of a few points)."""
from __future__ import annotations

import pytest

from arm_model.cli import main
from conftest import NOMINAL

QCOLS = ",".join(f"q{k}_deg" for k in range(1, 8))


def _exit(argv) -> int:
    """The exit status of ``aacmm argv`` (argparse's refusals raise SystemExit, the commands' return it)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def _points(tmp_path, rows=("m,f,10,20,30,40,50,60,70",), name="p.csv"):
    path = tmp_path / name
    path.write_text(f"measurement,feature,{QCOLS}\n" + "".join(r + "\n" for r in rows))
    return path


# ---------------------------------------------------------------------------------------------
# (b) a certified distance joins two centres: refused at its line for a ring, a cylinder or a free point

_ART = '''[[feature]]
id = "A"
kind = "seat"

[[feature]]
id = "R"
kind = "{kind}"
{size}
[[distance]]
between = ["A", "R"]
length_mm = 100.0
'''


@pytest.mark.parametrize("kind, size, words", [
    ("ring", "diameter_mm = 50.0\n", "a ring's axis is a line"),
    ("cylinder", "diameter_mm = 50.0\n", "a cylinder's axis is a line"),
    ("point", "# a point has no size\n", "a free point is no artefact's centre"),
])
def test_a_distance_to_a_feature_without_a_centre_is_refused_at_its_line(tmp_path, capsys, kind, size, words):
    """A distance to a ring was refused by the fit ("a distance needs feature centres", no line) only when a
    measurement held both features, and read without a word by `aacmm ring`, `view` and a live plan (which
    measured it between the ring's axis point and the seat). The artefacts reader refuses it at the table's line,
    so every command that reads the file says the same."""
    art = tmp_path / "a.toml"
    art.write_text(_ART.format(kind=kind, size=size))
    rc = _exit(["calibrate", str(_points(tmp_path, ("m,A,10,20,30,40,50,60,70",))), str(art), "--arm", "aacmm7",
                "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "a.toml, line 11, key 'distance[1].between'" in err and words in err, err
    assert not (tmp_path / "o").exists()
    from arm_model.errors import InputError
    from arm_model.live.plan import read_plan
    with pytest.raises(InputError, match="line 11"):
        read_plan(art)
