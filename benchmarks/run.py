"""`make bench`: run every benchmarks/bench_*.py main() in turn and print their tables.

``python -m benchmarks.run [--quick] [NAME ...]``: only the named benchmarks (``io``,
``kinematics``); ``--quick`` (``make bench BENCH=--quick``): the smaller sizes a module
lists in its ``QUICK`` (keyword arguments of its ``main``), a minute or two in all."""
from __future__ import annotations

import importlib
import platform
import sys
from pathlib import Path


def machine() -> str:
    import os
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = ("load average {:.1f} {:.1f} {:.1f} (1, 5, 15 min; above the core count, wall times are "
                "stretched)").format(*os.getloadavg())
    except OSError:
        load = "load average unknown"
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, {platform.system()} "
            f"{platform.machine()}"
            f"; {load}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    quick = "--quick" in argv
    argv = [a for a in argv if a != "--quick"]
    print(f"machine: {machine()}" + (" (--quick sizes)" if quick else ""))
    names = sorted(p.stem for p in Path(__file__).parent.glob("bench_*.py"))
    if argv:
        names = [n for n in names if any(n in (a, f"bench_{a}") for a in argv)]
    for name in names:
        print(f"\n=== {name} ===", flush=True)
        module = importlib.import_module(f"benchmarks.{name}")
        module.main(**(getattr(module, "QUICK", {}) if quick else {}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
