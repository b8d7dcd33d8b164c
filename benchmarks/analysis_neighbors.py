"""Benchmark: RDF and coordination number for 1e5 and 1e6 particles (not part of the tests).

A periodic box of random spheres at packing fraction 0.3 (about 2 neighbours each within
contact). PyGran's ``Particles.computeRDF`` and ``equilibrium.Neighbors(...).coon`` are
timed as installed (with the core's compiled sweep when it was built) and on
the core's pure numpy path, against a straightforward scipy cKDTree implementation
(``query_pairs`` then ``np.histogram`` / ``np.bincount``) and freud. The contenders run in
turn within each repetition (best of ``--repeats``), so a busy machine slows them alike; the
script prints each time and the ratios (other time / PyGran time: above 1, PyGran is faster).

freud is a benchmark dependency, not a dependency of PyGran: ``pip install freud-analysis``
into the environment that runs this script (it is left out when not importable).

    python benchmarks/analysis_neighbors.py [N ...] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Callable, Iterator

import numpy as np
from scipy.spatial import cKDTree

from pygran_core.analysis import Particles, _neighbors, equilibrium

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


def freud_functions(positions: np.ndarray, length: float, r_max: float) -> dict[str, Callable[[], object]]:
    try:
        import freud
    except ImportError:
        return {}
    box = freud.box.Box.cube(length)
    centred = positions - length / 2

    def rdf() -> np.ndarray:
        return freud.density.RDF(bins=NBINS, r_max=r_max).compute((box, centred)).rdf

    def coon() -> np.ndarray:
        query = freud.locality.AABBQuery(box, centred)
        bonds = query.query(centred, {"r_max": 2 * RADIUS, "exclude_ii": True}).toNeighborList()
        return np.bincount(bonds.query_point_indices, minlength=len(positions))

    return {"rdf": rdf, "coon": coon}


@contextlib.contextmanager
def numpy_path() -> Iterator[None]:
    """The core without its compiled sweep."""
    kernels, _neighbors._accel = _neighbors._accel, None
    try:
        yield
    finally:
        _neighbors._accel = kernels


def bench(n: int, repeats: int, names: list[str]) -> None:
    particles = system(n)
    positions = particles.positions
    length = float(np.asarray(particles.box)[0, 1])
    r_max = 5 * RADIUS
    ours = {
        "rdf": lambda: particles.computeRDF(dr=r_max / NBINS, rMax=r_max).g,
        "coon": lambda: np.asarray(equilibrium.Neighbors(particles).coon),
    }

    def pure(task: str) -> Callable[[], object]:
        def run() -> object:
            with numpy_path():
                return ours[task]()

        return run

    others = {
        "rdf": lambda: baseline_rdf(positions, length, r_max),
        "coon": lambda: baseline_coon(positions, length),
    }
    freud = freud_functions(positions, length, r_max)
    for task in ("rdf", "coon"):
        contenders = {"pygran": ours[task], "numpy": pure(task), "scipy": others[task]}
        if task in freud:
            contenders["freud"] = freud[task]
        best = dict.fromkeys(contenders, np.inf)
        results: dict[str, object] = {}
        for _ in range(repeats):  # interleaved: every contender once per round
            for name, function in contenders.items():
                start = time.perf_counter()
                results[name] = function()
                best[name] = min(best[name], time.perf_counter() - start)
        assert np.array_equal(results["pygran"], results["numpy"]), f"{task}: compiled and numpy paths differ"
        assert np.allclose(results["pygran"], results["scipy"], rtol=1e-6, atol=1e-9), (
            f"{task} differs from scipy"
        )
        if "freud" in results:
            assert np.allclose(results["pygran"], results["freud"], rtol=1e-3, atol=1e-3), (
                f"{task} differs from freud"
            )
        line = f"{n:>9} {task:>6}" + "".join(f" {best.get(name, np.nan):9.3f}" for name in names)
        line += "".join(
            f" {best.get(other, np.nan) / best[mine]:8.2f}"
            for mine, other in (
                ("pygran", "scipy"),
                ("pygran", "freud"),
                ("numpy", "scipy"),
                ("numpy", "freud"),
            )
        )
        print(line, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sizes", nargs="*", type=float, default=[1e5, 1e6])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    kernels = "the core's compiled sweep" if _neighbors._accel is not None else "numpy (no compiled kernels)"
    print(f"pygran: as installed, {kernels}; numpy: the core's pure numpy path; best of {args.repeats}")
    names = ["pygran", "numpy", "scipy", "freud"]
    header = f"{'N':>9} {'task':>6}" + "".join(f" {name + ' s':>9}" for name in names)
    print(header + "".join(f" {label:>8}" for label in ("sci/pg", "freud/pg", "sci/np", "freud/np")))
    for n in args.sizes:
        bench(int(n), args.repeats, names)
    print("ratios: other time / PyGran time (above 1: PyGran is faster); pg = as installed, np = numpy path")


if __name__ == "__main__":
    main()
