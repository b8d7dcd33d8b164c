"""The ``pygran`` command."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from collections.abc import Callable, Iterable, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from pygran_core import registry
from pygran_core.apps import demo
from pygran_core.errors import ConfigError, PluginNotFound, PyGranError
from pygran_core.io import Trajectory, expand_paths
from pygran_core.simulation import geometry
from pygran_core.simulation.dem import resolve_engine
from pygran_core.testing import validation

T = TypeVar("T")


def _solver_status(provided: registry.Provided) -> str:
    locate = provided.spec.locate_solver
    if locate is None:
        return ""
    try:
        return f"solver: {locate()}"
    except PyGranError as exc:
        return f"solver missing: {exc}"


def _describe(kind: str, provided: registry.Provided) -> str:
    spec = provided.spec
    if kind == "engine":
        return _solver_status(provided)
    if kind in ("reader", "writer"):
        return f"{', '.join(spec.extensions)} [{', '.join(sorted(spec.kinds))}]"
    return spec.description


def cmd_plugins(args: argparse.Namespace) -> int:
    """Print every plugin, then every engine, model, reader and writer with its distribution."""
    print("plugins:")
    for name, (dist, dist_version) in sorted(registry.plugins().items()):
        print(f"  {name:<16} {dist} {dist_version}")
    for kind in registry.KINDS:
        items = registry.available(kind)
        print(f"{kind}s:")
        if not items:
            print("  (none installed)")
        for name, provided in sorted(items.items()):
            detail = _describe(kind, provided)
            print(f"  {name:<16} {provided.origin:<24} {detail}".rstrip())
    return 0


def _open(pattern: str, format: str | None) -> tuple[Trajectory, str, int]:
    """The trajectory, its reader's name and the number of files behind it."""
    paths = expand_paths(pattern)
    spec = registry.reader_for(paths[0], format)
    return spec.open(paths), spec.name, len(paths)


def _progress(items: Iterable[T], total: int, what: str) -> Iterable[T]:
    """A progress bar on stderr for runs longer than a second; silent when not a terminal."""
    from tqdm import tqdm

    return tqdm(items, total=total, desc=what, unit="frame", delay=1.0, disable=None, leave=False)


def _box_text(box: Any, boundary: Any) -> str:
    if box is None:
        return "none"
    text = " x ".join(f"[{lo:g}, {hi:g}]" for lo, hi in np.asarray(box))
    return f"{text} ({' '.join(boundary)})" if boundary else text


def cmd_info(args: argparse.Namespace) -> int:
    """Frames, sizes, columns, box and timesteps of a trajectory or mesh sequence."""
    trajectory, name, n_files = _open(args.file, args.format)
    with trajectory:
        sizes: list[int] = []
        cells: list[int] = []
        steps: list[int] = []
        columns: list[str] = []
        first: dict[str, Any] = {}
        mesh: geometry.Surface | None = None
        read_header = getattr(trajectory, "read_header", None)  # dump: no need to parse atoms
        for index in _progress(range(len(trajectory)), len(trajectory), "reading"):
            if read_header is not None:
                header = read_header(index)
                size, box, boundary, names, step = (
                    header["natoms"],
                    header["box"],
                    header["boundary"],
                    header["columns"],
                    header["timestep"],
                )
            else:
                frame = trajectory[index]
                arrays = frame.arrays
                if "points" in arrays:
                    size = len(arrays["points"])
                    cells.append(len(arrays.get("cells", ())))
                    mesh = mesh if index else _surface(arrays)
                else:
                    size = len(next(iter(arrays.values()))) if arrays else 0
                box, boundary, names, step = frame.box, frame.boundary, list(arrays), frame.timestep
            sizes.append(size)
            if step is not None:
                steps.append(step)
            columns += [c for c in names if c not in columns]
            first = first or {"box": box, "boundary": boundary}
    files = f" ({n_files} files)" if n_files > 1 else ""
    print(f"file:       {args.file}{files}")
    print(f"format:     {name}")
    print(f"frames:     {len(sizes)}")
    if sizes:
        label = "points:" if cells else "particles:"
        print(f"{label:<12}{min(sizes)} min, {max(sizes)} max per frame")
    if cells:
        print(f"cells:      {min(cells)} min, {max(cells)} max per frame")
    print(f"columns:    {' '.join(columns) or 'none'}")
    if sizes:
        print(f"box:        {_box_text(first.get('box'), first.get('boundary'))} (first frame)")
    if steps:
        print(f"timesteps:  {min(steps)} to {max(steps)}")
    if mesh is not None:
        _print_surface(mesh)
    return 0


def _surface(arrays: dict[str, np.ndarray]) -> geometry.Surface | None:
    """The triangles of a mesh frame whose cells are all triangles, else None."""
    cells = np.asarray(arrays.get("cells", ()))
    if cells.ndim != 2 or cells.shape[1] != 3 or len(cells) == 0:
        return None
    return geometry.Surface(np.asarray(arrays["points"], float)[cells])


def _print_surface(surface: geometry.Surface) -> None:
    """Bounds, triangle count and watertightness of a mesh's first frame."""
    bounds = " x ".join(f"[{lo:g}, {hi:g}]" for lo, hi in surface.bounds)
    print(f"triangles:  {len(surface)} (first frame)")
    print(f"bounds:     {bounds} (first frame)")
    if surface.closed:
        print(f"closed:     yes (volume {surface.volume:.6g}, area {surface.area:.6g})")
    else:
        why = f"{surface.open_edges} open edges" if surface.open_edges else "inconsistently oriented"
        print(f"closed:     no ({why}; area {surface.area:.6g})")


def _writer_options(pairs: Sequence[str]) -> dict[str, Any]:
    """``KEY=VALUE`` words as writer options: true/false, none, integers, numbers, else text."""
    options: dict[str, Any] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise ConfigError(f"--option {pair!r}: give KEY=VALUE, such as binary=true")
        words: dict[str, Any] = {"true": True, "false": False, "none": None}
        options[key] = words.get(text.lower(), text)
        for kind in (float, int):  # an integer wins over a float
            with contextlib.suppress(ValueError):
                options[key] = kind(text)
    return options


def cmd_convert(args: argparse.Namespace) -> int:
    """Read every frame of IN and write it to OUT, in the formats their names (or flags) say.
    ``OUT.xdmf`` writes the H5MD file ``OUT.h5`` with that XDMF sidecar."""
    trajectory, name, _ = _open(args.input, args.input_format)
    output, writer = Path(args.output), args.output_format
    try:
        spec = registry.writer_for(output, writer)
    except PluginNotFound:
        if output.suffix.lower() != ".xdmf":
            raise
        output = output.with_suffix(".h5")  # an XDMF file is the sidecar of an H5MD one
        spec = registry.writer_for(output, "h5md")
    options = ({"units": args.units} if args.units else {}) | _writer_options(args.option or ())
    unknown = sorted(set(options) - set(spec.options))
    if unknown:
        takes = ", ".join(f"{k} (default {v!r})" for k, v in spec.options.items()) or "none"
        raise ConfigError(f"The {spec.name} writer takes no option {unknown}; its options: {takes}")
    if args.dt is not None and not (np.isfinite(args.dt) and args.dt > 0):
        raise ConfigError(f"--dt {args.dt!r}: give the time step in seconds, a number > 0")
    output.parent.mkdir(parents=True, exist_ok=True)
    with trajectory, spec.open(output, **options) as out:
        count = 0
        for frame in _progress(trajectory, len(trajectory), "converting"):
            if args.dt is not None and frame.time is None and frame.timestep is not None:
                frame.time = frame.timestep * args.dt
            out.write_frame(frame)
            count += 1
    print(f"converted {count} frames from {args.input} ({name}) to {output} ({spec.name})")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """The hopper discharge study: simulation, analysis, plots and summary in the output folder."""
    summary = demo.run(
        args.output,
        engine=args.engine,
        particles=args.particles,
        progress=False if args.no_progress else None,
        report=lambda text: print(f"pygran demo: {text}"),
        nprocs=args.nprocs,
    )
    print(summary.text(), end="")
    print(
        f"plots in {Path(args.output).resolve() / 'hopper.png'}; trajectory in traj.h5md "
        "(traj.xdmf for ParaView), walls in walls.pvd"
    )
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    """Physics checks of an engine against closed forms, as a table and a summary line;
    non-zero exit when a check failed or none could run."""
    engine = resolve_engine(args.engine)
    results = validation.run_validation(
        engine,
        checks=args.check,
        output=args.output,
        progress=lambda name: print(f"checking {name} ...", file=sys.stderr),
    )
    print(validation.format_table(results))
    status = validation.exit_status(results)
    line = validation.summary(results, engine)
    print(f"pygran: error: {line}" if status else line, file=sys.stderr if status else sys.stdout)
    return status


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pygran", description="PyGran: DEM simulation and analysis.")
    parser.add_argument("--version", action="version", version=f"pygran {version('pygran-core')}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    plugins = commands.add_parser("plugins", help="list installed engines, models, readers and writers")
    plugins.set_defaults(func=cmd_plugins)
    info = commands.add_parser("info", help="summarise a trajectory or mesh file (or a quoted glob)")
    info.add_argument("file", help="a file, a quoted glob such as 'particles*.dump', ...")
    info.add_argument("--format", help="reader name (default: detected from the file)")
    info.set_defaults(func=cmd_info)
    convert = commands.add_parser("convert", help="convert a trajectory, e.g. a dump glob to H5MD")
    convert.add_argument("input", help="a file or a quoted glob")
    convert.add_argument("output", help="the file to write; '*' in a dump name writes a file per frame")
    convert.add_argument("--from", dest="input_format", help="reader name (default: detected)")
    convert.add_argument("--to", dest="output_format", help="writer name (default: from the extension)")
    convert.add_argument("--units", help="unit system written into the output (H5MD: si)")
    convert.add_argument(
        "--dt", type=float, help="time step (s): frames without a time (dumps) get step x dt as their time"
    )
    convert.add_argument(
        "--option", action="append", metavar="KEY=VALUE", help="writer option, e.g. binary=true (repeatable)"
    )
    convert.set_defaults(func=cmd_convert)
    demo = commands.add_parser("demo", help="run the hopper discharge study and analyse it")
    demo.add_argument("--engine", default="native", help="engine to run on (default: native)")
    demo.add_argument("--particles", type=int, help="number of particles (default: 3000)")
    demo.add_argument("--output", default="pygran-demo", help="output folder (default: ./pygran-demo)")
    demo.add_argument(
        "--nprocs",
        type=int,
        help="MPI ranks for engines that run under MPI (default: every core when mpirun exists)",
    )
    demo.add_argument("--no-progress", action="store_true", help="no progress bars")
    demo.set_defaults(func=cmd_demo)
    validate = commands.add_parser("validate", help="check an engine's physics against closed forms")
    validate.add_argument("--engine", help="engine to check (default: the one DEM picks, native)")
    validate.add_argument(
        "--check", action="append", choices=list(validation.CHECKS), help="run only this check (repeatable)"
    )
    validate.add_argument("--output", help="keep the simulations in this folder (default: a temporary one)")
    validate.set_defaults(func=cmd_validate)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pygran`` console script; returns the exit status."""
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        status = func(args)
        sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
        return status
    except PyGranError as exc:
        print(f"pygran: error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # the reader of our output left (`pygran info ... | head`): stop quietly, as C tools do;
        # stdout goes to /dev/null so that the interpreter's final flush cannot fail again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    raise SystemExit(main())
