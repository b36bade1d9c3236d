"""`make demo`: the main jobs of the toolkit on bundled data, one after the other, through the CLI.

1. `aacmm tip` on the bundled paper-like ring campaign (deflection-corrected ball centres);
2. `aacmm ring` on it (the paper's pipeline and the full-wrench correction, HTML report);
3. `aacmm paper`: the seed paper's Tables 1-3 from its own measured data, and its loop closed;
4. `aacmm simulate` + `aacmm ring --signals` on the paper's two-channel campaign (force peaks from 1 kHz signals);
5. `aacmm simulate` + `aacmm calibrate` on a calibration campaign (ball bar, seats, sphere, plane, tracker);
6. `aacmm view --html` of one ring point (self-contained meshcat page);
7. `aacmm close-loop` on a bundled campaign with a hidden effect, printing the before/after table.
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

from .cli import main as aacmm

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "urdf" / "aacmm7.dh.toml"
DATA = ROOT / "examples" / "data"
CAMPAIGNS = ROOT / "examples" / "campaigns"


def _step(title: str, argv: list[str]) -> None:
    print(f"\n=== {title}\n$ aacmm {' '.join(argv)}", flush=True)
    t = time.perf_counter()
    code = aacmm(argv)
    if code:
        raise SystemExit(f"demo: step '{title}' failed with exit code {code}")
    print(f"({time.perf_counter() - t:.1f} s)", flush=True)


def _on_campaign(command: str, folder: Path, options: list[str], out: Path) -> list[str]:
    """The arguments of ``command`` on a simulated campaign's files (its reference points when it has them)."""
    ref = folder / "points-ref.csv"
    return ([command, str(folder / "points.csv"), str(folder / "artefacts.toml")]
            + (["--reference-points", str(ref)] if ref.exists() else [])
            + ["--arm", str(ARM), *options, "-o", str(out)])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m arm_model.demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    args = ap.parse_args(argv)
    out = args.out
    ring = DATA / "paper-ring-xyz"
    _step("1. deflection-corrected ball centres", ["tip", str(ring / "points.csv"), "--arm", str(ARM),
                                                 "-o", str(out / "tips.csv")])
    _step("2. ring-gauge pipeline: paper's four models vs full-wrench correction",
          ["ring", str(ring / "points.csv"), str(ring / "artefacts.toml"), "--arm", str(ARM), "-o", str(out / "ring")])
    _step("3. the seed paper's own data: Tables 1-3 and the loop closed", ["paper", "-o", str(out / "paper")])
    _step("4a. simulate the paper's campaign (two-channel sensor, 1 kHz signals)",
          ["simulate", str(CAMPAIGNS / "paper-ring.toml"), "-o", str(out / "sim-paper-ring"), "-q"])
    sim = out / "sim-paper-ring"
    _step("4b. ring pipeline from the force signals",
          ["ring", str(sim / "points.csv"), str(sim / "artefacts.toml"), "--arm", str(ARM), "--signals",
           str(sim / "signals"), "-o", str(out / "ring-signals")])
    _step("5a. simulate a calibration campaign", ["simulate", str(CAMPAIGNS / "calibration.toml"), "-o",
                                                 str(out / "sim-calibration"), "-q", "--no-signals"])
    cal = out / "sim-calibration"
    _step("5b. kinematic calibration with held-out validation",
          _on_campaign("calibrate", cal, ["--holdout", "0.25"], out / "calibration"))
    _step("6. the arm at a ring point, as a static meshcat page",
          ["view", str(ring / "points.csv"), "--arm", str(ARM), "--artefacts", str(ring / "artefacts.toml"),
           "--measurement", "ring-01", "--point", "5", "--html", str(out / "view.html")])
    loop_campaign = CAMPAIGNS / "loop-demo.toml"
    if importlib.util.find_spec("calibration.loop_cli") is not None and loop_campaign.exists():
        _step("7a. simulate a campaign with an effect the model does not declare",
              ["simulate", str(loop_campaign), "-o", str(out / "sim-loop"), "-q", "--no-signals"])
        lp = out / "sim-loop"
        _step("7b. close the loop: calibrate, diagnose, add the effect, report before/after",
              _on_campaign("close-loop", lp, ["--sigma-probe-um", "2"], out / "close-loop"))
    print(f"\ndemo done: reports in {out}/ (ring/report.html, paper/report.html, calibration/report.html, "
          f"view.html{', close-loop/report.html' if (out / 'close-loop').exists() else ''})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
