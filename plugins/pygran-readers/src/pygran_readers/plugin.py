"""Registers the pygran-readers file formats with PyGran: VTK (legacy, VTU, VTP), ParaView's
``.pvd`` series index and YADE output.

The LIGGGHTS dump, H5MD and STL are the core's own (``pygran_core.formats``). Discovery
imports this module and, through it, the format modules, which need numpy and the standard
library only: the plugin parses and writes VTK itself, without the vtk package.
"""

from __future__ import annotations

from pygran_core.hookspecs import ReaderSpec, WriterSpec, hookimpl
from pygran_readers import series, vtk, xmlwriter, yade


@hookimpl
def pygran_readers():
    # "yade-vtk" before "vtk": the registry asks can_open in this order, and vtk's accepts any VTK file.
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
        name="pvd",
        extensions=(".pvd",),
        open=vtk.PVDTrajectory,
        can_open=series.can_open,
        kinds=frozenset({"mesh", "particles"}),
        description="ParaView .pvd index of a VTK series: each frame's file, time and step",
    )


@hookimpl
def pygran_writers():
    yield WriterSpec(
        name="vtk",
        extensions=(".vtk",),
        open=vtk.VTKWriter,
        kinds=frozenset({"mesh", "particles"}),
        description="legacy VTK, a file per frame ('*' in the name is the step), indexed in a .pvd",
        options={"binary": False, "index": None},
    )
    yield WriterSpec(
        name="vtp",
        extensions=(".vtp",),
        open=xmlwriter.VTPWriter,
        kinds=frozenset({"mesh", "particles"}),
        description="VTK XML polydata, a file per frame ('*' in the name is the step), indexed in a .pvd",
        options={"index": None},
    )
    yield WriterSpec(
        name="vtu",
        extensions=(".vtu",),
        open=xmlwriter.VTUWriter,
        kinds=frozenset({"mesh", "particles"}),
        description="VTK XML unstructured grid, a file per frame ('*' is the step), indexed in a .pvd",
        options={"index": None},
    )
    yield WriterSpec(
        name="pvd",
        extensions=(".pvd",),
        open=xmlwriter.PVDWriter,
        kinds=frozenset({"mesh", "particles"}),
        description="ParaView series: out.pvd indexing out_<step>.vtp, one per frame",
    )
