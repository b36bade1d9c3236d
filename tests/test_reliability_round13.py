"""Reliability, round 13: a hostile-input audit of what changed most recently (the priors and the evidence: model
files carrying prior-dominated parameters and their covariance, read back by `tip`, `view` and `live`; `--effect` for
every kind on data without the columns it needs; close-loop's options; `live` from files, standard input, TCP and UDP;
plans; URDF and DH descriptions; outputs through links, into inputs and their folders; the ends of every numeric option's
range). Each test is named after its finding and is quick (no fit, a few points)."""
from __future__ import annotations

import pytest

from test_reliability_round12 import RING, _run


@pytest.mark.parametrize("command, option, value, words", [
    ("calibrate", "--holdout", "ring-01,,ring-02", "--holdout 'ring-01,,ring-02': item 2 of 3 is empty"),
    ("calibrate", "--holdout", "ring-01,", "item 2 of 2 is empty"),
    ("close-loop", "--holdout", ",ring-01", "item 1 of 2 is empty"),
    ("close-loop", "--candidates", "thermal,,eccentricity", "--candidates 'thermal,,eccentricity': item 2 of 3 is empty"),
    ("close-loop", "--candidates", "thermal,", "item 2 of 2 is empty"),
    ("close-loop", "--candidates", " , ", "--candidates names no family"),
    ("calibrate", "--holdout", "ring-01,ring-02,ring-01", "--holdout names ring-01 twice"),
])
def test_an_empty_item_of_a_list_option_is_refused(tmp_path, capsys, command, option, value, words):
    """`--holdout a,,b` and `--candidates thermal,` dropped the empty item and ran (the `$ID` of an unset shell
    variable, which round 9 refuses as a whole argument, went unnoticed inside a list). Now one rule for every
    comma-separated option (`cli_options.comma_list`): exit 2 naming the option and the item, nothing written."""
    out = tmp_path / "o"
    rc, err = _run([command, RING / "points.csv", RING / "artefacts.toml", "--arm", "aacmm7", option, value,
                    "-o", out], capsys)
    assert rc == 2 and words in err, err
    assert not out.exists()
