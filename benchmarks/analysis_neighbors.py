"""Benchmark: RDF and coordination number for 1e5 and 1e6 particles (not part of the tests).

A periodic box of random spheres at packing fraction 0.3 (about 2 neighbours each within
contact). PyGran's ``Particles.computeRDF`` and ``equilibrium.Neighbors(...).coon`` are
timed against a straightforward scipy cKDTree implementation (``query_pairs`` then
``np.histogram`` / ``np.bincount``) and, when importable, freud. Run as
``python benchmarks/analysis_neighbors.py [N ...]``; install freud only in a throwaway venv
(``pip install freud-analysis``).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.spatial import cKDTree

from pygran_core.analysis import Particles, equilibrium

RADIUS = 0.5
PHI = 0.3
NBINS = 100


def system(n: int) -> Particles:
    length = (n * 4 / 3 * np.pi * RADIUS**3 / PHI) ** (1 / 3)
    positions = np.random.default_rng(0).random((n, 3)) * length
    return Particles(
        x=positions[:, 0],
        y=positions[:, 1],
        z=positions[:, 2],
        radius=np.full(n, RADIUS),
        box=[[0, length]] * 3,
        boundary=("pp", "pp", "pp"),
    )


def baseline_rdf(positions: np.ndarray, length: float, r_max: float) -> np.ndarray:
    pairs = cKDTree(positions, boxsize=length).query_pairs(r_max, output_type="ndarray")
    delta = positions[pairs[:, 0]] - positions[pairs[:, 1]]
    delta -= length * np.round(delta / length)
    counts, edges = np.histogram(np.linalg.norm(delta, axis=1), bins=NBINS, range=(0, r_max))
    shells = 4 / 3 * np.pi * np.diff(edges**3)
    return 2 * counts / (len(positions) * (len(positions) - 1) / length**3 * shells)


def baseline_coon(positions: np.ndarray, length: float) -> np.ndarray:
    pairs = cKDTree(positions, boxsize=length).query_pairs(2 * RADIUS, output_type="ndarray")
    return np.bincount(pairs.ravel(), minlength=len(positions))


def timed(function, repeat: int = 3) -> tuple[float, object]:
    best, result = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return best, result


def freud_functions(positions: np.ndarray, length: float, r_max: float):
    try:
        import freud
    except ImportError:
        return None
    box = freud.box.Box.cube(length)
    centred = positions - length / 2

    def rdf():
        return freud.density.RDF(bins=NBINS, r_max=r_max).compute((box, centred)).rdf

    def coon():
        query = freud.locality.AABBQuery(box, centred)
        bonds = query.query(centred, {"r_max": 2 * RADIUS, "exclude_ii": True}).toNeighborList()
        return np.bincount(bonds.query_point_indices, minlength=len(positions))

    return rdf, coon


def bench(n: int) -> None:
    particles = system(n)
    positions = particles.positions
    length = float(np.asarray(particles.box)[0, 1])
    r_max = 5 * RADIUS
    repeat = 3 if n <= 200_000 else 1
    ours = {
        "rdf": lambda: particles.computeRDF(dr=r_max / NBINS, rMax=r_max).g,
        "coon": lambda: equilibrium.Neighbors(particles).coon,
    }
    base = {
        "rdf": lambda: baseline_rdf(positions, length, r_max),
        "coon": lambda: baseline_coon(positions, length),
    }
    freud_pair = freud_functions(positions, length, r_max)
    others = dict(zip(("rdf", "coon"), freud_pair)) if freud_pair else {}
    for task in ("rdf", "coon"):
        t_ours, mine = timed(ours[task], repeat)
        t_base, reference = timed(base[task], repeat)
        assert np.allclose(mine, reference, rtol=1e-6, atol=1e-9), f"{task} differs from the baseline"
        line = f"{n:>9} {task:>6} {t_ours:9.3f} {t_base:9.3f} {t_base / t_ours:6.2f}"
        if task in others:
            t_freud, theirs = timed(others[task], repeat)
            assert np.allclose(mine, theirs, rtol=1e-3, atol=1e-3), f"{task} differs from freud"
            line += f" {t_freud:8.3f} {t_freud / t_ours:6.2f}"
        print(line, flush=True)


def main(sizes: list[int]) -> None:
    print(f"{'N':>9} {'task':>6} {'pygran s':>9} {'scipy s':>9} {'ratio':>6} {'freud s':>8} {'ratio':>6}")
    for n in sizes:
        bench(n)
    print("ratio = other time / PyGran time (above 1: PyGran is faster)")


if __name__ == "__main__":
    main([int(float(a)) for a in sys.argv[1:]] or [100_000, 1_000_000])
