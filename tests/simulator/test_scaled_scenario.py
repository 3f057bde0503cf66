"""The benchmarks' scaled plant: copies of the bundled loops that build and run."""

from __future__ import annotations

from simhelpers import START, scaled_scenario

from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import load_scenario


def test_copies_of_a_coupled_loop_take_their_load_from_their_own_group() -> None:
    """The bundled plant couples loops (a cycle travelling downstream, ``from_loop``): each
    copy must point at the copy in its group, or the plant cannot be built (the service,
    ingest, capacity and scale benchmarks all failed with KeyError 'FIC801')."""
    m = len(load_scenario().loop)
    sc = scaled_scenario(2 * m + 3)
    plant = Plant(sc, START)
    for _ in range(5):
        plant.step()
    sources = {spec.id: d.from_loop for spec in sc.loop for d in spec.disturbances if d.from_loop}
    assert sources, "the bundled plant has a coupled loop"
    for loop_id, source in sources.items():
        assert int(source[1:]) // m == int(loop_id[1:]) // m
        assert int(source[1:]) < int(loop_id[1:])
