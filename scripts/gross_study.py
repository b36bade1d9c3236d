#!/usr/bin/env python3
"""Gross errors found on small simulated artefact sessions: the default (points and certified lengths left out at
``--gross-threshold`` 6) and ``--drop-outliers`` (dropped at ``--outlier-threshold`` 4), docs/studies/calibration.md
("Certified lengths and --drop-outliers on the same test").

Each seed is a session of the nominal arm (66 points: three ball-bar placements of one 500 mm length with a
0.8 um certificate, five points a sphere; three seats of 8 articulations; a 12-point sphere; 2 um noise),
fitted clean, then with one blunder at a time:

* ``length``: in the first placement, the bar's B end moved along the bar by ``size`` certificate sigmas
  (0.8 um each) between the probing of its two ends, by the simulator's inverse kinematics on the true arm (its
  sphere points stay consistent: only the length is wrong);
* ``seat``: one seat point's shoulder angle off by ``size`` noise sigmas of ball displacement.

Per run: what each option left out (kind, measurement, point, standardized equivalent). Summarised with
``--summary``: per case and size, the blunders found and the other points or lengths removed.

    python scripts/gross_study.py -o out/gross.json --seeds 0-10
    python scripts/gross_study.py --summary out/gross.json
"""
from __future__ import annotations

import argparse
import collections
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from arm_model import NumericalError, load_description  # noqa: E402
from arm_model.errors import InputError  # noqa: E402
from arm_model.model import ArmModel  # noqa: E402
from arm_model.sim.ik import solve_positions  # noqa: E402
from arm_model.sim.quick import SynthSpec, make_campaign  # noqa: E402
from calibration import FitOptions, calibrate, make_data  # noqa: E402

SESSION = SynthSpec(ballbars=3, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=12, rings=0,
                    planes=0, reference_points=0, force=0.0, noise=2e-6)
OPTIONS = {"default": FitOptions(), "drop": FitOptions(drop_outliers=True, gross_threshold=None)}
LENGTH_SIZES = (8, 20, 40, 100)
SEAT_SIZES = (8, 12, 20, 40)


def moved_end(model, c, size, rng):
    """The points of ``c`` with the first placement's B end moved ``size`` certificate sigmas along the bar."""
    pts = c.points
    m = sorted({m for m, f in zip(pts.measurement, pts.feature, strict=True) if f == "bar-B"})[0]
    a, b = ((pts.measurement == m) & (pts.feature == f) for f in ("bar-A", "bar-B"))
    xa, xb = (model.ball_centres(pts.q[s], None, c.p_true) for s in (a, b))
    u = xb.mean(axis=0) - xa.mean(axis=0)
    q = pts.q.copy()
    q[b] = solve_positions(model, c.p_true, xb + size * SESSION.u_length * u / np.linalg.norm(u), rng)[0]
    return replace(pts, q=q), m


def off_seat(model, c, size, bad):
    """The points of ``c`` with point ``bad``'s shoulder angle ``size`` noise sigmas of ball displacement off."""
    q0 = c.points.q[bad:bad + 1]
    q1 = q0.copy()
    q1[0, 1] += 1e-4
    d0 = float(np.linalg.norm(model.ball_centres(q1, None, c.p_true) - model.ball_centres(q0, None, c.p_true)))
    q = c.points.q.copy()
    q[bad, 1] += 1e-4 * size * SESSION.noise / d0
    return replace(c.points, q=q)


def left_out(model, data) -> dict:
    """What each of :data:`OPTIONS` leaves out of ``data`` (or its error)."""
    out: dict = {}
    for name, opt in OPTIONS.items():
        try:
            res = calibrate(model, data, opt)
        except (InputError, NumericalError) as exc:
            out[name] = {"error": str(exc)[:200]}
            continue
        out[name] = {"removed": [(o.kind, o.measurement, o.point, round(o.standardized, 2))
                                 for o in [g.outlier for g in res.gross] + list(res.dropped)]}
    return out


def run(seeds) -> list[dict]:
    model = ArmModel(load_description(ROOT / "urdf" / "aacmm7.dh.toml"))
    rows = []
    for seed in seeds:
        rng = np.random.default_rng(2000 + seed)
        c = make_campaign(model, SESSION, seed=seed)
        rows.append({"seed": seed, "case": "clean", "size": 0, "bad": None,
                     **left_out(model, make_data(c.points, c.artefacts, model))})
        for size in LENGTH_SIZES:
            pts, m = moved_end(model, c, size, rng)
            rows.append({"seed": seed, "case": "length", "size": size, "bad": m,
                         **left_out(model, make_data(pts, c.artefacts, model))})
        bad = int(rng.choice(np.flatnonzero(c.points.feature == "seat")))
        for size in SEAT_SIZES:
            rows.append({"seed": seed, "case": "seat", "size": size, "bad": bad,
                         **left_out(model, make_data(off_seat(model, c, size, bad), c.artefacts, model))})
        print(f"seed {seed} done", flush=True)
    return rows


def summary(rows) -> list[str]:
    """Per case and size and option: blunders found / runs, other points or lengths removed, runs refused."""
    agg = collections.defaultdict(list)
    for x in rows:
        agg[(x["case"], x["size"])].append(x)
    lines = []
    for (case, size), runs in sorted(agg.items()):
        line = f"{case:7s} {size:4d}"
        for opt in OPTIONS:
            found = other = refused = 0
            for x in runs:
                if "error" in x[opt]:
                    refused += 1
                    continue
                hit = [(r[0] == "distance" and r[1] == x["bad"]) if case == "length" else r[2] == x["bad"]
                       for r in x[opt]["removed"]]
                found += any(hit)
                other += hit.count(False)
            line += f" | {opt}: found {found}/{len(runs)}, others removed {other}, refused {refused}"
        lines.append(line)
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--output", type=Path, help="JSON file of every run")
    p.add_argument("--seeds", default="0-10", help="seeds FIRST-END (END excluded)")
    p.add_argument("--summary", type=Path, help="summarise a JSON file written before (no fits)")
    args = p.parse_args(argv)
    if args.summary is not None:
        rows = json.loads(args.summary.read_text())
    else:
        first, end = (int(v) for v in args.seeds.split("-"))
        rows = run(range(first, end))
        if args.output is not None:
            args.output.parent.mkdir(parents=True, exist_ok=True)
            args.output.write_text(json.dumps(rows))
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
