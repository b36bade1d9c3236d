"""Samples taken in blocks (``Session.push_block``, what ``aacmm live`` does with the lines that came together) against
the same samples pushed one at a time (``Session.push_sample``, the reference): the same outputs in the same order
(events, contacts, points, fits), the same state (counts, thresholds, noise, the joints' last moves) and the same
session files byte for byte (``contacts.csv`` less its latency column, which is timing), on the bundled session and
on generated streams with contacts, bumps, over-forces, joint limits, gaps, late samples, bad time stamps, clock
jumps and bad lines, cut into blocks of every size. Also the block readers against the line readers
(``SampleLayout.parse_block`` / ``parse``, ``chunk_texts`` / ``line_text``)."""
from __future__ import annotations

import csv
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, Phase, given, settings, strategies as st

from arm_model import InputError
from arm_model.live import ContactOptions, Event, FeatureFit, LivePoint, SampleLayout, Session
from arm_model.live.motion import NOISE_SAMPLES, LastMove
from arm_model.live.sources import chunk_texts, line_text
from arm_model.model_file import load_model
from conftest import ROOT

SAMPLES = ROOT / "examples" / "live" / "samples.csv"
LINES = SAMPLES.read_text().splitlines()
HEADER = LINES[0].split(",")
ARM = load_model("aacmm7", None)
FILES = ("samples", "points", "tips", "events", "features")


def norm(item) -> tuple:
    """What an output says, exactly (a point's latency left out: it is timing)."""
    if isinstance(item, LivePoint):
        return ("point", item.index, item.contact, item.feature, item.rigid.tobytes(), item.corrected.tobytes(),
                item.u.tobytes(), item.cov.tobytes(), item.over_force, item.beyond_limits,
                repr({k: np.asarray(v).tolist() for k, v in item.row.items()}))
    if isinstance(item, FeatureFit):
        return ("fit", repr(item.row(0)))
    assert isinstance(item, Event) or type(item).__name__ == "Contact"
    return ("item", item)


def session(folder: Path, source: str, rate: float | None) -> Session:
    return Session(ARM, folder, layout=SampleLayout(HEADER, 7, "s.csv"), contact=ContactOptions(source=source),
                   measurement="m", rate=rate)


def one_by_one(texts: list[str], folder: Path, source: str = "force", rate: float | None = None) -> tuple:
    s = session(folder, source, rate)
    out = []
    for no, text in enumerate(texts, start=2):
        try:
            smp = s.layout.parse(text, no)
        except InputError as exc:
            out.append(s.bad_line(exc))
            continue
        out += s.push_sample(smp, text, no)
    out += s.close()
    return s, out


def in_blocks(texts: list[str], folder: Path, sizes: list[int], source: str = "force",
              rate: float | None = None) -> tuple:
    s = session(folder, source, rate)
    out, k, i = [], 0, 0
    while k < len(texts):
        n = sizes[i % len(sizes)]
        i += 1
        for item in s.layout.parse_block(texts[k:k + n], list(range(k + 2, k + n + 2))):
            out += [s.bad_line(item)] if isinstance(item, InputError) else s.push_block(item)
        k += n
    out += s.close()
    return s, out


def assert_same(a: tuple, b: tuple) -> None:
    (sa, oa), (sb, ob) = a, b
    assert [norm(x) for x in oa] == [norm(x) for x in ob]
    assert sa.counts == sb.counts and sa.thresholds() == sb.thresholds()
    assert repr(sa.noise()) == repr(sb.noise()) and sa.latest == sb.latest
    assert repr(sa._last_move_status()) == repr(sb._last_move_status()) and sa._moves.sign == sb._moves.sign
    fa, fb = sa.record.folder, sb.record.folder
    for role in FILES:
        pa, pb = fa / f"{role}.csv", fb / f"{role}.csv"
        assert pa.exists() == pb.exists(), role
        if pa.exists():
            assert pa.read_bytes() == pb.read_bytes(), role
    with open(fa / "contacts.csv") as ca, open(fb / "contacts.csv") as cb:
        assert [r[:-1] for r in csv.reader(ca)] == [r[:-1] for r in csv.reader(cb)]


def test_the_bundled_session_in_blocks_is_the_session_one_by_one(tmp_path):
    texts = LINES[1:]
    ref = one_by_one(texts, tmp_path / "one")
    assert ref[0].counts["points"] == 19 and ref[0].counts["over_force"] == 1
    sizes = [int(n) for n in np.random.default_rng(1).choice([1, 2, 5, 64, 700, 1024, 5000], 40)]
    assert_same(ref, in_blocks(texts, tmp_path / "blocks", sizes))
    assert_same(ref, in_blocks(texts, tmp_path / "whole", [len(texts)]))


def stream(seed: int, n: int, touches: int, faults: list[str]) -> list[str]:
    """A 1 kHz stream of ``n`` samples (the bundled arm's first pose, joints wandering back and forth, a force sensor
    with noise and a drifting offset, the trigger held in each touch), ``touches`` touches (some too short, one
    perhaps beyond the probe's range) and ``faults``: "gap", "late", "bad_time", "jump_back", "jump_ahead",
    "limit", "bad_line"."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.001 + rng.uniform(0, 5)
    q0 = np.array([float(x) for x in LINES[1].split(",")[1:8]])
    k = np.arange(n)[:, None]
    q = q0 + rng.uniform(0.05, 2, 7) * np.sin(2 * np.pi * k / rng.uniform(80, 900, 7) + rng.uniform(0, 6, 7))
    q += np.cumsum(rng.normal(0, 0.002, (n, 7)), axis=0)
    f = rng.normal(0, 0.03, (n, 3)) + rng.uniform(-0.2, 0.2, 3) + np.linspace(0, rng.uniform(-0.1, 0.1), n)[:, None]
    trig = np.zeros(n, int)
    for _ in range(touches):
        a, d = int(rng.integers(130, n - 40)), int(rng.integers(5, 160))
        peak = rng.choice([0.15, 1.0, 4.0, 14.0, 30.0])
        u = rng.normal(size=3)
        f[a:a + d] += np.outer(peak * np.sin(np.linspace(0, np.pi, len(f[a:a + d]))), u / np.linalg.norm(u))
        trig[a:a + d] = 1
    if "limit" in faults:
        a = int(rng.integers(120, n - 20))
        q[a:a + int(rng.integers(1, 60)), 5] = -120.5
    lines = [f"{ti:.3f}," + ",".join(f"{x:.4f}" for x in qi) + "," + ",".join(f"{x:.6f}" for x in fi) + f",{g}"
             for ti, qi, fi, g in zip(t, q, f, trig, strict=True)]
    cells = [line.split(",", 1) for line in lines]

    def retime(i: int, new: float) -> None:
        cells[i][0] = f"{new:.3f}"
    for fault in faults:
        i = int(rng.integers(30, n - 10))
        if fault == "gap":
            del cells[i:i + int(rng.integers(1, 40))]
        elif fault == "late":
            retime(i, float(cells[i - 2][0]))
        elif fault == "bad_time":
            retime(i, float(cells[i][0]) + rng.choice([1e6, -50.0]))
        elif fault in ("jump_back", "jump_ahead"):
            shift = -0.3 if fault == "jump_back" else 7.0
            for j in range(i, len(cells)):
                retime(j, float(cells[j][0]) + shift)
        elif fault == "bad_line":
            cells[i][1] = rng.choice(["nan,1,2", "x" + cells[i][1], cells[i][1] + ",1", "1e999" + cells[i][1][1:]])
    return [",".join(c) for c in cells]


FAULTS = ["gap", "late", "bad_time", "jump_back", "jump_ahead", "limit", "bad_line"]


# no shrinking: an example is a whole session (a failure is reported as drawn)
@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow],
          phases=[Phase.explicit, Phase.reuse, Phase.generate])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(300, 1500), touches=st.integers(1, 5),
       faults=st.lists(st.sampled_from(FAULTS), max_size=4), trigger=st.booleans(), rate=st.booleans(),
       sizes=st.lists(st.integers(1, 400), min_size=1, max_size=8))
def test_generated_streams_in_blocks_are_the_streams_one_by_one(seed, n, touches, faults, trigger, rate, sizes):
    texts = stream(seed, n, touches, faults)
    source, hz = ("trigger" if trigger else "force"), (1000.0 if rate else None)
    with tempfile.TemporaryDirectory() as tmp:
        assert_same(one_by_one(texts, Path(tmp) / "one", source, hz),
                    in_blocks(texts, Path(tmp) / "blocks", sizes, source, hz))


SAMPLE_LINE = st.sampled_from(LINES[1:200])
NUMBERS = st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=11, max_size=13).map(
    lambda v: ",".join(map(repr, v)))
ANY_LINE = st.one_of(SAMPLE_LINE, SAMPLE_LINE, NUMBERS, st.text(max_size=60).filter(lambda x: "\n" not in x))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.lists(ANY_LINE, min_size=1, max_size=12))
def test_a_block_reads_as_its_lines(texts):
    layout = SampleLayout(HEADER, 7, "s.csv")
    got = []
    for item in layout.parse_block(texts, list(range(5, 5 + len(texts)))):
        got += [("error", str(item), item.line, item.column)] if isinstance(item, InputError) else \
            [("sample", repr(item.sample(k)), item.lines[k], item.texts[k]) for k in range(item.n)]
    want = []
    for no, text in enumerate(texts, start=5):
        try:
            want.append(("sample", repr(layout.parse(text, no)), no, text))
        except InputError as exc:
            want.append(("error", str(exc), exc.line, exc.column))
    assert got == want


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.lists(st.one_of(st.sampled_from([x.encode() for x in LINES[1:50]]),
                          st.binary(max_size=30).map(lambda b: b.replace(b"\n", b""))), min_size=1, max_size=10))
def test_a_chunk_decodes_as_its_lines(raws):
    chunk = list(enumerate(raws, start=3))
    want = []
    for no, raw in chunk:
        try:
            want.append((no, line_text(raw, "s", no)))
        except InputError as exc:
            want.append(str(exc))
    assert [x if isinstance(x, tuple) else str(x) for x in chunk_texts(chunk, "s")] == want


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(-4, 4), st.integers(-4, 4), st.booleans()), min_size=1, max_size=80),
       st.lists(st.integers(1, 30), min_size=1, max_size=5), st.floats(0, 3), st.integers(0, 2))
def test_moves_in_rows_are_the_moves_one_by_one(steps, cuts, band, first):
    """Readings on a grid (whole steps, so that a reading lands exactly on its band: the ties), in and out of
    contact, in rows cut anywhere: the same signs, ends, band and noise as sample by sample."""
    q = np.cumsum([[a, b] for a, b, _ in steps], axis=0).astype(float)
    held = np.array([h for _, _, h in steps])
    one, rows = LastMove([band / 3, 1.0]), LastMove([band / 3, 1.0])
    one.sign = rows.sign = [float(first - 1), 0.0]
    for x, h in zip(q.tolist(), held, strict=True):
        (one.held if h else one.free)(x)
    k, i = 0, 0
    while k < len(q):
        n = cuts[i % len(cuts)]
        rows.follow(q[k:k + n], held[k:k + n])
        k, i = k + n, i + 1
    assert one.sign == rows.sign and one._end == rows._end and one._held == rows._held
    m = min(one._n_diffs, NOISE_SAMPLES)
    assert one._n_diffs == rows._n_diffs and sorted(map(tuple, one._diffs[:m])) == sorted(map(tuple, rows._diffs[:m]))
    one.settle()
    rows.settle()
    assert one.band == rows.band
