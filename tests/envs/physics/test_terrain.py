"""Terrain: kinds, queries, exact round trips, clear errors."""

import math

import numpy as np
import pytest

from envs.physics.terrain import (
    NAMED_KINDS,
    TERRAIN_CONFIG_DIR,
    Terrain,
    as_terrain,
    available_terrains,
    terrain_height,
    terrain_spec,
)

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
        ("nonsense", "unknown terrain 'nonsense'; allowed"),
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


def test_a_shipped_course_name_resolves_to_its_file():
    assert {"flat", "paper_stairs", "rough_blocks", "classic_slope"} <= set(available_terrains())
    assert terrain_spec("paper_stairs")["kind"] == "stairs"
    stairs = as_terrain("paper_stairs")
    assert stairs == Terrain.from_yaml(TERRAIN_CONFIG_DIR / "paper_stairs.yaml")
    assert stairs == Terrain.stairs([0.40, 0.62], [-0.03, -0.03])
    assert as_terrain("classic_slope") == Terrain.slope(-0.0525)
    # a random course without a seed is a generator: a spec, not a Terrain
    assert terrain_spec("rough_blocks") == {
        "kind": "blocks", "start": 0.3, "length": 12.0, "width_range": [0.1, 0.3],
        "height_range": [-0.0075, 0.0075],
    }  # fmt: skip
    with pytest.raises(ValueError, match="needs a seed"):
        as_terrain("rough_blocks")


def test_flat_is_a_course_and_a_kind_with_one_meaning():
    assert terrain_spec("flat") == {"kind": "flat", "height": 0.0}  # configs/terrains/flat.yaml
    flat = as_terrain("flat")
    assert flat == Terrain.flat() and flat.to_dict() == Terrain.flat().to_dict()


def test_a_yaml_path_resolves_to_its_spec(tmp_path):
    course = Terrain.staircase(0.5, 3, 0.3, 0.02)
    for name in ("course.yaml", "course.yml"):
        course.to_yaml(tmp_path / name)
        assert terrain_spec(str(tmp_path / name)) == course.to_dict()
        assert as_terrain(tmp_path / name) == course  # a path object too
    with pytest.raises(ValueError, match="does not exist"):
        terrain_spec(str(tmp_path / "missing.yaml"))
    (tmp_path / "list.yaml").write_text("[1, 2]\n")
    with pytest.raises(ValueError, match="spec mapping"):
        terrain_spec(str(tmp_path / "list.yaml"))


def test_a_kind_name_gets_default_fields():
    assert as_terrain("slope") == Terrain.slope(0.0)
    assert terrain_spec("slope") == {"kind": "slope", "angle": 0.0}
    for kind in ("blocks", "piecewise"):
        assert terrain_spec(kind) == {"kind": kind}  # a generator with default fields
        with pytest.raises(ValueError, match="needs a seed"):
            as_terrain(kind)
    assert set(NAMED_KINDS) == {"flat", "slope", "blocks", "piecewise"}
    # no shipped course shadows a kind, except "flat" (the same ground)
    assert set(available_terrains()) & set(NAMED_KINDS) == {"flat"}


def test_terrain_arguments_other_than_names_pass_through():
    course = Terrain.flat(0.2)
    assert terrain_spec(course) is course and as_terrain(course) is course
    spec = {"kind": "stairs", "edges": [0.4], "rises": [0.1]}
    copy = terrain_spec(spec)
    assert copy == spec and copy is not spec and copy["edges"] is not spec["edges"]
    assert as_terrain(spec) == Terrain.stairs([0.4], [0.1])


@pytest.mark.parametrize("name", ["stairs", "points", "no_such_course", "Flat", ""])
def test_an_unknown_name_lists_what_is_allowed(name):
    with pytest.raises(ValueError, match="unknown terrain") as err:
        as_terrain(name)
    for allowed in ("configs/terrains", "paper_stairs", "YAML", "'slope'", "spec dict"):
        assert allowed in str(err.value)
    with pytest.raises(ValueError, match="must be a Terrain"):
        terrain_spec(3.0)
