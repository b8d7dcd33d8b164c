"""The file formats the core itself needs, registered like any plugin's readers and writers.

The LIGGGHTS text dump (the default trajectory of every engine), H5MD (the trajectory that
checkpoints cut back and the demo writes; h5py is already a core dependency) and STL (mesh
walls). VTK, VTU/VTP and YADE's output come with the ``pygran-readers`` plugin.
"""
