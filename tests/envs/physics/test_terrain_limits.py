"""Course size bounds and the exact round trip of every terrain spec."""

from __future__ import annotations

import pytest

from envs.physics.terrain import MAX_VERTICES, Terrain

COURSES = {
    "flat": Terrain.flat(0.1),
    "slope": Terrain.slope(-0.05, 0.2),
    "stairs": Terrain.stairs([0.5, 1.0], [0.05, -0.1]),
    "staircase": Terrain.staircase(0.4, 3, 0.3, 0.01),
    "blocks": Terrain.random_blocks(3, 0.3, 4.0),
    "piecewise": Terrain.random_piecewise(4, 0.3, 4.0),
    "points": Terrain.from_points([0.0, 1.0, 1.0, 2.0], [0.0, 0.0, 0.1, 0.2]),
    "flat_with_vertices": Terrain.from_dict(
        {"kind": "flat", "xs": [0.0, 0.5, 1.0], "ys": [0.0, 0.02, 0.0]}
    ),
    "stairs_with_vertices": Terrain.from_dict(
        {"kind": "stairs", "edges": [0.5], "rises": [0.1], "xs": [0.0, 2.0], "ys": [0.0, 0.1]}
    ),
    "blocks_with_vertices": Terrain.from_dict(
        {"kind": "blocks", "seed": 1, "xs": [0.0, 1.0, 1.0, 3.0], "ys": [0.0, 0.0, 0.1, 0.1]}
    ),
}


@pytest.mark.parametrize("name", sorted(COURSES))
def test_every_terrain_round_trips_through_its_dict(name):
    t = COURSES[name]
    again = Terrain.from_dict(t.to_dict())
    assert again == t and again.kind == t.kind and again.to_dict() == t.to_dict()


def test_a_custom_polyline_of_a_kind_is_kept_by_to_dict():
    t = COURSES["flat_with_vertices"]
    assert t.to_dict()["xs"] == [0.0, 0.5, 1.0] and t.height(0.5) == 0.02
    with pytest.raises(ValueError, match="give both 'xs' and 'ys'"):
        Terrain.from_dict({"kind": "flat", "xs": [0.0, 1.0]})


@pytest.mark.parametrize("kind", ["blocks", "piecewise"])
@pytest.mark.parametrize("length", [1e7, 1e12])
def test_course_length_is_bounded(kind, length):
    with pytest.raises(ValueError, match=r"'length' = .* out of range; allowed: \[0, 10000\] m"):
        Terrain.from_dict({"kind": kind, "seed": 0, "length": length})


@pytest.mark.parametrize(
    "spec,field",
    [
        ({"kind": "blocks", "seed": 0, "length": 1e4, "width_range": [1e-3, 0.1]}, "width_range"),
        ({"kind": "blocks", "seed": 0, "width_range": [1e-320, 0.1]}, "width_range"),
        ({"kind": "piecewise", "seed": 0, "segment_range": [1e-6, 0.1]}, "segment_range"),
    ],
)
def test_vertex_count_of_random_courses_is_bounded(spec, field):
    with pytest.raises(ValueError, match=rf"at most {MAX_VERTICES} .*'{field}'"):
        Terrain.from_dict(spec)


def test_vertex_count_of_given_courses_is_bounded():
    n = MAX_VERTICES + 1
    with pytest.raises(ValueError, match=rf"{n} vertices; allowed: at most {MAX_VERTICES}"):
        Terrain.from_points(list(range(n)), [0.0] * n)
    with pytest.raises(ValueError, match=r"'edges' has .* entries; allowed: at most"):
        Terrain.stairs(list(range(n)), [0.0] * n)
    with pytest.raises(ValueError, match=r"'count' = 1000000000; allowed: integer in \[0, "):
        Terrain.staircase(0.5, 10**9, 0.3, 0.01)
    assert Terrain.staircase(0.5, 3.0, 0.3, 0.01) == Terrain.staircase(0.5, 3, 0.3, 0.01)
