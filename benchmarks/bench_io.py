"""Start-up and file speed of the command line: ``aacmm --help``, ``aacmm tip`` on a 2-million-row points
file (wall time, CPU time and peak memory), ``aacmm ring`` with and without its 17 force-signal files.
Each command runs as its own process (what a user waits for); its CPU time (``os.wait4``) includes the
worker processes it forks (``aacmm tip`` reads a large file in parts, one a core, up to 2), its peak
memory is its own plus an upper bound for the workers (see ``_MEASURED``). The load average is printed:
on a shared machine the wall time grows with it, the CPU time much less.

``python -m benchmarks.bench_io [--quick]``: ``--quick`` uses a 200 000-row points file."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
QUICK = {"n_rows": 200_000}
AACMM = [sys.executable, "-c", "import sys; from arm_model.cli import main; sys.exit(main())"]
# the peak memory of the command: VmHWM of its own process at exit (the rusage of a child spawned from
# this large process also counts the parent's pages it was started from), plus, when it forked worker
# processes (``aacmm tip`` on a large file), their number times the largest worker's peak: an upper
# bound on the total (the workers share the parent's pages, which this counts again for each)
_MEASURED = [sys.executable, "-c", """
import os, resource, sys
from arm_model.cli import main
try:
    rc = main(sys.argv[1:])
finally:
    hwm = [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM:')]
    from arm_model.parallel import workers
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    open(os.environ['AACMM_BENCH_HWM'], 'w').write(str(int(hwm[0]) + workers() * child) if hwm else '')
sys.exit(rc)
"""]


def run(args, cwd=None, one_core: bool = False) -> tuple[float, float, float]:
    """(wall s, CPU s (user + system, its worker processes included), peak RSS MiB) of one ``aacmm``
    process."""
    with tempfile.TemporaryFile() as err, tempfile.NamedTemporaryFile("r") as hwm:
        t = time.perf_counter()
        # one_core: the command may run on one core only, so it takes its serial path
        pin = (lambda: os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})) if one_core else None
        p = subprocess.Popen(_MEASURED + list(map(str, args)), cwd=cwd, stdout=subprocess.DEVNULL, stderr=err,
                             env={**os.environ, "AACMM_BENCH_HWM": hwm.name}, preexec_fn=pin)
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"aacmm {' '.join(map(str, args))} failed:\n{err.read().decode()}")
        peak = float(hwm.read() or "nan") / 1024.0
    return wall, ru.ru_utime + ru.ru_stime, peak


def best(args, repeat=3, cwd=None, one_core: bool = False) -> tuple[float, float, float]:
    """The fastest of ``repeat`` runs by wall time (wall, its CPU time, the largest peak RSS)."""
    runs = [run(args, cwd, one_core) for _ in range(repeat)]
    fastest = min(runs)
    return fastest[0], fastest[1], max(r[2] for r in runs)


def points_file(path: Path, n: int, seed: int = 0) -> None:
    """A points file of ``n`` rows, 1000 a measurement: 7 joint angles inside the shipped arm's limits
    (6 decimals, deg), three-axis force (4 decimals, N)."""
    from arm_model.csv_io import format_csv
    from arm_model.model_file import load_model
    desc = load_model("aacmm7").desc
    low = np.array([np.degrees(j.lower) for j in desc.joints])
    high = np.array([np.degrees(j.upper) for j in desc.joints])
    rng = np.random.default_rng(seed)
    fmt = {**{f"q{j + 1}_deg": "%.6f" for j in range(7)}, "fx_N": "%.4f", "fy_N": "%.4f", "fz_N": "%.4f"}
    with open(path, "wb") as fh:
        for a in range(0, n, 500_000):
            m = min(500_000, n - a)
            cols = {"measurement": np.array([f"m-{i // 1000:05d}" for i in range(a, a + m)], dtype=object),
                    "feature": np.full(m, "ring", dtype=object)}
            q = rng.uniform(low, high, (m, 7))
            cols.update({f"q{j + 1}_deg": q[:, j] for j in range(7)})
            f = rng.normal(0, 1.5, (m, 3))
            cols.update({k: f[:, j] for j, k in enumerate(("fx_N", "fy_N", "fz_N"))})
            fh.write(format_csv(cols, fmt, header=a == 0))


def phases(path: Path) -> dict:
    """CPU time [s] of each phase of ``aacmm tip`` on ``path``, read whole in this process: reading the
    points, the rigid and corrected centres, formatting, writing (the start-up is in the whole command's
    figures)."""
    from arm_model.commands import tip_table
    from arm_model.csv_io import format_csv
    from arm_model.io import iter_points
    from arm_model.model_file import load_model
    t = {"reading": 0.0, "centres": 0.0, "formatting": 0.0, "writing": 0.0}
    arm = load_model("aacmm7")
    blocks = iter_points(path, arm.desc.n_joints)
    with tempfile.TemporaryFile() as fh:
        while True:
            c = time.process_time()
            block = next(blocks, None)
            t["reading"] += time.process_time() - c
            if block is None:
                break
            c = time.process_time()
            cols = tip_table(arm, block)
            c2 = time.process_time()
            text = format_csv(cols, "%.6f", header=fh.tell() == 0)
            c3 = time.process_time()
            fh.write(text)
            c4 = time.process_time()
            t["centres"] += c2 - c
            t["formatting"] += c3 - c2
            t["writing"] += c4 - c3
    return t


def load() -> str:
    return "load average " + " ".join(f"{v:.1f}" for v in os.getloadavg())


def main(n_rows: int = 2_000_000) -> dict:
    out = {}
    print(f"{os.cpu_count()} cores; {load()} at the start")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t, cpu, mem = best(["--help"], repeat=5)
        print(f"aacmm --help: {t:.3f} s wall, {cpu:.3f} s CPU, peak {mem:.0f} MiB (best of 5)")
        out["help"] = (t, cpu, mem)
        pts = tmp / "big.csv"
        t0 = time.perf_counter()
        points_file(pts, n_rows)
        size = pts.stat().st_size
        print(f"points file: {n_rows:,d} rows, {size / 2**20:.0f} MiB, written in {time.perf_counter() - t0:.1f} s")
        t, cpu, mem = best(["tip", pts, "--arm", "aacmm7", "-o", tmp / "tips.csv"], repeat=2)
        print(f"aacmm tip, {n_rows:,d} rows: {t:.2f} s wall, {cpu:.2f} s CPU, peak {mem:.0f} MiB "
              f"({mem * 2**20 / n_rows:.0f} B a row; best of 2; {load()})")
        out["tip"] = (t, cpu, mem)
        if hasattr(os, "sched_setaffinity"):
            t, cpu, mem = best(["tip", pts, "--arm", "aacmm7", "-o", tmp / "tips-serial.csv"], repeat=2, one_core=True)
            same = (tmp / "tips.csv").read_bytes() == (tmp / "tips-serial.csv").read_bytes()
            print(f"aacmm tip on one core (the file read whole): {t:.2f} s wall, {cpu:.2f} s CPU, peak {mem:.0f} MiB "
                  f"(best of 2); output {'byte-identical' if same else 'DIFFERENT'} ({load()})")
            out["tip_one_core"] = (t, cpu, mem)
            os.unlink(tmp / "tips-serial.csv")
            out["tip_phases"] = phases(pts)
            print("aacmm tip's CPU time by phase, the file read whole in this process: "
                  + ", ".join(f"{k} {v:.2f} s" for k, v in out["tip_phases"].items()))
        os.unlink(pts)
        os.unlink(tmp / "tips.csv")
        sim = tmp / "ring"
        subprocess.run(AACMM + ["simulate", str(ROOT / "examples" / "campaigns" / "paper-ring.toml"), "-o", str(sim)],
                       check=True, capture_output=True)
        base = ["ring", sim / "points.csv", sim / "artefacts.toml", "--arm", "aacmm7"]
        plain = best(base + ["-o", tmp / "r1"])
        sig = best(base + ["--signals", sim / "signals", "-o", tmp / "r2"])
        n_sig = sum(1 for _ in (sim / "signals").glob("*.csv"))
        print(f"aacmm ring (paper-ring, 17 x 72): {plain[0]:.2f} s wall, {plain[1]:.2f} s CPU; with --signals "
              f"({n_sig} files): {sig[0]:.2f} s wall, {sig[1]:.2f} s CPU; ratio {sig[0] / plain[0]:.2f} wall, "
              f"{sig[1] / plain[1]:.2f} CPU (goal <= 1.5; best of 3; {load()})")
        out["ring"] = (plain, sig)
    return out


if __name__ == "__main__":
    main(**(QUICK if "--quick" in sys.argv[1:] else {}))
