"""Registers the core's formats (entry-point group ``pygran.readers`` for plugins)."""

from __future__ import annotations

from collections.abc import Iterator

from pygran_core.formats import dump, h5md, stl, xdmf
from pygran_core.hookspecs import ReaderSpec, WriterSpec, hookimpl


@hookimpl
def pygran_readers() -> Iterator[ReaderSpec]:
    yield ReaderSpec(
        name="dump",
        extensions=(".dump", ".dump.gz", ".lammpstrj", ".lammpstrj.gz"),
        open=dump.DumpTrajectory,
        can_open=dump.can_open,
        kinds=frozenset({"particles", "contacts"}),
        description="LIGGGHTS/LAMMPS text dump (multi-frame, globs, gzip); dump local contacts",
    )
    yield ReaderSpec(
        name="stl",
        extensions=(".stl",),
        open=stl.STLTrajectory,
        kinds=frozenset({"mesh"}),
        description="STL surface mesh (ASCII or binary)",
    )
    yield ReaderSpec(
        name="h5md",
        extensions=(".h5md", ".h5", ".hdf5"),
        open=h5md.open_h5md,
        can_open=h5md.can_open,
        kinds=frozenset({"particles", "contacts"}),
        description="HDF5 in the H5MD layout (particles, contacts)",
    )
    yield ReaderSpec(
        name="xdmf",
        extensions=(".xdmf",),
        open=xdmf.XdmfTrajectory,
        kinds=frozenset({"particles"}),
        description="the XDMF sidecar of an H5MD trajectory (ParaView's view of it), read back",
    )


@hookimpl
def pygran_writers() -> Iterator[WriterSpec]:
    yield WriterSpec(
        name="dump",
        extensions=(".dump",),
        open=dump.DumpWriter,
        kinds=frozenset({"particles", "contacts"}),
        description="LIGGGHTS/LAMMPS text dump; '*' in the name writes a file per frame",
        options={"time": False},
    )
    yield WriterSpec(
        name="h5md",
        extensions=(".h5md", ".h5", ".hdf5"),
        open=h5md.H5MDWriter,
        kinds=frozenset({"particles", "contacts"}),
        description="HDF5 in the H5MD layout, flushed frame by frame",
        options={"group": "trajectory", "units": "si", "compression": 4, "contacts": False, "xdmf": True},
    )
    yield WriterSpec(
        name="stl",
        extensions=(".stl",),
        open=stl.STLWriter,
        kinds=frozenset({"mesh"}),
        description="ASCII STL surface mesh, polygons as triangle fans; '*' in the name: a file per frame",
    )
