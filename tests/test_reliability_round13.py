"""Reliability, round 13: a hostile-input audit of what changed most recently (the priors and the evidence: model
files carrying prior-dominated parameters and their covariance, read back by `tip`, `view` and `live`; `--effect` for
every kind on data without the columns it needs; close-loop's options; `live` from files, standard input, TCP and UDP;
plans; URDF and DH descriptions; outputs through links, into inputs and their folders; the ends of every numeric
option's range). Each test is named after its finding and is quick (no fit, a few points)."""
from __future__ import annotations

import pytest
from test_reliability_round12 import RING, _run

from conftest import exit_status, wait_udp_bound


@pytest.mark.parametrize("command, option, value, words", [
    ("calibrate", "--holdout", "ring-01,,ring-02", "--holdout 'ring-01,,ring-02': item 2 of 3 is empty"),
    ("calibrate", "--holdout", "ring-01,", "item 2 of 2 is empty"),
    ("close-loop", "--holdout", ",ring-01", "item 1 of 2 is empty"),
    ("close-loop", "--candidates", "thermal,,eccentricity",
     "--candidates 'thermal,,eccentricity': item 2 of 3 is empty"),
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


THERMAL = ('\n[[effect]]\nkind = "thermal"\nper_joint = false\nparameter = [\n    { name = "links.thermal_alpha", '
           'value_ppm_per_K = 1.0, u_ppm_per_K = 0.0, state = "fixed" },\n]\n')


def _short_stream(tmp_path, n=300):
    from test_reliability_round12 import SAMPLES
    stream = tmp_path / "stream.csv"
    stream.write_text("".join(SAMPLES.read_text().splitlines(keepends=True)[:n]))
    return stream


def test_a_stream_without_a_column_the_model_needs_is_refused_at_its_header(tmp_path, capsys):
    """`live --arm` a model with a thermal effect, on a stream without `temperature_C`: the session folder was created,
    the first point then stopped the command naming 'points.csv, line 1' (no such input) and session.json stayed
    'running', as if the process had been killed. Now the header is refused (its file, line 1, the column), exit 2, no
    folder: the rule of every points file (`Arm.check_columns`, the one message of `Arm.check_points`)."""
    from conftest import NOMINAL
    model = tmp_path / "thermal.toml"
    model.write_text(NOMINAL.read_text() + THERMAL)
    stream, sess = _short_stream(tmp_path), tmp_path / "s"
    rc, err = _run(["live", stream, "--arm", model, "--speed", "0", "--feature", "seat:a", "-o", sess], capsys)
    assert rc == 2 and ("stream.csv, line 1, column 'temperature_C': the model's effect 'thermal' needs the column "
                        "'temperature_C', which the stream lacks") in err, err
    assert not sess.exists()


def test_an_error_inside_a_live_session_closes_it_as_stopped(tmp_path, capsys, monkeypatch):
    """An error raised while a sample was taken (any but the stream's own failure) left session.json at 'running',
    which says the process was killed. Now the session is closed as 'stopped' with the error, and the error keeps its
    exit status (here a bug: 3)."""
    import json

    from arm_model.live import Session
    real = Session.push_sample

    def failing(self, sample, *a, **k):
        if self.counts["samples"] >= 100:
            raise RuntimeError("a bug in a point's computation")
        return real(self, sample, *a, **k)
    monkeypatch.setattr(Session, "push_sample", failing)
    sess = tmp_path / "s"
    rc, err = _run(["live", _short_stream(tmp_path), "--arm", "aacmm7", "--speed", "0", "-o", sess], capsys)
    assert rc == 3 and "a bug in a point's computation" in err, err
    status = json.loads((sess / "session.json").read_text())
    assert status["status"] == "stopped" and "a bug in a point's computation" in status["message"]
    assert status["counts"]["samples"] == 100


def test_a_udp_session_started_late_skips_any_line_before_the_header(tmp_path, capsys):
    """Over UDP a session may start while the adapter is mid-stream: the lines before the next header are to be
    skipped. A datagram line cut in two whose second half starts with a comma (or bytes that are not text) was taken
    as the header: exit 2, 'empty column name in the header', the session lost. Now, over UDP, the header is the first
    line naming the time column; every line before it is counted and skipped (a file, standard input and TCP keep
    their first line as the header, refused when wrong)."""
    import json
    import socket
    import threading
    import time
    stream = _short_stream(tmp_path)
    lines = stream.read_bytes().splitlines(keepends=True)
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()

    def send():
        wait_udp_bound(port)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for d in (b",-153.2937,92.1295,-89.4768\n", b"\xff\xfe garbage\n", b"0.5,1,2,3\n", *lines):
                s.sendto(d, ("127.0.0.1", port))
                time.sleep(0.0005)
    threading.Thread(target=send, daemon=True).start()
    sess = tmp_path / "s"
    rc = exit_status(["live", f"udp://127.0.0.1:{port}", "--arm", "aacmm7", "--stop-after-idle-s", "2", "-o",
                      str(sess)])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert json.loads((sess / "session.json").read_text())["counts"]["samples"] == len(lines) - 1
    assert "3 datagram line(s) before the header" in out.out + out.err


@pytest.mark.parametrize("kind, key", [("plane", "diameter_mm = 5.0"), ("seat", "diameter_mm = 25.0"),
                                       ("point", "form_error_mm = 0.001"), ("seat", "u_diameter_mm = 0.001")])
def test_a_certificate_of_a_kind_without_a_diameter_is_refused(kind, key):
    """A `diameter_mm` (or `u_diameter_mm`, `form_error_mm`) on a plane, a seat or a point was read and ignored
    (`live --feature plane:p:5` ran as if the 5 said something): the three keys certify a ring, a cylinder or a sphere
    (docs/formats.md), so on another kind they are a key of another kind, refused at their line (one reader:
    artefacts files, live plans and `--feature`)."""
    from arm_model.errors import InputError
    from arm_model.io import parse_artefacts
    from arm_model.live.plan import single_feature_plan
    with pytest.raises(InputError, match=rf"line 4, key 'feature\[1\]\.{key.split()[0]}': '{key.split()[0]}' is not "
                                         rf"a key of a {kind}"):
        parse_artefacts(f'[[feature]]\nid = "f"\nkind = "{kind}"\n{key}\n', "a.toml")
    parse_artefacts('[[feature]]\nid = "f"\nkind = "sphere"\ndiameter_mm = 25.0\nform_error_mm = 0.001\n', "a.toml")
    with pytest.raises(InputError, match="'diameter_mm' is not a key of a plane"):
        single_feature_plan("plane:p:5")


@pytest.mark.parametrize("argv", [["tip", RING / "points.csv", "--arm", "aacmm7", "-o", "{out}/"],
                                  ["urdf", "aacmm7", "-o", "{out}/"],
                                  ["view", RING / "points.csv", "--arm", "aacmm7", "--html", "{out}/"]])
def test_a_file_output_named_with_a_trailing_slash_is_refused(tmp_path, capsys, argv):
    """`tip -o t.csv/` wrote the file t.csv (Path() drops the slash; the shell's `> t.csv/` refuses it: a trailing
    slash names a folder). Now every one-file output refuses it at the option (`cli_options.file_output_path`)."""
    out = tmp_path / "t.csv"
    rc, err = _run([str(a).replace("{out}", str(out)) for a in argv], capsys)
    assert rc == 2 and "ends with '/', which names a folder: a file is expected here" in err, err
    assert not out.exists()
