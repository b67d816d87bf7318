"""Foothold selection: the rules, checked one by one against a plain rendering of them, and the
chains of footholds that rank a step's candidates."""

import math

import numpy as np
import pytest

from controllers.planner import PlannerConfig
from controllers.planner.footholds import (
    FootholdChains,
    TerrainMap,
    candidate_footholds,
    touchdown_configuration,
)
from envs.physics import model
from envs.physics.terrain import Terrain

TERRAINS = {
    "flat": Terrain.flat(),
    "blocks": Terrain.random_blocks(3, 0.3, 3.0, (0.1, 0.3), (-0.015, 0.015)),
    "stairs_up": Terrain.staircase(0.4, 3, 0.3, 0.01),
    "stairs_down": Terrain.stairs([0.4, 0.62], [-0.01, -0.01]),
    "slope": Terrain.slope(-0.0525),
}


def admissible(tmap, stance, rules, l):  # noqa: E741
    """The rules of :func:`candidate_footholds`, written out point by point."""
    x0, y0 = stance
    n = int(math.floor((rules.step_max - rules.step_min) / rules.resolution)) + 1
    out = []
    for k in range(n):
        x = x0 + rules.step_min + rules.resolution * k
        y = float(tmap.height(x))
        dh = y - y0
        if tmap.features.size and np.min(np.abs(tmap.features - x)) < rules.edge_margin:
            continue
        if not -rules.max_drop <= dh <= rules.max_rise:
            continue
        q1, _ = touchdown_configuration(x - x0, dh, l)
        if not rules.q1_min <= q1 <= rules.q1_max:
            continue
        ok = True
        for xf, ya, yb in tmap.faces:
            drop, rise = ya - yb, yb - ya
            if x0 < xf < x and drop > 0:  # room behind the foothold after a step down
                ok &= x - xf >= rules.edge_margin + rules.drop_margin * drop
            if x < xf and 0 < rise <= rules.max_rise:  # room before a step up ahead
                ok &= xf - x >= rules.edge_margin + rules.rise_margin * rise
        if ok:
            out.append((x, y, abs(x - x0 - rules.step_length)))
    return out


@pytest.mark.parametrize("terrain", list(TERRAINS))
@pytest.mark.parametrize("robot,l", [("paper", 0.32), ("classic", 1.0)])
def test_candidates_follow_the_rules(robot, l, terrain):  # noqa: E741
    rules = PlannerConfig.for_robot(robot).rules()
    tmap = TerrainMap(TERRAINS[terrain])
    rng = np.random.default_rng(0)
    for x0 in rng.uniform(-0.1, 2.5 if l < 1 else 4.0, 40):
        stance = (float(x0), float(tmap.height(x0)))
        cx, cy, why = candidate_footholds(tmap, stance, rules, l)
        ref = admissible(tmap, stance, rules, l)
        np.testing.assert_allclose(np.sort(cx), [r[0] for r in ref], atol=1e-12)
        np.testing.assert_allclose(cy, tmap.height(cx), atol=0)
        score = np.abs(cx - x0 - rules.step_length)
        assert np.all(np.diff(score) >= -1e-12)  # best first
        assert (cx.size == 0) == (why != "")


def test_ranking_by_touchdown_angle():
    rules = PlannerConfig.for_robot("paper").rules()
    tmap = TerrainMap(TERRAINS["blocks"])
    stance = (0.5, float(tmap.height(0.5)))
    target = 0.2
    cx, cy, _ = candidate_footholds(tmap, stance, rules, 0.32, target, -0.2)
    q1, q2 = np.vectorize(touchdown_configuration)(cx - stance[0], cy - stance[1], 0.32)
    score = np.abs(q2 - target) + 0.1 * np.abs(cx - stance[0] - rules.step_length) / 0.32
    score += 2.0 * np.abs(q2 - q1 + 0.2)
    assert np.all(np.diff(score) >= -1e-12)


def test_footholds_near_a_step_down_riser_rank_after_the_others():
    """``drop_edge_margin``: the same admissible footholds; those closer than ``edge_margin +
    drop_edge_margin`` to a step-down riser (ahead of them or behind them) rank after every
    other one, each group in the order without it; 0 changes nothing."""
    tmap = TerrainMap(Terrain.stairs([0.30], [-0.005]))  # a 5 mm step down at x = 0.30
    stance = (0.14, 0.0)
    plain = PlannerConfig.for_robot("paper").rules()
    rules = PlannerConfig.for_robot("paper", drop_edge_margin=0.03).rules()
    ref, _, _ = candidate_footholds(tmap, stance, plain, 0.32)
    cx, cy, _ = candidate_footholds(tmap, stance, rules, 0.32)
    np.testing.assert_array_equal(np.sort(cx), np.sort(ref))
    near = np.abs(cx - 0.30) < rules.edge_margin + 0.03
    assert near.any() and (cx[near] < 0.30).any() and (cx[near] > 0.30).any()
    k = int(np.argmax(near))
    assert not near[:k].any() and near[k:].all()  # the near ones last
    clear = ref[np.abs(ref - 0.30) >= rules.edge_margin + 0.03]
    np.testing.assert_array_equal(cx[:k], clear)
    np.testing.assert_array_equal(cx[k:], ref[np.abs(ref - 0.30) < rules.edge_margin + 0.03])
    assert ref[0] in cx[k:]  # the best foothold without it is near the riser
    off = PlannerConfig.for_robot("paper", drop_edge_margin=0.0).rules()
    np.testing.assert_array_equal(candidate_footholds(tmap, stance, off, 0.32)[0], ref)
    # a step up is no such riser
    up = TerrainMap(Terrain.stairs([0.30], [0.005]))
    np.testing.assert_array_equal(
        candidate_footholds(up, stance, rules, 0.32)[0],
        candidate_footholds(up, stance, plain, 0.32)[0],
    )


def test_no_foothold_says_why():
    rules = PlannerConfig.for_robot("paper").rules()
    wall = TerrainMap(Terrain.stairs([0.05], [0.5]))
    cx, cy, why = candidate_footholds(wall, (0.0, 0.0), rules, 0.32)
    assert cx.size == 0 and cy.size == 0
    assert "no admissible foothold" in why and "height change" in why


def brute_reach(tmap, x, depth, rules, l):  # noqa: E741
    """Longest chain (at most ``depth``) of admissible footholds from a stance foot at ``x``
    rounded to 1 mm, by trying every candidate."""
    if depth <= 0:
        return 0
    xr = round(float(x), 3)
    cx, _, _ = candidate_footholds(tmap, (xr, float(tmap.height(xr))), rules, l)
    return max((1 + brute_reach(tmap, float(c), depth - 1, rules, l) for c in cx), default=0)


@pytest.mark.parametrize("terrain", ["stairs_up", "stairs_down", "blocks"])
def test_chain_lengths_match_an_exhaustive_search(terrain):
    cfg = PlannerConfig.for_robot("paper")
    tmap = TerrainMap(TERRAINS[terrain])
    chains = FootholdChains(cfg.rules(), 0.32, cfg.candidate_spacing)
    for x in np.linspace(0.0, 0.9, 10):
        ref = brute_reach(tmap, x, 2, cfg.rules(), 0.32)
        assert chains.reach(tmap, x, 2) == ref
        assert chains.chain(tmap, x, 2) == (ref >= 2)
    # stance feet far off the map, and a deeper horizon after shallower ones (a larger memo)
    for x in (float(tmap.xs[0]) - 3.0, float(tmap.xs[-1]) + 3.0):
        assert chains.reach(tmap, x, 2) == brute_reach(tmap, x, 2, cfg.rules(), 0.32)
    assert chains.reach(tmap, 0.3, 3) == brute_reach(tmap, 0.3, 3, cfg.rules(), 0.32)
    wall = TerrainMap(Terrain.stairs([0.4], [0.3]))
    assert chains.reach(wall, 0.0, 5) < 5
    assert "no admissible foothold" in chains.reach_break(wall, 0.0, 5)
    spanned = next(x for x in np.linspace(0.0, 0.9, 10) if chains.chain(tmap, x, 2))
    assert chains.reach_break(tmap, spanned, 2) == ""  # a chain that does not end


def test_ranked_candidates_pick_spaced_footholds_that_keep_a_chain():
    cfg = PlannerConfig.for_robot("paper")
    rules = cfg.rules()
    tmap = TerrainMap(TERRAINS["stairs_up"])
    chains = FootholdChains(rules, 0.32, cfg.candidate_spacing)
    stance = (0.2, float(tmap.height(0.2)))
    cx, cy, picks, why = chains.ranked(tmap, stance, 0.2, -0.2, 3, None, 4)
    ref_x, _, _ = candidate_footholds(tmap, stance, rules, 0.32, 0.2, -0.2)
    assert why == "" and np.array_equal(np.sort(cx), np.sort(ref_x))
    assert len(picks) == 4
    xs = cx[picks]
    assert np.min(np.abs(np.subtract.outer(xs, xs)) + np.eye(4)) >= cfg.candidate_spacing
    ranks = [chains.landing_rank(tmap, float(x), 3) for x in xs]
    assert ranks[0] == min(chains.landing_rank(tmap, float(x), 3) for x in cx)
    assert ranks == sorted(ranks)
    # a warm start: the candidate next to it comes first
    warm = float(cx[picks[-1]])
    cx2, _, picks2, _ = chains.ranked(tmap, stance, 0.2, -0.2, 3, warm, 4)
    assert abs(cx2[picks2[0]] - warm) < rules.resolution


def plain_ranked(tmap, stance, rules, l, spacing, theta, sigma, depth, warm_x, need):  # noqa: E741
    """The ranking rule of :meth:`FootholdChains.ranked`, written out in Python with the
    exhaustive chain lengths: every candidate ranked (0: chains continue however far the foot
    lands off by up to 8 mm, 1: by up to 4 mm, 2: from the foothold only, 3: no chain), the
    candidate nearest the warm start picked first, then spaced candidates in rank order."""
    cx, _, _ = candidate_footholds(tmap, stance, rules, l, theta, sigma)

    def rank(x):
        if brute_reach(tmap, x, depth, rules, l) < depth:
            return 3
        for r, s in enumerate((0.008, 0.004)):
            if min(brute_reach(tmap, x + d, depth, rules, l) for d in (-s, s)) >= depth:
                return r
        return 2

    ranks = [rank(float(x)) for x in cx]
    order = sorted(range(cx.size), key=lambda k: (ranks[k], k))
    picks = []
    near = [k for k in range(cx.size) if warm_x is not None and abs(cx[k] - warm_x) < 0.002]
    for k in [min(near, key=lambda k: (ranks[k], k))] if near else []:
        picks.append(k)
    for k in order:
        if len(picks) < need and all(abs(cx[k] - cx[p]) >= spacing for p in picks):
            picks.append(k)
    return cx[[k for k in picks]], [ranks[k] for k in picks]


@pytest.mark.parametrize("terrain", ["stairs_up", "stairs_down", "blocks"])
def test_the_compiled_ranking_picks_what_the_plain_rule_picks(terrain):
    """The picks of :meth:`FootholdChains.ranked` (lazily ranked, memoised, compiled) are the
    footholds the plain rule picks, with the same ranks, from stance feet along the course,
    with and without a warm start."""
    cfg = PlannerConfig.for_robot("paper")
    rules, l = cfg.rules(), 0.32  # noqa: E741
    tmap = TerrainMap(TERRAINS[terrain])
    chains = FootholdChains(rules, l, cfg.candidate_spacing)
    for x0 in np.linspace(0.05, 0.65, 7):
        stance = (float(x0), float(tmap.height(x0)))
        for warm in (None, float(x0) + 0.3):
            cx, _, picks, _ = chains.ranked(tmap, stance, 0.2, -0.2, 2, warm, 3)
            ref_x, ref_ranks = plain_ranked(
                tmap, stance, rules, l, cfg.candidate_spacing, 0.2, -0.2, 2, warm, 3
            )
            np.testing.assert_array_equal(cx[picks], ref_x)
            assert [chains.landing_rank(tmap, float(x), 2) for x in cx[picks]] == ref_ranks


def test_terrain_key_identifies_the_polyline():
    a, b = TerrainMap(TERRAINS["blocks"]), TerrainMap(TERRAINS["blocks"])
    assert a.key == b.key and a.key != TerrainMap(TERRAINS["flat"]).key


def test_coerce_resolves_terrain_arguments_like_the_simulator():
    stairs = Terrain.stairs([0.40, 0.62], [-0.03, -0.03])
    for arg in ("paper_stairs", stairs, stairs.to_dict()):
        assert TerrainMap.coerce(arg).key == TerrainMap(stairs).key
    assert TerrainMap.coerce("flat").terrain == Terrain.flat()
    tmap = TerrainMap(stairs)
    assert TerrainMap.coerce(tmap) is tmap
    x = np.linspace(0.0, 1.0, 51)
    scanned = TerrainMap.coerce((x, stairs.height(x)))
    assert len(scanned.faces) == 2
    with pytest.raises(ValueError, match="unknown terrain"):
        TerrainMap.coerce("stairs")


def test_the_planner_touchdown_configuration_is_the_model_one():
    """The planner uses the model's touchdown configuration (one formula), which puts the swing
    foot at the foothold and is NaN out of reach."""
    assert touchdown_configuration is model.touchdown_configuration
    rng = np.random.default_rng(5)
    for dx, dh in zip(rng.uniform(0.05, 0.7, 50), rng.uniform(-0.1, 0.1, 50)):
        q1, q2 = touchdown_configuration(dx, dh, 0.32)
        if math.hypot(dx, dh) > 0.64:
            assert math.isnan(q1)
            continue
        fx = 0.32 * (math.sin(q2) - math.sin(q2 - q1))
        fy = 0.32 * (math.cos(q2) - math.cos(q2 - q1))
        assert (fx, fy) == pytest.approx((dx, dh), abs=1e-14)


def test_relaxed_margins_apply_only_where_the_rules_leave_no_foothold():
    """On the paper's stairs a stance foot 0.29-0.31 m out has no admissible foothold: too far
    for a step before the riser at 0.40 m, too near for one past its drop margin. The relaxed
    rules (half the margins) give it footholds; everywhere else the candidates are the rules'
    own, and the chains that rank candidates keep the full margins."""
    cfg = PlannerConfig.for_robot("paper")
    assert cfg.relaxed_margin == 0.5
    rules, relaxed = cfg.rules(), cfg.relaxed_rules()
    assert relaxed.drop_margin == 0.5 * rules.drop_margin
    assert relaxed.rise_margin == 0.5 * rules.rise_margin
    assert PlannerConfig.for_robot("paper", relaxed_margin=1.0).relaxed_rules() is None
    tmap = TerrainMap(Terrain.stairs([0.40, 0.62], [-0.03, -0.03]))
    chains = FootholdChains(rules, 0.32, cfg.candidate_spacing, relaxed)
    gap = (0.30, 0.0)
    nominal, _, why = candidate_footholds(tmap, gap, rules, 0.32)
    assert nominal.size == 0 and "no admissible foothold" in why
    cx, _, picks, why = chains.ranked(tmap, gap, 0.2, -0.2, 3, None, 4)
    ref, _, _ = candidate_footholds(tmap, gap, relaxed, 0.32)
    assert np.array_equal(np.sort(cx), np.sort(ref)) and picks
    assert why.startswith("riser margins relaxed to 2 / 2 m/m: no admissible foothold")
    assert np.all(cx >= 0.40 + rules.edge_margin + relaxed.drop_margin * 0.03 - 1e-9)
    # the ranking's chains keep the full margins: the gap is still a dead end for them ...
    assert chains.reach(tmap, 0.30, 1) == 0 and not chains.chain(tmap, 0.30, 1)
    # ... but not for the search's feasibility check, which may take relaxed steps
    assert chains.reach(tmap, 0.30, 3, relaxed=True) == 3
    assert chains.reach_break(tmap, 0.30, 3, relaxed=True) == ""
    for x in (0.0, 0.2, 0.35, 0.45):  # a foothold exists: the rules' candidates, no note
        stance = (x, float(tmap.height(x)))
        cx, _, _, why = chains.ranked(tmap, stance, 0.2, -0.2, 3, None, 4)
        ref, _, _ = candidate_footholds(tmap, stance, rules, 0.32, 0.2, -0.2)
        assert why == "" and np.array_equal(np.sort(cx), np.sort(ref))
    with pytest.raises(ValueError, match="relaxed_margin"):
        PlannerConfig(relaxed_margin=1.5)
    with pytest.raises(ValueError, match="relaxed_margin"):
        PlannerConfig(relaxed_margin=-0.1)
