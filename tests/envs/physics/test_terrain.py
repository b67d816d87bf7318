"""Terrain: kinds, queries, exact round trips, clear errors."""

import math

import numpy as np
import pytest

from envs.physics.terrain import Terrain, as_terrain, terrain_height

ALL_KINDS = [
    Terrain.flat(0.1),
    Terrain.slope(-0.0525, height=0.2),
    Terrain.stairs([0.4, 0.62], [-0.03, -0.03]),
    Terrain.staircase(0.5, 4, 0.3, 0.05),
    Terrain.random_blocks(seed=3, length=5.0),
    Terrain.random_piecewise(seed=4, length=5.0),
    Terrain.from_points([0.0, 1.0, 1.0, 2.0], [0.0, 0.0, 0.1, 0.3]),
]


@pytest.mark.parametrize("terrain", ALL_KINDS, ids=lambda t: t.kind)
def test_dict_and_yaml_round_trips_are_exact(terrain, tmp_path):
    again = Terrain.from_dict(terrain.to_dict())
    assert again == terrain and again.kind == terrain.kind
    path = tmp_path / "course.yaml"
    terrain.to_yaml(path)
    loaded = Terrain.from_yaml(path)
    assert loaded == terrain
    x = np.linspace(-2.0, 7.0, 301)
    assert np.array_equal(loaded.height(x), terrain.height(x))


def test_random_courses_are_seeded():
    assert Terrain.random_blocks(seed=7) == Terrain.random_blocks(seed=7)
    assert Terrain.random_blocks(seed=7) != Terrain.random_blocks(seed=8)
    assert Terrain.random_piecewise(seed=7) == Terrain.random_piecewise(seed=7)
    b = Terrain.random_blocks(seed=1, start=0.5, length=3.0, height_range=(-0.02, 0.02))
    faces = b.vertical_faces()
    assert faces and all(0.5 <= x <= 3.5 + 0.4 for x, _, _ in faces)
    assert all(abs(y1 - y0) <= 0.02 for _, y0, y1 in faces)
    assert b.height(0.0) == 0.0


def test_heights_slopes_and_faces():
    s = Terrain.slope(-0.0525, height=0.2)
    assert math.isclose(s.height(2.0), 0.2 + 2.0 * math.tan(-0.0525), rel_tol=1e-15)
    assert math.isclose(s.slope_at(-3.0), math.tan(-0.0525), rel_tol=1e-15)
    st = Terrain.stairs([0.4, 0.62], [-0.03, -0.03])
    assert st.height(0.39) == 0.0 and st.height(0.5) == -0.03 and st.height(1.0) == -0.06
    assert st.height(0.4) == 0.0  # the upper height on a face
    assert st.vertical_faces() == [(0.4, 0.0, -0.03), (0.62, -0.03, -0.06)]
    assert st.next_edge(0.0) == 0.4 and st.next_edge(0.4) == 0.62
    assert st.next_edge(0.7) == math.inf
    up = Terrain.staircase(0.5, 2, 0.3, 0.05)
    assert up.height(0.5) == 0.05 and up.height(0.81) == 0.1
    xs, ys = up.arrays()
    assert terrain_height(xs, ys, xs.size, 0.65) == 0.05


@pytest.mark.parametrize(
    "spec,match",
    [
        ({"kind": "volcano"}, "unknown terrain kind"),
        ({"height": 0.0}, "kind"),
        ("nonsense", "unknown terrain kind"),
        ({"kind": "slope", "angle": 0.7}, "angle"),
        ({"kind": "slope", "angle": float("nan")}, "angle"),
        ({"kind": "slope", "angle": 0.1, "tilt": 2}, "bad fields"),
        ({"kind": "stairs", "edges": [0.4, 0.3], "rises": [0.1, 0.1]}, "edges"),
        ({"kind": "stairs", "edges": [0.4], "rises": [0.1, 0.1]}, "differ in length"),
        ({"kind": "blocks", "seed": -1}, "seed"),
        ({"kind": "blocks", "seed": 1, "width_range": [0.0, 0.1]}, "width_range"),
        ({"kind": "blocks", "seed": 1, "height_range": [0.1, -0.1]}, "height_range"),
        ({"kind": "piecewise", "seed": 1, "slope_range": [-2, 2]}, "slope_range"),
        ({"kind": "points", "xs": [0, 2, 1], "ys": [0, 0, 0]}, "non-decreasing"),
        ({"kind": "points", "xs": [0, 1, 1, 1], "ys": [0, 0, 1, 2]}, "at most two"),
        ({"kind": "points", "xs": [0, 1], "ys": [0, float("inf")]}, "finite"),
    ],
)
def test_bad_specs_raise_clear_errors(spec, match):
    with pytest.raises(ValueError, match=match):
        as_terrain(spec)


def test_blocks_without_a_seed_is_an_error():
    with pytest.raises(ValueError, match="seed"):
        as_terrain("blocks")
