"""Start-up and file speed of the command line: ``aacmm --help``, ``aacmm tip`` on a 2-million-row points
file (wall time and peak memory of the process), ``aacmm ring`` with and without its 17 force-signal
files. Each command runs as its own process (what a user waits for)."""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
AACMM = [sys.executable, "-c", "import sys; from arm_model.cli import main; sys.exit(main())"]


def run(args, cwd=None) -> tuple[float, float]:
    """(wall seconds, peak RSS MiB) of one ``aacmm`` process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    r = subprocess.run(AACMM + list(map(str, args)), cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(r.stderr)
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(peak, before) / 1024.0


def points_file(path: Path, n: int, seed: int = 0) -> None:
    """A points file of ``n`` rows: 7 joint angles (6 decimals, deg), three-axis force (4 decimals, N)."""
    from arm_model._csv import format_csv
    rng = np.random.default_rng(seed)
    with open(path, "wb") as fh:
        for a in range(0, n, 500_000):
            m = min(500_000, n - a)
            cols = {"measurement": np.array([f"m-{i // 1000:05d}" for i in range(a, a + m)], dtype=object),
                    "feature": np.full(m, "ring", dtype=object)}
            q = rng.uniform(-170, 170, (m, 7))
            cols.update({f"q{j + 1}_deg": np.round(q[:, j], 6) for j in range(7)})
            f = rng.normal(0, 1.5, (m, 3))
            cols.update({k: np.round(f[:, j], 4) for j, k in enumerate(("fx_N", "fy_N", "fz_N"))})
            fh.write(format_csv(cols, {**{f"q{j + 1}_deg": "%.6f" for j in range(7)},
                                       "fx_N": "%.4f", "fy_N": "%.4f", "fz_N": "%.4f"}, header=a == 0))


def best(args, repeat=3, cwd=None):
    runs = [run(args, cwd) for _ in range(repeat)]
    return min(r[0] for r in runs), max(r[1] for r in runs)


def main(n_rows: int = 2_000_000) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t, mem = best(["--help"], repeat=5)
        print(f"aacmm --help: {t:.3f} s, peak {mem:.0f} MiB (best of 5)")
        out["help"] = (t, mem)
        pts = tmp / "big.csv"
        t0 = time.perf_counter()
        points_file(pts, n_rows)
        size = pts.stat().st_size
        print(f"points file: {n_rows:,d} rows, {size / 2**20:.0f} MiB, written in {time.perf_counter() - t0:.1f} s")
        t, mem = best(["tip", pts, "--arm", "aacmm7", "-o", tmp / "tips.csv"], repeat=2)
        print(f"aacmm tip, {n_rows:,d} rows: {t:.2f} s, peak {mem:.0f} MiB ({mem * 2**20 / n_rows:.0f} B a row)")
        out["tip"] = (t, mem)
        os.unlink(pts)
        os.unlink(tmp / "tips.csv")
        sim = tmp / "ring"
        subprocess.run(AACMM + ["simulate", str(ROOT / "examples" / "campaigns" / "paper-ring.toml"), "-o", str(sim)],
                       check=True, capture_output=True)
        base = ["ring", sim / "points.csv", sim / "artefacts.toml", "--arm", "aacmm7"]
        t_plain, _ = best(base + ["-o", tmp / "r1"])
        t_sig, _ = best(base + ["--signals", sim / "signals", "-o", tmp / "r2"])
        n_sig = sum(1 for _ in (sim / "signals").glob("*.csv"))
        print(f"aacmm ring (paper-ring, 17 x 72): {t_plain:.2f} s; with --signals ({n_sig} files): {t_sig:.2f} s "
              f"({t_sig / t_plain:.2f}x)")
        out["ring"] = (t_plain, t_sig)
    return out


if __name__ == "__main__":
    main()
