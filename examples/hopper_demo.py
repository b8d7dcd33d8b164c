"""The hopper discharge study (``pygran demo``) as a script, with every knob on the command line.

    python examples/hopper_demo.py --particles 3000 --output hopper-run
    python examples/hopper_demo.py --engine liggghts --particles 1000 --discharge-time 0.8

Writes traj.h5md (particles, with its XDMF sidecar), walls.pvd (the hopper), hopper.png and summary.txt.
"""

import argparse

from pygran_core.apps import demo


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default="native")
    parser.add_argument("--particles", type=int, default=3000)
    parser.add_argument("--output", default="hopper-run")
    parser.add_argument("--settle-time", type=float, default=demo.HopperStudy.settle_time)
    parser.add_argument("--discharge-time", type=float, default=demo.HopperStudy.discharge_time)
    args = parser.parse_args(argv)
    summary = demo.run(
        args.output,
        engine=args.engine,
        particles=args.particles,
        report=print,
        settle_time=args.settle_time,
        discharge_time=args.discharge_time,
    )
    print(summary.text(), end="")
    return summary


if __name__ == "__main__":
    main()
