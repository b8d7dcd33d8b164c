"""A YADE script that makes VTKRecorder output for the reader tests, and what it must hold.

``yade -n -x yade_vtkrecorder.py OUT [ascii]``: spheres of two materials and two radii,
spinning, fall onto a box and a facet box while VTKRecorder writes ``OUT/yade_*.vtu`` every
1000 iterations (binary, or ASCII with ``ascii``); a PyRunner after it saves each sphere's
state at the same iterations to ``OUT/expected.<iter>.npz``. Spheres are added at
iterations 500 and 1500 and every fourth one erased at 2500, so the files at 0, 1000, 2000
and 3000 hold 0, 12, 24 and 18 spheres.
"""

import sys

import numpy as np
from yade import O, geom, utils
from yade.wrapper import (
    Bo1_Box_Aabb,
    Bo1_Facet_Aabb,
    Bo1_Sphere_Aabb,
    ForceResetter,
    FrictMat,
    Ig2_Box_Sphere_ScGeom,
    Ig2_Facet_Sphere_ScGeom,
    Ig2_Sphere_Sphere_ScGeom,
    InsertionSortCollider,
    InteractionLoop,
    Ip2_FrictMat_FrictMat_FrictPhys,
    Law2_ScGeom_FrictPhys_CundallStrack,
    NewtonIntegrator,
    PyRunner,
    Sphere,
    VTKRecorder,
)

OUT = sys.argv[1]
ASCII = sys.argv[2:] == ["ascii"]
steel = O.materials.append(FrictMat(young=1e7, poisson=0.3, density=7800, frictionAngle=0.5))
glass = O.materials.append(FrictMat(young=5e6, poisson=0.25, density=2500, frictionAngle=0.4))
O.bodies.append(utils.box(center=(0, 0, -0.01), extents=(0.1, 0.1, 0.01), fixed=True, material=steel))
O.bodies.append(geom.facetBox((0, 0, 0.05), (0.1, 0.1, 0.05), wallMask=31, material=steel))


def add_spheres(z):
    for i in range(12):
        centre = (-0.05 + 0.02 * (i % 6), -0.04 + 0.02 * (i // 6), z + 0.001 * i)
        radius = 0.004 if i % 2 else 0.006
        body = utils.sphere(centre, radius, material=glass if i % 3 else steel, color=(i / 12, 0.5, 0.2))
        body.state.vel = (0.01 * i, -0.02, 0.0)
        body.state.angVel = (i, -2.0 * i, 0.5)
        O.bodies.append(body)


def events():
    if O.iter == 500:
        add_spheres(0.02)
    elif O.iter == 1500:
        add_spheres(0.06)
    elif O.iter == 2500:
        for body in spheres()[::4]:
            O.bodies.erase(body.id)


def spheres():
    return [b for b in O.bodies if isinstance(b.shape, Sphere)]


def record():
    found = spheres()
    np.savez(
        f"{OUT}/expected.{O.iter}.npz",
        id=np.array([b.id for b in found], dtype=np.int64),
        material=np.array([b.material.id for b in found], dtype=np.int64),
        radius=np.array([b.shape.radius for b in found]),
        position=np.array([tuple(b.state.pos) for b in found]).reshape(-1, 3),
        velocity=np.array([tuple(b.state.vel) for b in found]).reshape(-1, 3),
        omega=np.array([tuple(b.state.angVel) for b in found]).reshape(-1, 3),
        mask=np.array([b.mask for b in found], dtype=np.int64),
        clump=np.array([b.clumpId for b in found], dtype=np.int64),
        color=np.array([tuple(b.shape.color) for b in found]).reshape(-1, 3),
    )


O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb(), Bo1_Facet_Aabb()]),
    InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom(), Ig2_Box_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom()],
        [Ip2_FrictMat_FrictMat_FrictPhys()],
        [Law2_ScGeom_FrictPhys_CundallStrack()],
    ),
    NewtonIntegrator(gravity=(0, 0, -9.81), damping=0.2),
    VTKRecorder(
        fileName=f"{OUT}/yade_",
        recorders=["spheres", "velocity", "id", "color", "materialId", "clumpId", "mask", "facets", "boxes"],
        iterPeriod=1000,
        ascii=ASCII,
    ),
    PyRunner(command="record()", iterPeriod=1000, initRun=True),
    PyRunner(command="events()", iterPeriod=500),
]
O.dt = 2e-5
O.run(3001, True)
