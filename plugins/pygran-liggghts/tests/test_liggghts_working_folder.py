"""A LIGGGHTS simulation writes only into its output folder, never into the script's working
folder: LIGGGHTS writes ``log.cite`` there when a cited feature (``neighbor multi``) runs,
unless told not to."""

from pygran_liggghts.library import find_library

from pygran_core import params, simulation
from pygran_core.testing.solvers import require_solver


def test_nothing_lands_beside_the_script(tmp_path, monkeypatch):
    require_solver(find_library)
    monkeypatch.chdir(tmp_path)
    species = ({"material": params.glass, "radius": 5e-4}, {"material": params.glass, "radius": 5e-3})
    with simulation.DEM(
        engine="liggghts",
        box=(0, 0.05, 0, 0.05, 0, 0.05),
        dt=1e-6,
        output="out",
        nns_type="multi",
        species=species,
        progress=False,
    ) as sim:
        sim.createParticles(1, "single", 0.01, 0.01, 0.01)
        sim.createParticles(2, "single", 0.03, 0.03, 0.03)
        sim.run(10)
    assert "neighbor 0.0005 multi" in (tmp_path / "out" / "in.pygran").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
