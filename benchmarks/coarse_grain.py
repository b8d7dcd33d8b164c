"""Benchmark: coarse-graining N particles and 5 N contacts onto a 100^3 grid (not part of the tests).

A periodic box of N spheres of radius 0.5 (diameter 1) at random positions, the box side
chosen so that the 100^3 grid has cells one diameter wide (about one particle per cell);
5 N contacts between random particles and their neighbours (branch vectors of length 0.9
to 1 in random directions, random forces). ``coarse_grain`` computes density, momentum,
kinetic and contact stress with each kernel (``WIDTH``: the Gaussian's 0.5 reaches 1.5 cells),
as installed (the core's compiled deposits when they were built) and, for sizes up to
``--numpy-max``, on the core's numpy path. Best of ``--repeats``; the script checks that the
grid holds the mass and ``sum f ⊗ b``, prints the seconds per size, and for N = 1e6 whether
the issue's target is met: N = 1e6 (5e6 contacts) on the 100^3 grid under 10 s on a 2-core
machine (OpenMP threads: ``OMP_NUM_THREADS``, default all cores).

    python benchmarks/coarse_grain.py [N ...] [--repeats 3] [--bins 100] [--numpy-max 1e5]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from collections.abc import Iterator

import numpy as np

from pygran_core.analysis import coarse_grain as cg

#: Kernel widths: the particle radius, and for the top hat the smallest width that reaches one
#: cell (its half-width sqrt(3) w = 1 cell), as coarse_grain requires.
WIDTH = {"gaussian": 0.5, "lucy": 0.5, "heaviside": 1 / np.sqrt(3)}


def scene(n: int, bins: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(0)
    length = float(bins)  # cells of one diameter
    positions = rng.random((n, 3)) * length
    velocity = rng.normal(size=(n, 3))
    mass = np.full(n, np.pi / 6)
    first = rng.integers(0, n, 5 * n)
    direction = rng.normal(size=(5 * n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    branch = direction * rng.uniform(0.9, 1.0, (5 * n, 1))
    force = rng.normal(size=(5 * n, 3))
    return positions, velocity, mass, positions[first], branch, force, np.array([[0.0, length]] * 3)


@contextlib.contextmanager
def numpy_path() -> Iterator[None]:
    kernels, cg._accel = cg._accel, None
    try:
        yield
    finally:
        cg._accel = kernels


def bench(n: int, bins: int, kernel: str, repeats: int, pure: bool) -> float:
    positions, velocity, mass, start, branch, force, box = scene(n, bins)
    grid = cg.Grid3D(bins=(bins,) * 3)
    periodic = ("pp", "pp", "pp")

    def run() -> cg.Fields:
        contacts = (start, branch, force)
        return cg.coarse_grain(
            grid,
            positions,
            mass,
            velocity,
            contacts,
            kernel=kernel,
            width=WIDTH[kernel],
            box=box,
            boundary=periodic,
        )

    paths = {"installed": run}
    if pure:

        def run_numpy() -> cg.Fields:
            with numpy_path():
                return run()

        paths["numpy"] = run_numpy
    best = dict.fromkeys(paths, np.inf)
    for _ in range(repeats):
        for name, function in paths.items():
            begin = time.perf_counter()
            fields = function()
            best[name] = min(best[name], time.perf_counter() - begin)
            stress = (fields.contact_stress * fields.cell_volume[..., None, None]).sum(axis=(0, 1, 2))
            expected = force.T @ branch
            assert abs(fields.mass / mass.sum() - 1) < 1e-12, "the grid lost mass"
            assert np.allclose(stress, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max()), "sum f x b"
    timings = "".join(f" {best.get(name, np.nan):10.3f}" for name in ("installed", "numpy"))
    print(f"{n:>9} {5 * n:>9} {kernel:>10}{timings}", flush=True)
    return best["installed"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sizes", nargs="*", type=float, default=[1e5, 1e6])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--bins", type=int, default=100)
    parser.add_argument("--numpy-max", type=float, default=1e5)
    parser.add_argument("--kernels", nargs="*", default=list(cg.KERNELS))
    args = parser.parse_args()
    kernels = "the core's compiled deposits" if cg._accel is not None else "numpy (no compiled kernels)"
    threads = os.environ.get("OMP_NUM_THREADS", f"{os.cpu_count()} (all cores)")
    print(
        f"installed: {kernels}, {threads} thread(s); numpy: the core's numpy path; {args.bins}^3 grid; "
        f"best of {args.repeats}"
    )
    print(f"{'particles':>9} {'contacts':>9} {'kernel':>10} {'install s':>10} {'numpy s':>10}")
    for n in args.sizes:
        for kernel in args.kernels:
            seconds = bench(int(n), args.bins, kernel, args.repeats, n <= args.numpy_max)
            if int(n) == 10**6 and args.bins == 100:
                verdict = "met" if seconds < 10 else "NOT met"
                print(f"{'':>30} target (1e6 particles, 5e6 contacts, 100^3, < 10 s): {verdict}")


if __name__ == "__main__":
    main()
