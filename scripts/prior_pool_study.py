#!/usr/bin/env python3
"""Exploration: the seat studies with the prior's geometric groups pooled (``--prior-groups pooled``), or pinned.

By default the evidence (calibration/prior.py, :func:`calibration.prior.update_scales`) gives each group of the
description's parameters its own scale (lengths, joint offsets, axis angles, the tip offset); ``aacmm calibrate
--prior-groups pooled`` and ``aacmm close-loop --prior-groups pooled`` (``FitOptions.prior_groups``) give the four one
scale by one fixed point. This study runs ``scripts/real_seats_study.py`` or ``scripts/sim_seats_study.py`` with that
option (``--groups``) and the loop's ``--pose-folds`` given to every ``calibrate`` and ``close-loop`` of the study, or
with groups pinned at a given scale (``--pin``: the evidence's update wrapped in this process only, every other rule
unchanged). Measured in docs/studies/close-loop.md ("Blocked folds by pose") and docs/studies/calibration.md.

    python scripts/prior_pool_study.py real --methods calibrate,close-loop --pose-folds blocked -o out/pool
    python scripts/prior_pool_study.py real --groups separate --pin "lengths=3" --methods calibrate -o out/pin
    python scripts/prior_pool_study.py sim --methods calibrate -o out/pool-sim -- --capture sweep
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import calibration.prior as prior  # noqa: E402

CALIBRATE = sys.modules["calibration.calibrate"]       # the module (the package's attribute is the function)


def pinned_update(pins: dict[str, float]):
    """:func:`calibration.prior.update_scales` with the groups of ``pins`` at a given scale."""
    plain = prior.update_scales

    def update(*args, **kw):
        new, gamma = plain(*args, **kw)
        new.update({g: v for g, v in pins.items() if g in new})
        return new, gamma
    return update


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("study", choices=("real", "sim"))
    p.add_argument("--groups", choices=prior.PRIOR_GROUPS, default="pooled", help="--prior-groups of every fit")
    p.add_argument("--pose-folds", choices=("dealt", "blocked"), default="dealt", help="close-loop's --pose-folds")
    p.add_argument("--pin", default="", help="comma-separated group=scale pinned (e.g. 'lengths=3')")
    p.add_argument("--methods", default="calibrate,close-loop")
    p.add_argument("-o", "--output", type=Path, required=True)
    argv = list(sys.argv[1:] if argv is None else argv)
    cut = argv.index("--") if "--" in argv else len(argv)
    args = p.parse_args(argv[:cut])             # after --: options of the study script
    pins = {k: float(v) for k, v in (s.split("=") for s in args.pin.split(",") if s)}
    if pins:
        CALIBRATE.update_scales = pinned_update(pins)     # what calibrate() calls, for this process only
    fit = ["--prior-groups", args.groups]
    loop = fit + ["--pose-folds", args.pose_folds]
    rest = ["--methods", args.methods, "-o", str(args.output), *argv[cut + 1:]]
    if args.study == "real":
        import real_seats_study
        return int(real_seats_study.main(["--calibrate-options", " ".join(fit), "--loop-options", " ".join(loop),
                                          *rest]))
    import sim_seats_study
    for method in sim_seats_study.OPTIONS:
        sim_seats_study.OPTIONS[method] += loop if method.startswith("close-loop") else fit
    return int(sim_seats_study.main(rest))


if __name__ == "__main__":
    sys.exit(main())
