"""``aacmm live``: its sources (a file, standard input, TCP, UDP give the same session), what it promises
when stopped (Ctrl-C, SIGTERM, a kill), bad lines (counted and skipped, or --strict), refused folders and
headers, and hostile lines (a located error, never a traceback)."""
from __future__ import annotations

import csv
import json
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest
from hypothesis import given, strategies as st

from arm_model import InputError
from arm_model.cli import main
from arm_model.io import read_points
from arm_model.live import SampleLayout, read_status
from arm_model.live.sources import open_source
from conftest import ROOT, wait_udp_bound

EXAMPLE = ROOT / "examples" / "live"
SAMPLES = EXAMPLE / "samples.csv"
LINES = SAMPLES.read_text().splitlines(keepends=True)
HEADER = LINES[0]


def live(*args) -> int:
    return main(["live", *map(str, args), "--arm", "aacmm7", "-q"])


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """The first 4000 lines of the example (four contacts) and its session replayed from the file."""
    d = tmp_path_factory.mktemp("short")
    (d / "samples.csv").write_text("".join(LINES[:4001]))
    assert live(d / "samples.csv", "-o", d / "file", "--speed", "0", "--measurement", "m") == 0
    assert len(read_points(d / "file" / "points.csv", 7)) >= 4
    return d


def rows(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def command(*args) -> list[str]:
    return [sys.executable, "-m", "arm_model.cli", "live", *map(str, args), "--arm", "aacmm7"]


# -- sources --------------------------------------------------------------------------------------

def test_stdin_gives_the_file_session(short):
    out = short / "stdin"
    res = subprocess.run(command("-", "-o", out, "--measurement", "m"), input=(short / "samples.csv").read_bytes(),
                         capture_output=True, timeout=120, cwd=ROOT)
    assert res.returncode == 0, res.stderr.decode()
    assert (out / "tips.csv").read_bytes() == (short / "file" / "tips.csv").read_bytes()
    assert read_status(out)["source"] == "<stdin>"


def test_tcp_gives_the_file_session(short):
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def serve():
        conn, _ = server.accept()
        with conn:
            conn.sendall((short / "samples.csv").read_bytes())
        server.close()
    threading.Thread(target=serve, daemon=True).start()
    out = short / "tcp"
    assert live(f"tcp://127.0.0.1:{port}", "-o", out, "--measurement", "m") == 0
    assert (out / "tips.csv").read_bytes() == (short / "file" / "tips.csv").read_bytes()


def test_a_udp_source_holds_a_burst_while_the_session_is_busy(short):
    """The session asks the kernel for a large receive buffer: a whole 4 s stream sent while nothing reads
    arrives whole (where the system grants the buffer; the console says when it does not)."""
    from arm_model.live.sources import UDP_BUFFER_BYTES
    source = open_source("udp://127.0.0.1:0")
    try:
        if source.buffer_bytes < UDP_BUFFER_BYTES:
            pytest.skip(f"this system grants a UDP buffer of {source.buffer_bytes} bytes only")
        lines = (short / "samples.csv").read_bytes().splitlines(keepends=True)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for k in range(0, len(lines), 20):
                s.sendto(b"".join(lines[k:k + 20]), source.address)
        got = []
        for chunk in source.chunks():
            if chunk is None:
                break
            got += [raw for _, raw in chunk]
        assert got == [line.rstrip(b"\r\n") for line in lines]
    finally:
        source.close()


def test_a_small_udp_buffer_is_said(tmp_path, monkeypatch, capsys):
    from arm_model.live import sources
    monkeypatch.setattr(sources._UdpSource, "_ask_buffer", lambda self, size: 212992)
    assert live("udp://127.0.0.1:0", "-o", tmp_path / "s", "--stop-after-idle-s", "0.3") == 2
    err = capsys.readouterr().err
    assert "the UDP receive buffer is 208 KiB" in err and "net.core.rmem_max=8388608" in err
    assert not (tmp_path / "s").exists()


def test_udp_gives_the_file_session(short):
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    lines = (short / "samples.csv").read_text().splitlines(keepends=True)

    def send():
        wait_udp_bound(port)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"0.5,1,2,3,4,5,6,7,0,0,0,0\n", ("127.0.0.1", port))    # before any header: skipped
            for k in range(1, len(lines), 20):
                if k % 1000 == 1:
                    s.sendto(lines[0].encode(), ("127.0.0.1", port))          # the header, again and again
                s.sendto("".join(lines[k:k + 20]).encode(), ("127.0.0.1", port))
                time.sleep(0.005)     # 4x real time: a pause of the session under ~0.4 s loses nothing in any buffer
    threading.Thread(target=send, daemon=True).start()
    out = short / "udp"
    assert live(f"udp://127.0.0.1:{port}", "-o", out, "--measurement", "m", "--stop-after-idle-s", "1.5") == 0
    assert (out / "tips.csv").read_bytes() == (short / "file" / "tips.csv").read_bytes()
    assert json.loads((out / "session.json").read_text())["counts"]["dropped"] == 0


def test_a_paced_replay_keeps_time(short, tmp_path):
    """--speed 4: the 4 s stream takes about 1 s (the pacing, not the processing, sets the pace)."""
    t0 = time.monotonic()
    assert live(short / "samples.csv", "-o", tmp_path / "s", "--speed", "4", "--measurement", "m") == 0
    assert 0.95 <= time.monotonic() - t0 < 6.0
    assert (tmp_path / "s" / "tips.csv").read_bytes() == (short / "file" / "tips.csv").read_bytes()


# -- stopped sessions ------------------------------------------------------------------------------

def _feed_then(sig, tmp_path, n_lines: int = 3001):
    """Send ``n_lines`` of the example to ``aacmm live -`` on its standard input, wait until they are
    flushed, send ``sig``: (exit code, stderr, the session folder)."""
    out = tmp_path / "s"
    proc = subprocess.Popen(command("-", "-o", out), stdin=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, cwd=ROOT)
    proc.stdin.write("".join(LINES[:n_lines]).encode())
    proc.stdin.flush()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:       # the samples read, and a flush (at most 0.5 s) after them
        st_ = read_status(out)
        if st_ and st_.get("counts", {}).get("samples") == n_lines - 1:
            break
        time.sleep(0.1)
    time.sleep(0.2)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err.decode(), out


@pytest.mark.parametrize("sig, code, status",
                         [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")])
def test_a_stopped_session_is_kept_and_says_so(sig, code, status, tmp_path):
    rc, err, out = _feed_then(sig, tmp_path)
    assert rc == code, err
    assert "Traceback" not in err and f"session {status}" in err and str(out) in err
    st_ = read_status(out)
    assert st_["status"] == status and st_["closed"]
    samples = (out / "samples.csv").read_text().splitlines()
    assert len(samples) == 3001 and samples[0] == HEADER.strip()
    assert len(read_points(out / "points.csv", 7)) >= 2


def test_a_killed_session_keeps_what_it_flushed(tmp_path):
    rc, _, out = _feed_then(signal.SIGKILL, tmp_path)
    assert rc == -signal.SIGKILL
    st_ = read_status(out)
    assert st_["status"] == "running" and not st_["closed"]           # never closed: killed
    text = (out / "samples.csv").read_text()
    assert text.endswith("\n") and len(text.splitlines()) == 3001      # every sample read, whole lines
    assert len(read_points(out / "points.csv", 7)) >= 2
    # a new session never goes into it, and says what it is
    assert live(SAMPLES, "-o", out, "--speed", "0") == 2


def test_refused_folders_leave_everything_as_it_was(tmp_path, capsys):
    other = tmp_path / "other"
    other.mkdir()
    (other / "keep.txt").write_text("mine")
    assert live(SAMPLES, "-o", other, "--speed", "0") == 2
    assert sorted(p.name for p in other.iterdir()) == ["keep.txt"]
    a_file = tmp_path / "f.txt"
    a_file.write_text("x")
    assert live(SAMPLES, "-o", a_file, "--speed", "0") == 2
    assert live(SAMPLES, "-o", EXAMPLE, "--speed", "0") == 2              # the folder of its input
    s = tmp_path / "s"
    assert live(tmp_path / "missing.csv", "-o", s) == 2 and not s.exists()
    err = capsys.readouterr().err
    assert "never writes into an existing folder" in err and "Traceback" not in err


def test_an_earlier_session_is_named(tmp_path, short, capsys):
    assert live(short / "samples.csv", "-o", short / "file", "--speed", "0") == 2
    assert "an earlier session (status 'complete')" in capsys.readouterr().err


@pytest.mark.parametrize("header, message", [
    ("time_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N", "q1 ... q7"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg,fx_N,fy_N,fz_N", "time column"),
    ("time_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg,fx_N,fy_N,fz_N,pressure_Pa", "pressure_Pa"),
    ("time_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg,fx_N,fy_N", "fz"),
    ("time_s,q1_mm,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg", "angle"),
])
def test_a_bad_header_writes_nothing(header, message, tmp_path, capsys):
    src = tmp_path / "bad.csv"
    src.write_text(header + "\n0,1,2,3,4,5,6,7,8,9,10\n")
    assert live(src, "-o", tmp_path / "s") == 2
    err = capsys.readouterr().err
    assert message in err and "line 1" in err and str(src) in err
    assert not (tmp_path / "s").exists()


def test_bad_lines_are_counted_and_skipped_or_stop_with_strict(tmp_path, capsys):
    lines = LINES[:3001]
    cells = lines[100].split(",")
    lines[100] = ",".join([cells[0], "nan"] + cells[2:])
    lines[200] = "garbage\n"
    lines[300] = lines[300].replace(",0\n", ",0,1\n")
    lines[400] = lines[400].replace("0", "1e999", 1)
    lines.insert(500, "\xff\xfe bytes\n")
    src = tmp_path / "bad.csv"
    src.write_bytes("".join(lines).encode("utf-8", "surrogateescape").replace("\xff\xfe".encode(), b"\xff\xfe"))
    assert live(src, "-o", tmp_path / "s", "--speed", "0") == 0
    err = capsys.readouterr().err
    ev = [e for e in rows(tmp_path / "s" / "events.csv") if e["kind"] == "bad_line"]
    assert len(ev) == 5
    assert all(str(src) in e["message"] and "line " in e["message"] for e in ev)
    assert "column 'q1_deg'" in ev[0]["message"] and "line 101" in ev[0]["message"]
    assert json.loads((tmp_path / "s" / "session.json").read_text())["counts"]["bad_lines"] == 5
    assert "bad_line" in err and "Traceback" not in err
    # --strict stops at the first, exit 2, the session kept and closed as stopped
    assert live(src, "-o", tmp_path / "t", "--speed", "0", "--strict") == 2
    st_ = read_status(tmp_path / "t")
    assert st_["status"] == "stopped" and "line 101" in st_["message"]
    assert len((tmp_path / "t" / "samples.csv").read_text().splitlines()) == 100


# -- hostile lines ---------------------------------------------------------------------------------

LAYOUT = SampleLayout(HEADER.strip().split(","), 7, "s.csv")


@given(st.text(max_size=200))
def test_any_line_is_a_sample_or_one_located_error(text):
    try:
        s = LAYOUT.parse(text, 7)
    except InputError as exc:
        assert exc.path == "s.csv" and exc.line == 7
    else:
        assert len(s.q) == 7 and len(s.wrench) == 6


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=12, max_size=12))
def test_any_numbers_are_a_sample_or_one_located_error(values):
    try:
        s = LAYOUT.parse(",".join(repr(v) for v in values), 3)
    except InputError as exc:
        assert exc.line == 3 and exc.column in LAYOUT.header
    else:
        assert all(map(lambda v: abs(v) < 1e10, (s.t, *s.q, *s.wrench)))


@pytest.mark.parametrize("rate, said", [(100.0, True), (5000.0, True), (1000.0, False), (1400.0, False)])
def test_a_stated_rate_the_time_stamps_contradict_is_said_with_both_figures(tmp_path, capsys, rate, said):
    """--rate-Hz 100 on the example's 1 kHz stream (or 5000): every gap was judged against the stated period without a
    word (at 5000 Hz, 4 samples counted dropped a sample). One 'rate' event, printed and in events.csv, giving both
    figures: the stated rate and period, the time stamps' median interval and rate; within 1.5x, none. By a file
    (rows taken by arrays) and pushed one at a time the same."""
    from arm_model.live import Session
    (tmp_path / "samples.csv").write_text("".join(LINES[:301]))
    # without force columns (contacts by the trigger) the rows after the first are taken by arrays at once
    (tmp_path / "trigger.csv").write_text("".join(",".join(c for k, c in enumerate(r.rstrip("\n").split(","))
                                                           if k not in (8, 9, 10)) + "\n" for r in LINES[:301]))
    assert "fx_N" not in (tmp_path / "trigger.csv").read_text()
    events, err = [], ""
    for name, more in (("samples", []), ("trigger", ["--contact", "trigger"])):
        d = tmp_path / name
        assert main(["live", str(tmp_path / f"{name}.csv"), "--arm", "aacmm7", "--speed", "0", "--rate-Hz",
                     f"{rate:g}", *more, "-o", str(d)]) == 0
        err += capsys.readouterr().err
        events += [e["message"] for e in rows(d / "events.csv") if e["kind"] == "rate"]
    session = Session("aacmm7", rate=rate)
    events += [e.message for k in range(300) for e in session.push(k * 1e-3, (0.0,) * 7, (0.0, 0.0, 0.0))
               if e.kind == "rate"]
    assert len(events) == 3 * int(said), events
    if said:
        words = (f"the stated rate (--rate-Hz) {rate:g} Hz, a sample every {1e3 / rate:.4g} ms, contradicts the time "
                 "stamps: the median of their first 16 intervals is 1 ms (1000 Hz)")
        assert all(words in e for e in events) and err.count(words) == 2, err
