"""The readers plugin is discovered through its entry point and adds the VTK family."""

from pygran_core import registry


def test_registered_with_its_formats():
    assert registry.plugins()["readers"][0] == "pygran-readers"
    readers = registry.available("reader")
    assert {name: readers[name].distribution for name in ("vtk", "yade-vtk", "dump", "h5md", "stl")} == {
        "vtk": "pygran-readers",
        "yade-vtk": "pygran-readers",
        "dump": "pygran-core",
        "h5md": "pygran-core",
        "stl": "pygran-core",
    }
    assert registry.available("writer")["vtk"].distribution == "pygran-readers"
