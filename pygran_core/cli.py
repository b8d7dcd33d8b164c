"""The ``pygran`` command."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from importlib.metadata import version

from pygran_core import registry
from pygran_core.errors import PyGranError


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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pygran", description="PyGran: DEM simulation and analysis.")
    parser.add_argument("--version", action="version", version=f"pygran {version('pygran-core')}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    plugins = commands.add_parser("plugins", help="list installed engines, models, readers and writers")
    plugins.set_defaults(func=cmd_plugins)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pygran`` console script; returns the exit status."""
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except PyGranError as exc:
        print(f"pygran: error: {exc}")
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
