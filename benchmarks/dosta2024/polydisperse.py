"""The penetration bed (25k beads of r = 1 mm) with its r = 10 mm ball against the bed alone,
through ``simulation.DEM`` with default neighbour settings, on each engine in one run:
particle-steps per second of each and their ratio (the target: the bed with its ball at least
80 % of the bed alone's speed per particle-step).

    .venv/bin/python benchmarks/dosta2024/polydisperse.py --engines native liggghts --steps 2000

Each engine runs with the case's mesh walls and without them. (LIGGGHTS' ``neighbor multi`` is
not used: LIGGGHTS 3.8 refuses it beside mesh walls, and without them it ran the bed and ball
ten times faster than the bed alone, as if pairs were missing from its lists.) Both runs start
as the case does (the ball 0.1 m above the bed at 5 m/s, dt = 5e-7 s, so the ball meets no bead
within the steps timed unless ``--steps`` exceeds 40,000): what differs is the neighbour lists
the declared 10 mm species makes each engine build.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

sys.path.insert(0, str(Path(__file__).parent))

import cases

from pygran_core import simulation


def speed(engine: str, with_ball: bool, walls: bool, steps: int, folder: Path) -> tuple[float, str]:
    """Particle-steps per second of ``steps`` steps, and the engine's neighbour settings;
    without ``walls`` the box's mesh walls are left out."""
    case = cases.penetration("25k")
    keywords = dict(case.keywords, engine=engine, output=str(folder / f"{engine}-{with_ball}-{walls}"))
    keywords["traj"], keywords["progress"] = {"pfile": None}, False
    if not walls:
        del keywords["mesh"]
        keywords["pairs"] = {key: value for key, value in keywords["pairs"].items() if "walls" not in key}
    if not with_ball:
        keywords["species"] = keywords["species"][:1]
        keywords["pairs"] = {key: value for key, value in keywords["pairs"].items() if 2 not in key}
    with simulation.DEM(**keywords) as sim:
        sim.createParticles(1, "single", cases.bed("25k"))
        if with_ball:
            sim.createParticles(2, "single", *cases.BALL["centre"], vel=(0.0, 0.0, -cases.BALL["speed"]))
        sim.run(100)  # lists built, the worker started
        count = len(sim.extractIds())
        start = time.perf_counter()
        sim.run(steps)
        elapsed = time.perf_counter() - start
        log = (Path(keywords["output"]) / "pygran.log").read_text().splitlines()
    neighbours = next((line.split(" INFO ")[-1] for line in log if "neighbour" in line or "skin" in line), "")
    return count * steps / elapsed, neighbours


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--engines", nargs="+", default=["native", "liggghts"])
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args()
    with TemporaryDirectory() as tmp:
        for engine, walls in ((engine, walls) for engine in args.engines for walls in (True, False)):
            alone, _ = speed(engine, False, walls, args.steps, Path(tmp))
            both, settings = speed(engine, True, walls, args.steps, Path(tmp))
            print(
                f"{engine:<9} {'mesh walls' if walls else 'no walls':<10} "
                f"bed alone {alone / 1e6:6.2f} M particle-steps/s, "
                f"bed and ball {both / 1e6:6.2f} M, "
                f"ratio {both / alone:.2f} ({settings})"
            )


if __name__ == "__main__":
    main()
