#!/usr/bin/env python3
"""Honesty of the closed loop on clean simulated campaigns (no effect hidden in the truth): over seeds, how
often it adds an effect (library or built from the residual), builds an effect from the residual at all, and
claims structured residual. Each seed is a new campaign (``aacmm simulate``: random base errors, operator,
noise), analysed by ``close_loop`` with its defaults (effects built from the residual on) and ``cv_top=2``.

    python scripts/honesty_study.py                          # 20 seeds, the synthesis-test shape (about 3 min)
    python scripts/honesty_study.py --shape tiny --seeds 0-19 -o out/honesty

Shapes (probing noise 2 um, the temperature drifting 8 K/h with a 5-min gap between measurements, so 9 K
(tiny) to 17 K (synthesis) over the campaign, and a 3 N mean contact force, so the thermal, force and approach families
have something to look at):

* ``synthesis``: 280 points, 26 measurements (12 ball-bar positions of 5 points a sphere, 4 seats of 10
  articulations, 10 spheres of 12 points), the size of tests/test_loop_synthesis.py;
* ``tiny``: 100 points, 14 measurements (tests/test_loop_honesty.py's tasks);
* ``quick``: tests/test_loop_synthesis.py's own campaigns (the simulator's fast path, 280 points, random base
  errors of the seed, 3 N mean force, no temperature column), its clean reference.

``--no-thermometer`` drops the temperature column of the simulated shapes (``time_s`` kept; the truth's links do
not grow): the campaigns on which the loop offers a drift of the links in time (``thermal drift (time)``).

Writes ``results.json`` (one row a seed) into ``-o`` and prints the counts.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SHAPES = {
    "synthesis": [{"kind": "ballbar", "positions": 12, "length_mm": 600.0, "points_per_sphere": 5},
                  {"kind": "seat", "articulations": 10, "measurements": 4},
                  {"kind": "sphere", "points": 12, "measurements": 10}],
    "tiny": [{"kind": "ballbar", "positions": 6, "length_mm": 600.0, "points_per_sphere": 4},
             {"kind": "seat", "articulations": 6, "measurements": 4},
             {"kind": "sphere", "points": 7, "measurements": 4}],
}


#: the quick shape: tests/test_loop_synthesis.py's SPEC with a 3 N force
QUICK = dict(ballbars=12, ballbar_points=5, seats=4, articulations=10, spheres=10, sphere_points=12, noise=2e-6,
             force=3.0)


def _campaign(seed: int, shape: str):
    """(points, artefacts, nominal description) of one clean campaign."""
    import numpy as np

    if shape == "quick":
        from arm_model import load_description
        from arm_model.model import ArmModel
        from arm_model.sim.quick import SynthSpec, make_campaign, random_truth

        nominal = load_description(ROOT / "urdf" / "aacmm7.dh.toml")
        truth = ArmModel(nominal)
        p = random_truth(truth, np.random.default_rng(seed), length=30e-6, angle=5e-5, probe=30e-6)
        camp = make_campaign(truth, SynthSpec(**QUICK), seed=seed, p_true=p)
        return camp.points, camp.artefacts, nominal
    from arm_model.sim import campaign_from_dict, simulate

    camp = campaign_from_dict({"seed": seed, "sensor": "xyz", "signals": {"enabled": False},
                               "noise": {"probing_repeatability_um": 2.0}, "task": SHAPES[shape],
                               "environment": {"drift_C_per_h": 8.0},
                               "operator": {"measurement_gap_s": 300.0, "force_mean_N": 3.0}})
    sim = simulate(camp)
    return sim.points, sim.artefacts, camp.arm


def one_seed(seed: int, shape: str, no_thermometer: bool = False) -> dict:
    """The loop on one clean campaign: what it added, built and claimed (``no_thermometer``: without the
    temperature column)."""
    import dataclasses

    import numpy as np

    from calibration.data import Weights
    from calibration.loop import close_loop

    t0 = time.perf_counter()
    points, artefacts, arm = _campaign(seed, shape)
    if no_thermometer:
        points = dataclasses.replace(points, temperature=None)
    loop = close_loop(points, artefacts, arm, weights=Weights(probe=2e-6), cv_top=2, seed=seed)
    t = points.temperature
    return {"seed": seed, "points": len(points), "temperature_span_K": None if t is None else float(np.ptp(t)),
            "added": [{"name": c.name, "origin": c.origin} for c in loop.added],
            "built": [{"name": b["name"], "added": b["added"], "why_not_added": b["why_not_added"]}
                      for b in loop.built],
            "structure_claimed": [f.name for f, _, _ in loop.remaining],
            "heldout_worse": bool(loop.heldout_check and loop.heldout_check["worse_than_stated"]),
            "heldout_check": loop.heldout_check,
            "escalated": None if loop.escalated is None else loop.escalated["families"],
            "verdict_clean": "No structured residual remains" in loop.verdict,
            "seconds": round(time.perf_counter() - t0, 1)}


def summary(rows: list[dict]) -> str:
    n = len(rows)
    added = [r["seed"] for r in rows if r["added"]]
    built_added = [r["seed"] for r in rows if any(a["origin"] == "residual" for a in r["added"])]
    built = [r["seed"] for r in rows if r["built"]]
    claimed = [r["seed"] for r in rows if r["structure_claimed"]]
    worse = [r["seed"] for r in rows if r.get("heldout_worse")]
    escalated = [r["seed"] for r in rows if r.get("escalated")]

    def seeds(s):
        return f" (seeds {', '.join(map(str, s))})" if s else ""
    lines = [f"{n} clean campaigns",
             f"effect added: {len(added)} of {n}{seeds(added)}; of them built from the residual: {len(built_added)}",
             f"an effect built from the residual (added or not): {len(built)} of {n}{seeds(built)}",
             f"structure claimed: {len(claimed)} of {n}{seeds(claimed)}",
             f"outer test set worse than stated: {len(worse)} of {n}{seeds(worse)}; opt-in families offered: "
             f"{len(escalated)} of {n}{seeds(escalated)}"]
    for r in rows:
        for b in r["built"]:
            lines.append(f"  seed {r['seed']}: built {b['name']}: " + ("added" if b["added"] else b["why_not_added"]))
        if r["structure_claimed"]:
            lines.append(f"  seed {r['seed']}: structure claimed: {', '.join(r['structure_claimed'])}")
    return "\n".join(lines)


def _seeds(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--shape", choices=[*SHAPES, "quick"], default="synthesis", help="campaign shape")
    p.add_argument("--seeds", default="0-19", help="seeds, e.g. 0-19 or 1,4,7")
    p.add_argument("-o", "--output", type=Path, default=Path("out/honesty"), help="output folder")
    p.add_argument("--no-thermometer", action="store_true", help="drop the temperature column (time_s kept)")
    args = p.parse_args(argv)
    rows = []
    for seed in _seeds(args.seeds):
        rows.append(one_seed(seed, args.shape, args.no_thermometer))
        print(f"seed {seed}: added {[a['name'] for a in rows[-1]['added']]}, built "
              f"{[b['name'] for b in rows[-1]['built']]}, claimed {rows[-1]['structure_claimed']} "
              f"({rows[-1]['seconds']} s)", file=sys.stderr, flush=True)
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
    print(summary(rows))
    return 0


if __name__ == "__main__":
    logging.disable(logging.INFO)          # the loop's progress lines; the seeds' lines go to stderr
    raise SystemExit(main())
