"""Registers the pygran-readers file formats with PyGran.

Only this module is imported at plugin discovery; the format modules import numpy only,
and h5py, meshio and vtk are imported inside the functions that use them.
"""

from __future__ import annotations

from pygran_core.hookspecs import ReaderSpec, WriterSpec, hookimpl
from pygran_readers import dump, h5md, stl, vtk, yade


@hookimpl
def pygran_readers():
    yield ReaderSpec(
        name="dump",
        extensions=(".dump", ".dump.gz", ".lammpstrj", ".lammpstrj.gz"),
        open=dump.DumpTrajectory,
        can_open=dump.can_open,
        description="LIGGGHTS/LAMMPS text dump (multi-frame, globs, gzip)",
    )
    # Before "vtk": the registry asks can_open in this order, and vtk's accepts any VTK file.
    yield ReaderSpec(
        name="yade-vtk",
        extensions=(".vtu",),
        open=yade.YadeTrajectory,
        can_open=yade.can_open,
        kinds=frozenset({"mesh", "particles"}),
        description="YADE VTKRecorder output: <name>spheres.<iter>.vtu particles, facets/boxes meshes",
    )
    yield ReaderSpec(
        name="vtk",
        extensions=(".vtk", ".vtu", ".vtp"),
        open=vtk.VTKTrajectory,
        can_open=vtk.can_open,
        kinds=frozenset({"mesh", "particles"}),
        description="VTK legacy and XML meshes or particle points, one frame per file",
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
        open=h5md.H5MDTrajectory,
        can_open=h5md.can_open,
        description="HDF5 in the H5MD layout",
    )


@hookimpl
def pygran_writers():
    yield WriterSpec(
        name="dump",
        extensions=(".dump",),
        open=dump.DumpWriter,
        description="LIGGGHTS/LAMMPS text dump; '*' in the name writes a file per frame",
    )
    yield WriterSpec(
        name="h5md",
        extensions=(".h5md", ".h5", ".hdf5"),
        open=h5md.H5MDWriter,
        description="HDF5 in the H5MD layout, flushed frame by frame",
        options={"group": "all", "units": None, "compression": 4},
    )
    yield WriterSpec(
        name="vtk",
        extensions=(".vtk",),
        open=vtk.VTKWriter,
        kinds=frozenset({"mesh", "particles"}),
        description="legacy VTK, a file per frame ('*' in the name is the timestep)",
        options={"binary": False},
    )
