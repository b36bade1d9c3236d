"""`make demo`: the main jobs of the toolkit on bundled data, one after the other, through the CLI.

0. `aacmm live --view` replays the bundled live session (examples/live/) at real time in the background,
   while the other steps run: open the URL it prints to watch the points come (a minute at most);
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
from .cli_options import output_path
from .shipped import shipped_path

# the shipped files: the checkout's, or an installed wheel's copy (`python -m arm_model.demo` after a pip install)
ARM = shipped_path("urdf/aacmm7.dh.toml")
DATA = shipped_path("examples/data")
CAMPAIGNS = shipped_path("examples/campaigns")


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


LIVE = shipped_path("examples/live")


def _start_live(out: Path):
    """Step 0: ``aacmm live`` on the bundled session with its live view, in the background (a child
    process writing to ``out/live.log``); returns (process, log) once it printed its URL, or (None, log)."""
    import subprocess
    log = out / "live.log"
    out.mkdir(parents=True, exist_ok=True)
    session = out / "live"
    if session.exists():
        import shutil
        if (session / "session.json").exists():
            shutil.rmtree(session)      # the demo's own earlier session, replaced (a demo, not a measurement)
    cmd = [sys.executable, "-m", "arm_model.cli", "live", str(LIVE / "samples.csv"), "--arm", str(ARM), "--plan",
           str(LIVE / "plan.toml"), "-o", str(session), "--view", "--linger-s", "120"]
    print(f"\n=== 0. a live measurement session, replayed at real time in the background\n$ aacmm "
          f"{' '.join(cmd[3:])}", flush=True)
    fh = open(log, "w")
    proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT)   # -o relative to this folder
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        text = log.read_text()
        if "live view: " in text:
            url = text.split("live view: ", 1)[1].split()[0]
            print(f"open {url} now: the arm, its force and the points as they come (14 s, then the last view "
                  f"stays until the demo ends); the session is recorded in {session}/", flush=True)
            return proc, log
        time.sleep(0.2)
    print(f"(the live session did not start its view: see {log})", flush=True)
    return proc, log


def _end_live(proc, log: Path | None) -> None:
    import signal
    if proc is None or log is None:
        return
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)     # the replay is over by now: only its view lingers
    proc.wait(timeout=60)
    lines = [x for x in log.read_text().splitlines() if " samples, " in x or "over_force" in x]
    print("\n=== 0. the live session: " + ("; ".join(lines) if lines else f"see {log}"), flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m arm_model.demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=output_path, default=Path("out/demo"), help="output folder (default out/demo)")
    ap.add_argument("--no-live", action="store_true", help="leave out step 0 (the live session and its view)")
    args = ap.parse_args(argv)
    out = args.out
    live, live_log = _start_live(out) if not args.no_live else (None, None)
    try:
        _steps(out)
    finally:
        _end_live(live, live_log)
    print(f"\ndemo done: reports in {out}/ (ring/report.html, paper/report.html, calibration/report.html, "
          f"view.html{', close-loop/report.html' if (out / 'close-loop').exists() else ''}"
          f"{', live/ (the live session) and live/view.html' if live is not None else ''})")
    return 0


def _steps(out: Path) -> None:
    """Steps 1-7 (see the module doc)."""
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


if __name__ == "__main__":
    sys.exit(main())
