"""Dump parsing speed on one core: pygran-readers vs numpy.loadtxt vs MDAnalysis.

Writes a synthetic LIGGGHTS dump (id type x y z radius vx vy vz fx fy fz), then times
reading every frame with each reader and prints MB/s of dump text and the ratios.
MDAnalysis is optional: it is used when importable here, or through another interpreter
that has it (``--mdanalysis-python /path/to/venv/bin/python``).

    python benchmarks/read_dump.py [--particles 200000] [--frames 5]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pygran_core.formats.dump import DumpTrajectory, format_frame
from pygran_core.io import Frame

COLUMNS = "id type x y z radius vx vy vz fx fy fz".split()

MDA_SCRIPT = """
import sys, time
import MDAnalysis as mda
start = time.perf_counter()
u = mda.Universe(sys.argv[1], format="LAMMPSDUMP", lammps_coordinate_convention="unscaled")
for ts in u.trajectory:
    pass
print(time.perf_counter() - start)
"""


def make_dump(path: Path, particles: int, frames: int) -> None:
    rng = np.random.default_rng(0)
    with open(path, "w") as out:
        for k in range(frames):
            arrays = {"id": np.arange(1, particles + 1), "type": rng.integers(1, 3, particles)}
            for name in COLUMNS[2:]:
                arrays[name] = np.round(rng.normal(size=particles) * 1e-3, 9)
            out.write(
                format_frame(
                    Frame(
                        arrays,
                        timestep=1000 * k,
                        box=np.array([[-0.1, 0.1], [-0.1, 0.1], [0.0, 0.4]]),
                        boundary=("ff", "ff", "ff"),
                    )
                )
            )


def best_of(repeats: int, run) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=200_000)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mdanalysis-python", help="an interpreter with MDAnalysis installed")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.dump"
        make_dump(path, args.particles, args.frames)
        megabytes = path.stat().st_size / 1e6
        print(
            f"{args.frames} frames x {args.particles} particles x {len(COLUMNS)} columns: {megabytes:.1f} MB"
        )

        def pygran() -> None:
            trajectory = DumpTrajectory([path])
            for frame in trajectory:
                assert len(frame.arrays["id"]) == args.particles

        def loadtxt() -> None:  # the atom rows of each frame; headers skipped with a comment mark
            lines = path.read_bytes().split(b"\n")
            header = 9
            for k in range(args.frames):
                start = k * (header + args.particles) + header
                np.loadtxt(lines[start : start + args.particles], dtype=np.float64)

        results = {
            "pygran-readers": best_of(args.repeats, pygran),
            "numpy.loadtxt": best_of(args.repeats, loadtxt),
        }
        python = args.mdanalysis_python
        if python is None:
            try:
                import MDAnalysis  # noqa: F401

                python = sys.executable
            except ImportError:
                print("MDAnalysis: not importable here (pass --mdanalysis-python)")
        if python is not None:
            runs = [
                float(
                    subprocess.run(
                        [python, "-c", MDA_SCRIPT, str(path)], capture_output=True, text=True, check=True
                    ).stdout
                )
                for _ in range(args.repeats)
            ]
            results["MDAnalysis LAMMPSDUMP"] = min(runs)
        ours = results["pygran-readers"]
        for name, seconds in results.items():
            print(f"{name:<24} {megabytes / seconds:8.1f} MB/s  ({seconds:.3f} s)")
        for name, seconds in results.items():
            if name != "pygran-readers":
                print(f"pygran-readers / {name}: {seconds / ours:.2f}x")


if __name__ == "__main__":
    main()
