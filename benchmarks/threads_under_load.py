"""Native threads on a busy machine: the settle benchmark with 1 thread and with the default
thread count, on the machine as it is and while a busy loop this script starts holds a core.

    .venv/bin/python benchmarks/threads_under_load.py [--n 20000] [--reps 2] [--pin]

Runs :func:`settle.run` (the settle scenario through ``simulation.DEM``: 8,000 settling and
4,000 dense-bed steps) for each of the four cases, interleaved ``--reps`` times (alternating
which thread count goes first), then prints the medians of particle-steps per second and the
ratios: default / 1 thread with and without the busy loop (issue 20 asks for at least 1 under
load, and about 1.9 on an otherwise idle 2-core machine), and each thread count's speed under
load relative to without. The busy loop is a Python ``while True: pass`` in its own process,
pinned with ``--pin`` to the last CPU this process may use, else left to the scheduler. Other
processes on the machine count too: the load average is printed before and after. Ends with
one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

from pygran_native.solver import default_threads
from scenario import SIZES, busy_loop
from settle import run

PHASES = ("settle_pss", "bed_pss")


def measure(n: int, reps: int, pin: bool) -> dict[tuple[bool, str], dict[str, list[float]]]:
    """Particle-steps per second by (busy loop on, thread count) and phase, over the repetitions."""
    cpu = max(os.sched_getaffinity(0)) if pin else None
    results = {(load, t): {p: [] for p in PHASES} for load in (False, True) for t in ("1", "default")}
    for rep in range(reps):
        order = ("1", "default") if rep % 2 == 0 else ("default", "1")
        for load in (False, True):
            busy = busy_loop(cpu) if load else None
            try:
                time.sleep(0.5 if load else 0)
                for threads in order:
                    result = run("native", n, 1 if threads == "1" else None)
                    for phase in PHASES:
                        results[load, threads][phase].append(result[phase])
                    print(
                        f"  rep {rep + 1}, {'busy loop' if load else 'no busy loop'}, {threads} thread(s): "
                        + ", ".join(f"{p[:-4]} {result[p] / 1e6:.2f}" for p in PHASES)
                        + " M particle-steps/s",
                        flush=True,
                    )
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000, choices=sorted(SIZES))
    parser.add_argument("--reps", type=int, default=2, help="interleaved repetitions of the four cases")
    parser.add_argument("--pin", action="store_true", help="pin the busy loop to one CPU")
    args = parser.parse_args()
    threads = default_threads()
    print(
        f"native settle N = {args.n}: 1 thread and the default {threads} threads, busy loop "
        f"{'pinned to CPU ' + str(max(os.sched_getaffinity(0))) if args.pin else 'unpinned'}; "
        f"load average before: {os.getloadavg()[0]:.2f}"
    )
    results = measure(args.n, args.reps, args.pin)
    median = {key: {p: statistics.median(v) for p, v in phases.items()} for key, phases in results.items()}
    print(f"medians over {args.reps} repetition(s), M particle-steps/s (settle / dense bed):")
    for (load, t), m in median.items():
        print(
            f"  {'busy loop' if load else 'no busy loop':12s} {t:>7s} thread(s): "
            f"{m['settle_pss'] / 1e6:6.2f} / {m['bed_pss'] / 1e6:6.2f}"
        )
    ratios = {
        "default_over_1_busy": {p: median[True, "default"][p] / median[True, "1"][p] for p in PHASES},
        "default_over_1_no_busy": {p: median[False, "default"][p] / median[False, "1"][p] for p in PHASES},
        "busy_over_no_busy_1": {p: median[True, "1"][p] / median[False, "1"][p] for p in PHASES},
        "busy_over_no_busy_default": {
            p: median[True, "default"][p] / median[False, "default"][p] for p in PHASES
        },
    }
    print("ratios (settle / dense bed):")
    for name, r in ratios.items():
        print(f"  {name:26s} {r['settle_pss']:.2f} / {r['bed_pss']:.2f}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(
        json.dumps(
            {
                "N": args.n,
                "default_threads": threads,
                "reps": args.reps,
                "pin": args.pin,
                "medians": {f"{'busy' if load else 'no_busy'}_{t}": m for (load, t), m in median.items()},
                "ratios": ratios,
            }
        )
    )


if __name__ == "__main__":
    main()
