"""``aacmm tip`` on a large file reads it in parts in worker processes: the output, the summary and
every located error must be those of the serial run (the threshold is lowered here so that small files
take the parallel path)."""
from __future__ import annotations

import numpy as np
import pytest

import arm_model.csv_io as csvmod
import arm_model.parallel as par
from arm_model import InputError
from arm_model.cli import main
from arm_model.csv_io import csv_spans, iter_csv_blocks
from arm_model.model_file import load_model

Q = ",".join(f"q{i}_deg" for i in range(1, 8))
HEADER = f"measurement,feature,{Q},fx_N,fy_N,fz_N"


def rows(n: int, seed: int = 0) -> list[str]:
    desc = load_model("aacmm7").desc
    lo = np.degrees([j.lower for j in desc.joints])
    hi = np.degrees([j.upper for j in desc.joints])
    rng = np.random.default_rng(seed)
    q = rng.uniform(lo, hi, (n, 7))
    q[::97, 1] = hi[1] + 1.0                        # some beyond a joint limit: the warning lists them
    f = rng.normal(0, 1.5, (n, 3))
    f[::131, 2] = 80.0                             # some over the probe's force range
    return [",".join([f"m-{i // 40:03d}", "ring", *(f"{v:.6f}" for v in q[i]), *(f"{v:.4f}" for v in f[i])])
            for i in range(n)]


def run_tip(tmp_path, capsys, text: str, parallel: bool, name: str):
    src = tmp_path / "points.csv"
    src.write_bytes(text.encode())
    out = tmp_path / f"{name}.csv"
    code = main(["tip", str(src), "--arm", "aacmm7", "-o", str(out)])
    cap = capsys.readouterr()
    return code, (out.read_bytes() if out.exists() else None), cap.err


@pytest.fixture
def small_parts(monkeypatch):
    """Every file over 1 kB is read in parts (2 workers), or in one (``workers`` 1) for the reference."""
    monkeypatch.setattr(csvmod, "PARALLEL_BYTES", 1000)
    calls = []
    fork_map = par.fork_map

    def spy(func, arg_lists):
        calls.append(len(arg_lists))
        return fork_map(func, arg_lists)
    monkeypatch.setattr(par, "fork_map", spy)

    def use(n_workers: int) -> list:
        monkeypatch.setattr(par, "workers", lambda limit=2: n_workers)
        return calls
    return use


def test_parts_give_the_serial_output_and_summary(tmp_path, capsys, small_parts):
    text = "\ufeff" + HEADER + "\r\n\r\n" + "\r\n".join(rows(3000)) + "\r\n"
    assert csv_spans(_write(tmp_path / "x.csv", text), 2, 1000) is not None
    small_parts(1)
    ref = run_tip(tmp_path, capsys, text, False, "serial")
    calls = small_parts(2)
    assert calls == []
    got = run_tip(tmp_path, capsys, text, True, "parallel")
    assert calls == [2]
    assert ref[0] == got[0] == 0
    assert ref[1] == got[1]                         # byte-identical output
    assert ref[2] == got[2]                         # same summary, warnings and listed lines
    assert "over the probe's calibrated force range" in got[2] and "beyond" in got[2].lower()
    assert not list(tmp_path.glob(".*tmp*")), "a part file was left behind"


def _write(path, text):
    path.write_bytes(text.encode())
    return path


def test_spans_cover_the_file_in_whole_lines_after_the_header(tmp_path):
    text = "\n\n" + HEADER + "\n" + "\n".join(rows(500)) + "\n"
    path = _write(tmp_path / "p.csv", text)
    data = path.read_bytes()
    for parts in (2, 3, 5):
        (line, names), spans = csv_spans(path, parts, 100)
        assert line == 3 and names == HEADER.split(",")
        assert spans[0][0] == 0 and spans[-1][1] == len(data)
        assert all(a[1] == b[0] for a, b in zip(spans[:-1], spans[1:], strict=True))
        assert all(data[s - 1:s] == b"\n" for s, _ in spans[1:])
        # the parts' rows, with their physical lines, are the whole file's
        got = []
        for span in spans:
            for _, _, blk in iter_csv_blocks(path, "f", lambda h, ln: ([2, 3], [0]), 4096, None, span,
                                             None if span[0] == 0 else (line, names)):
                got += list(zip(blk.lines.tolist(), blk.texts[:, 0].tolist(), strict=True))
        whole = [(ln, t) for _, _, blk in iter_csv_blocks(path, "f", lambda h, ln: ([2, 3], [0]), 4096)
                 for ln, t in zip(blk.lines.tolist(), blk.texts[:, 0].tolist(), strict=True)]
        assert got == whole and len(whole) == 500 and whole[0][0] == 4


def test_small_or_odd_files_are_read_whole(tmp_path):
    assert csv_spans(_write(tmp_path / "a.csv", HEADER + "\n" + "\n".join(rows(10)) + "\n"), 2) is None
    assert csv_spans(_write(tmp_path / "b.csv", "\n" * 5000), 2, 100) is None          # no header
    assert csv_spans(tmp_path, 2, 0) is None                                             # a folder
    assert csv_spans(tmp_path / "missing.csv", 2, 0) is None


@pytest.mark.parametrize("where", ["first", "second", "both"])
def test_the_first_error_in_file_order_is_reported_and_nothing_written(tmp_path, capsys, small_parts, where):
    r = rows(3000)
    bad = {"first": [100], "second": [2500], "both": [2500, 100]}[where]
    for i in bad:
        cells = r[i].split(",")
        cells[4] = "x1"
        r[i] = ",".join(cells)
    text = HEADER + "\n" + "\n".join(r) + "\n"
    results = []
    for n in (1, 2):
        small_parts(n)
        code, out, err = run_tip(tmp_path, capsys, text, n == 2, f"o{n}")
        assert code == 2 and out is None and "Traceback" not in err
        results.append(err)
    assert results[0] == results[1]
    assert f"line {min(bad) + 2}" in results[1] and "column 'q3_deg'" in results[1]
    assert not [p for p in tmp_path.iterdir() if p.name != "points.csv"], "something was written"


def test_a_large_file_with_no_rows_is_an_error(tmp_path, capsys, small_parts):
    small_parts(2)
    code, out, err = run_tip(tmp_path, capsys, HEADER + "\n" + "\n" * 5000, True, "o")
    assert code == 2 and out is None and "no points after the header line" in err and "line 2" in err


def test_worker_errors_reach_the_parent_whole():
    """An InputError crosses the process boundary with its file, line and column; a worker killed
    without a result is reported, not waited for forever."""
    def fail(line):
        raise InputError("bad", "f.csv", line, "q1_deg")
    with pytest.raises(InputError) as exc:
        par.fork_map(fail, [(7,), (3,)])
    assert (exc.value.path, exc.value.line, exc.value.column) == ("f.csv", 7, "q1_deg")
    assert par.fork_map(lambda a, b: a + b, [(1, 2), (3, 4)]) == [3, 7]

    def die():
        import os
        os._exit(9)
    with pytest.raises(par.WorkerDied, match="exit code 9"):
        par.fork_map(die, [()])


def test_a_hysteresis_model_reads_the_file_whole(tmp_path, capsys, small_parts):
    """A point's last move (:class:`arm_model.effects.JointHysteresis`) is from the point captured before it, in any
    part of the file: such a model's points are read as one block, never in parts or blocks (the second part's first
    row took 0, its move from the first part's last row unseen: 71 um off here), and give Python's ``tip_table`` on
    the whole set."""
    from arm_model.commands import tip_table
    from arm_model.effects import JointHysteresis
    from arm_model.io import read_points
    from arm_model.model_file import Arm, format_model

    desc = load_model("aacmm7").desc
    effect = JointHysteresis(joints=(1, 3))
    model = tmp_path / "hyst.toml"
    model.write_text(format_model(desc, (effect,), {"j2.hysteresis": 1e-4, "j4.hysteresis": -5e-5}))
    src = _write(tmp_path / "points.csv", HEADER + "\n" + "\n".join(rows(400)) + "\n")
    calls = small_parts(2)
    out = tmp_path / "tips.csv"
    assert main(["tip", str(src), "--arm", str(model), "-o", str(out)]) == 0
    capsys.readouterr()
    assert calls == []                                     # one block
    got = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(5, 6, 7))
    arm = Arm(desc, (effect,), {"j2.hysteresis": 1e-4, "j4.hysteresis": -5e-5})
    want = tip_table(arm, read_points(src, desc.joint_quantities))
    assert np.max(np.abs(got - np.column_stack([want[f"{a}_mm"] for a in "xyz"]))) <= 1e-6   # the 6 decimals
