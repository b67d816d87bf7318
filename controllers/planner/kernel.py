"""Compiled evaluation of one step's constraints and cost, for a batch of Bezier shapes.

The planner's optimiser evaluates a step thousands of times per footstep (SLSQP iterations and
their finite-difference Jacobians, global searches). This kernel computes, row by row and in one
compiled loop, what :class:`controllers.planner.problem.StepEvaluator` documents: the reduced
dynamics along the constraint, ``theta_dot^2`` and the step time, the nominal input and
stance-foot reaction, the swing-foot geometry against the terrain (retractable-foot rule,
vertical faces), the touchdown and impact conditions, and the cost. Every model quantity comes
from :mod:`envs.physics.model` (its functions compile for scalars), the reduced dynamics and the
phase grid from :mod:`controllers.reduced` and the constraint's values from
:mod:`controllers.bezier`; only the loops live here.

The constraints of a row go to the columns of ``G`` that the constraint-group table
(:data:`controllers.planner.problem.CONSTRAINT_GROUPS`) lays out; the kernel receives each
group's first column by name (a ``GroupColumns`` record built from that table). Every entry is
``>= 0`` when satisfied.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from envs.physics import model
from envs.physics.params import PL
from envs.physics.terrain import terrain_height

from .. import reduced as rd
from ..bezier import bezier_on_basis, chord_coefficients, second_coeff

__all__ = [
    "NO_ROWS",
    "StepGrids",
    "StepGround",
    "StepOutputs",
    "StepScalars",
    "StepSettings",
    "allocate_outputs",
    "evaluate_shapes",
    "evaluate_steps",
    "pack",
    "packed_size",
    "pair_values",
    "residual_count",
    "step_values",
]


_jit = njit(cache=True, error_model="numpy")
#: no row-by-row start slope or ``theta_dot`` (:func:`evaluate_shapes`: the step's own)
NO_ROWS = np.empty(0)


class StepSettings(NamedTuple):
    """Constants of the step problem: robot, bounds and cost weights (SI units)."""

    min_thetadot: float  # least theta_dot over the step [rad/s]
    dip_floor: float  # least theta_dot over a step as a fraction of its start theta_dot
    alpha_scale: float  # scale of the reduced inertia alpha (M22 at q1 = 0)
    u_lim: float  # bound on the nominal |u| [input units]
    u_max: float  # actuator limit [input units]
    retract: float  # swing-foot retraction [m]
    arm: float  # arming distance of the swing foot [m]
    arm_clearance: float  # least height of the full-length foot when armed [m]
    clearance: float  # least height of the armed swing foot [m]
    clearance_ramp: float  # fraction of the step over which the clearance ramps
    retracted_clearance: float  # least height of the retracted foot [m]
    face_clearance: float  # least height over the top of a vertical face [m]
    touchdown_slope: float  # least descent rate of the foot at touchdown [m/rad]
    friction: float  # friction coefficient
    duration_min: float  # step duration bounds [s]
    duration_max: float
    weight: float  # robot weight [N]
    mass: float  # total mass [kg]
    w_speed: float  # cost weights
    w_torque: float
    w_end: float
    w_slope: float
    w_shape: float


class StepScalars(NamedTuple):
    """The scalars of one step problem: its start, stance foot, foothold and cost targets."""

    fmin: float  # least theta_dot^2 [rad^2/s^2]
    xs: float  # stance foot [m]
    ys: float
    slope_stance: float  # ground slope under the stance foot
    slope_foot: float  # ground slope under the foothold
    foot_x: float  # foothold abscissa [m]
    theta_plus: float  # phase at the start [rad]
    span: float  # phase range theta_minus - theta_plus [rad]
    wscale: float  # scale of the weights pulling towards the reference gait
    v_target: float  # walking speed aimed at [m/s]
    thetadot_minus_ref: float  # reference end-of-step theta_dot [rad/s] (with a reference)
    slope_ref: float  # reference post-impact slope (with a reference)
    delta_ref: float  # reference impact gain (with a reference)


class StepGrids(NamedTuple):
    """The grids of a step problem (phase as a fraction of the step's range)."""

    nodes: np.ndarray  # Chebyshev nodes (N,)
    basis: np.ndarray  # Bernstein basis on the nodes (N, M + 1)
    dbasis: np.ndarray  # its first derivative
    ddbasis: np.ndarray  # its second derivative
    check: np.ndarray  # uniform check grid (K + 1,)
    check_basis: np.ndarray  # Bernstein basis on the check grid (K + 1, M + 1)
    integral: np.ndarray  # Chebyshev cumulative-integral matrix (N, N)
    interp: np.ndarray  # nodes -> check grid interpolation (K + 1, N)
    clearance: np.ndarray  # clearance required along the check grid [m] (K + 1,)


class StepGround(NamedTuple):
    """The ground of a step problem: terrain polyline and the faces between stance foot and
    foothold (abscissa, top height [m], whether the full-length foot crosses it)."""

    xs: np.ndarray
    ys: np.ndarray
    face_x: np.ndarray
    face_top: np.ndarray
    face_full: np.ndarray


class StepOutputs(NamedTuple):
    """What :func:`evaluate_steps` writes, one row per shape."""

    constraints: np.ndarray  # (B, columns) constraint groups, >= 0 when satisfied
    thetadot_sq: np.ndarray  # (B, N) theta_dot^2 on the nodes [rad^2/s^2]
    input: np.ndarray  # (B, N) nominal input on the nodes [input units]
    cost: np.ndarray  # (B,)
    duration: np.ndarray  # (B,) step duration [s]
    thetadot_minus: np.ndarray  # (B,) theta_dot at the impact [rad/s]
    delta: np.ndarray  # (B,) impact gain along the constraints
    slope_plus: np.ndarray  # (B,) post-impact q1d/q2d
    speed: np.ndarray  # (B,) walking speed [m/s]
    arm_theta: np.ndarray  # (B,) phase at which the swing foot is armed [rad] (NaN: never)
    thetadot_plus: np.ndarray  # (B,) start theta_dot [rad/s]
    gain: np.ndarray  # (B,) step-to-step gain of theta_dot^2 (periodic gait; else NaN)
    residuals: np.ndarray  # (B, R) the cost's terms: cost = sum of their squares


@_jit
def residual_count(nodes: int, order: int) -> int:
    """Length of a row of :attr:`StepOutputs.residuals`: the speed term, then the effort on
    each of ``nodes`` nodes (periodic gait) or the end speed, the post-impact slope and the
    ``order - 2`` shape terms (steps)."""
    return 1 + max(nodes, order + 1)


@_jit
def cost_term(res, i, weight, r):
    """The cost term ``weight * r^2`` of the error ``r``; writes its residual, ``sqrt(weight)
    r``, to ``res[i]`` (the cost is the sum of the residuals' squares)."""
    res[i] = math.sqrt(weight) * r
    return weight * r**2


@_jit
def evaluate_steps(
    P, a, thd_plus_in, periodic, use_ref, shape_ref, cfg, step, grids, ground, col, out, screen
):
    """Evaluate the steps with Bezier coefficients ``a`` (``(B, M + 1)``), one row each.

    ``P``: robot parameter vector. ``thd_plus_in``: start ``theta_dot`` per row (ignored when
    ``periodic``: the fixed point of the step-to-step map is used). ``use_ref``: the cost pulls
    towards the reference gait (``step.thetadot_minus_ref``, ``step.slope_ref``,
    ``shape_ref``: the gait's normalised shape) instead of minimising effort. ``cfg``:
    :class:`StepSettings`; ``step``: :class:`StepScalars`; ``grids``: :class:`StepGrids`;
    ``ground``: :class:`StepGround`; ``col``: first column of each constraint group in
    ``out.constraints``, by group name. Writes ``out`` (:class:`StepOutputs`).

    ``screen``: a row with a constraint of the dynamics below it (``theta_dot^2`` on the nodes,
    the duration bounds, ``alpha``, the input, the stance-foot reaction; checked in that order)
    is left there (:func:`_screened`): it is infeasible for any feasibility threshold at or
    above ``screen``, and the rest of its evaluation is skipped (``-inf``: every row is
    evaluated whole). Most shapes sampled over a wide range fail there.
    """
    snodes, B0, B1, B2 = grids.nodes, grids.basis, grids.dbasis, grids.ddbasis
    sg, Bg, qint, interp, clear_req = (
        grids.check,
        grids.check_basis,
        grids.integral,
        grids.interp,
        grids.clearance,
    )
    tx, ty = ground.xs, ground.ys
    face_x, face_top, face_full = ground.face_x, ground.face_top, ground.face_full
    G, F, U = out.constraints, out.thetadot_sq, out.input
    nb, m1 = a.shape
    m = m1 - 1
    nn = B0.shape[0]
    nk = Bg.shape[0]
    nt = tx.size
    nf = face_x.size
    span = step.span
    th0 = step.theta_plus
    half = 0.5 * span
    xs, ys = step.xs, step.ys
    l = P[PL]  # noqa: E741
    min_thd = cfg.min_thetadot
    thd_ref = max(min_thd, 1e-3)
    lo = 0.25 * min_thd * min_thd
    nx, ny = model.ground_normal(step.slope_stance)  # under the stance foot
    sl = step.slope_foot
    fnx, fny = model.ground_normal(sl)  # under the foothold
    weight = cfg.weight
    mass = cfg.mass
    arm = cfg.arm
    ret = cfg.retract
    al_min = 0.02 * cfg.alpha_scale  # alpha floor in the integrals (kept away from 0)
    ph = np.empty(nn)
    dph = np.empty(nn)
    ddph = np.empty(nn)
    th = np.empty(nn)
    al = np.empty(nn)
    be = np.empty(nn)
    ga = np.empty(nn)
    hint = np.empty(nn)
    psi = np.empty(nn)
    thd = np.empty(nn)
    tcum = np.empty(nn)
    phg = np.empty(nk)
    cfull = np.empty(nk)
    cret = np.empty(nk)
    fxf = np.empty(nk)
    fyf = np.empty(nk)
    fxr = np.empty(nk)
    fyr = np.empty(nk)
    ahead = np.empty(nk)
    fk = np.empty(nk)
    for b in range(nb):
        # constraint and its phase derivatives on the nodes
        bezier_on_basis(a[b], B0, ph)
        bezier_on_basis(a[b], B1, dph)
        bezier_on_basis(a[b], B2, ddph)
        for k in range(nn):
            dph[k] = dph[k] / span
            ddph[k] = ddph[k] / (span * span)
            th[k] = rd.phase_at(th0, span, snodes[k])
        # reduced dynamics and its integral theta_dot^2 = psi theta_dot0^2 + Gam
        for k in range(nn):
            al[k], be[k], ga[k] = rd.reduced_coefficients(P, ph[k], th[k], dph[k], ddph[k])
        rd.grid_reduced_integral(al, be, ga, qint, half, al_min, psi, hint)  # hint: Gam
        gain = math.nan
        if periodic:
            d, _ = rd.impact_along_constraint(P, ph[nn - 1], dph[nn - 1])
            d2 = d * d
            gain = d2 * psi[nn - 1]
            td2 = d2 * hint[nn - 1] / (1.0 - gain) if gain < 1.0 else -1.0
            thp = math.sqrt(max(td2, lo))
        else:
            td2 = 0.0
            thp = thd_plus_in[b]
        for k in range(nn):
            F[b, k] = psi[k] * thp * thp + hint[k]
        fmin = step.fmin if periodic else max(step.fmin, (cfg.dip_floor * thp) ** 2)
        for k in range(nn):
            G[b, col.thetadot_sq + k] = (F[b, k] - fmin) / (thd_ref * thd_ref)
        if screen > -math.inf and _below(G[b], col.thetadot_sq, nn, screen):
            _screened(out, b)  # (before the step time: most screened rows stop here)
            continue
        rd.grid_step_time(F[b], qint, half, lo, thd, tcum)
        T = tcum[nn - 1]
        G[b, col.duration] = (T - cfg.duration_min) / cfg.duration_min
        G[b, col.duration + 1] = (cfg.duration_max - T) / cfg.duration_min
        if screen > -math.inf and _below(G[b], col.duration, 2, screen):
            _screened(out, b)
            continue
        # nominal input and stance-foot reaction along the motion
        cut = False
        for k in range(nn):
            f = max(F[b, k], lo)
            a_safe = max(al[k], al_min)
            q1dd, q2dd = rd.nominal_accelerations(a_safe, be[k], ga[k], dph[k], ddph[k], f)
            u = rd.nominal_input(P, ph[k], th[k], dph[k], ddph[k], thd[k])
            U[b, k] = u
            fn, ft = model.stance_reaction(
                P, ph[k], th[k], dph[k] * thd[k], thd[k], q1dd, q2dd, nx, ny
            )
            G[b, col.alpha + k] = al[k] / cfg.alpha_scale - 0.05
            G[b, col.torque + k] = (cfg.u_lim - abs(u)) / cfg.u_max
            G[b, col.stance_reaction + k] = fn / weight
            G[b, col.stance_reaction + nn + k] = (
                model.friction_cone_margin(fn, ft, cfg.friction) / weight
            )
            if screen > -math.inf and (
                min(
                    G[b, col.alpha + k],
                    G[b, col.torque + k],
                    G[b, col.stance_reaction + k],
                    G[b, col.stance_reaction + nn + k],
                )
                < screen
            ):
                cut = True
                break
        if cut:
            _screened(out, b)
            continue
        rd.matvec(interp, F[b], fk)  # theta_dot^2 on the check grid
        for k in range(nk):
            G[b, col.thetadot_sq + nn + k] = (fk[k] - fmin) / (thd_ref * thd_ref)
        # swing foot on the check grid, full length and retracted
        i_arm = -1
        bezier_on_basis(a[b], Bg, phg)
        for k in range(nk):
            thg = rd.phase_at(th0, span, sg[k])
            x, y = model.swing_foot_position(P, phg[k], thg, xs, ys, 0.0)
            fxf[k] = x
            fyf[k] = y
            cfull[k] = y - terrain_height(tx, ty, nt, x)
            x, y = model.swing_foot_position(P, phg[k], thg, xs, ys, ret)
            fxr[k] = x
            fyr[k] = y
            cret[k] = y - terrain_height(tx, ty, nt, x)
            ahead[k] = fxf[k] - xs - arm
            if i_arm < 0 and ahead[k] >= 0.0:
                i_arm = k
        s_arm = sg[i_arm] if i_arm >= 0 else 1.0
        g_arm = -math.inf
        for k in range(nk):
            rise = min(max((sg[k] - s_arm) / cfg.clearance_ramp, 0.0), 1.0)
            req = min(clear_req[k], cfg.arm_clearance + (cfg.clearance - cfg.arm_clearance) * rise)
            if k < nk - 1:
                if i_arm >= 0 and k >= i_arm:
                    G[b, col.clearance + k] = (cfull[k] - req) / l
                else:
                    G[b, col.clearance + k] = (cret[k] - cfg.retracted_clearance) / l
                g_arm = max(g_arm, min(ahead[k] / l, (cfull[k] - req) / l))
        G[b, col.armed] = g_arm
        # the simulator arms the foot as soon as it is ahead (and above the ground): between
        # the grid points around the crossing the full-length foot must already clear the ground
        s_cross = s_arm
        G[b, col.armed + 1] = 1.0
        if i_arm > 0:
            wk = -ahead[i_arm - 1] / (ahead[i_arm] - ahead[i_arm - 1])
            s_cross = sg[i_arm - 1] + wk * (sg[i_arm] - sg[i_arm - 1])
            c_cross = cfull[i_arm - 1] + wk * (cfull[i_arm] - cfull[i_arm - 1])
            G[b, col.armed + 1] = (c_cross - cfg.arm_clearance) / l
        # vertical faces crossed: the full-length foot once ahead, else the retracted one
        G[b, col.faces] = 1.0
        for j in range(nf):
            xf = face_x[j]
            val = -1.0
            for k in range(nk - 1):
                if fxf[k] < xf and fxf[k + 1] >= xf:
                    wk = (xf - fxf[k]) / (fxf[k + 1] - fxf[k])
                    if face_full[j]:
                        yy = fyf[k] + wk * (fyf[k + 1] - fyf[k])
                    else:
                        yy = fyr[k] + wk * (fyr[k + 1] - fyr[k])
                    val = (yy - face_top[j] - cfg.face_clearance) / l
                    break
            G[b, col.faces + 1 + j] = val
        # touchdown transversality: clearance decreasing along theta
        e = nn - 1
        vx1, vy1 = model.swing_foot_velocity(P, ph[e], th[e], dph[e], 1.0)
        G[b, col.touchdown] = (-(vy1 - sl * vx1) - cfg.touchdown_slope) / l
        # impact: impulse into the ground within the cone, trailing foot leaves the ground
        q1m, q2m, w1m, w2m = ph[e], th[e], dph[e] * thd[e], thd[e]
        q1p, q2p, w1p, w2p = model.impact(P, q1m, q2m, w1m, w2m)
        delta, slope_plus = rd.impact_along_constraint(P, q1m, dph[e])
        ix, iy = model.impact_impulse(P, q1m, q2m, w1m, w2m, q1p, q2p, w1p, w2p)
        imp_n, imp_t = model.normal_tangential(ix, iy, fnx, fny)
        sc = mass * l * thd_ref
        G[b, col.impact] = imp_n / sc
        G[b, col.impact + 1] = model.friction_cone_margin(imp_n, imp_t, cfg.friction) / sc
        lift = model.trailing_foot_normal_velocity(P, q1p, q2p, w1p, w2p, nx, ny)
        G[b, col.trailing_foot] = lift / (l * thd_ref)
        G[b, col.post_impact_speed] = (delta * thd[e] - min_thd) / thd_ref
        if periodic:
            G[b, col.periodic] = 1.0 - gain - 0.02
            G[b, col.periodic + 1] = td2 / (min_thd * min_thd) - 1.0
        # cost: speed; with a reference gait also the end speed, post-impact slope and shape;
        # each term's error once, for the cost and for its residual (out.residuals)
        v = (step.foot_x - xs) / T
        vt = step.v_target
        res = out.residuals[b]
        cost = cost_term(res, 0, cfg.w_speed, (v - vt) / vt)
        if not use_ref:
            su = 0.0
            for k in range(nn):
                r = U[b, k] / cfg.u_max
                su += r**2
                res[1 + k] = math.sqrt(cfg.w_torque / nn) * r
            cost += cfg.w_torque * su / nn
        else:
            ws = step.wscale
            dr = step.delta_ref * step.thetadot_minus_ref
            cost += cost_term(res, 1, ws * cfg.w_end, (delta * thd[e] - dr) / dr)
            cost += cost_term(res, 2, ws * cfg.w_slope, slope_plus - step.slope_ref)
            chord = a[b, m] - a[b, 0]
            den = max(abs(chord), 1e-6)
            sh = 0.0
            for i in range(2, m):
                r = (a[b, i] - chord_coefficients(a[b, 0], a[b, m], i, m)) / den - shape_ref[i]
                sh += r**2
                res[1 + i] = math.sqrt(ws * cfg.w_shape) * r
            cost += ws * cfg.w_shape * sh
        out.cost[b] = cost
        out.duration[b] = T
        out.thetadot_minus[b] = thd[e]
        out.delta[b] = delta
        out.slope_plus[b] = slope_plus
        out.speed[b] = v
        out.arm_theta[b] = rd.phase_at(th0, span, s_cross) if i_arm >= 0 else math.nan
        out.thetadot_plus[b] = thp
        out.gain[b] = gain


@_jit
def _below(row, start, count, screen):
    """Whether one of ``row[start : start + count]`` is below ``screen`` (NaN is not)."""
    for i in range(start, start + count):
        if row[i] < screen:
            return True
    return False


@_jit
def _screened(out, b):
    """Mark row ``b`` of ``out`` as left by :func:`evaluate_steps`'s screen: its scalar outputs
    NaN (its constraints not written stay NaN: violated)."""
    for v in (
        out.cost,
        out.duration,
        out.thetadot_minus,
        out.delta,
        out.slope_plus,
        out.speed,
        out.arm_theta,
        out.thetadot_plus,
        out.gain,
    ):
        v[b] = math.nan


def packed_size(sizes: list[int], block: int) -> int:
    """Length of the constraint vector :func:`pack` makes from groups of these sizes."""
    return sum(-(-k // block) if k > 2 * block else k for k in sizes)


@_jit
def pack(G, offsets, block, out):
    """SLSQP's constraint vectors from ``G``: groups longer than ``2 block`` reduced to minima
    over blocks of ``block`` neighbouring grid points (SLSQP's cost grows quickly with the number
    of constraints); NaN -> violated (``-1e3``), ``+inf`` -> ``1e3``, ``-inf`` -> ``-1e3``."""
    nb = G.shape[0]
    ng = offsets.size - 1
    for b in range(nb):
        c = 0
        for i in range(ng):
            lo, hi = offsets[i], offsets[i + 1]
            step = block if hi - lo > 2 * block else 1
            for j in range(lo, hi, step):
                v = G[b, j]
                for k in range(j + 1, min(j + step, hi)):
                    if G[b, k] < v or G[b, k] != G[b, k]:
                        v = G[b, k]
                        if v != v:
                            break
                if v != v or v == -math.inf:
                    v = -1e3
                elif v == math.inf:
                    v = 1e3
                out[b, c] = v
                c += 1


@_jit
def allocate_outputs(rows, columns, nodes, order):
    """:class:`StepOutputs` for ``rows`` shapes, ``columns`` constraints, ``nodes`` nodes and
    Bezier order ``order``: the constraints NaN until the kernel writes them (a column left
    unwritten would read as violated), the residuals zero, the rest uninitialised."""
    return StepOutputs(
        np.full((rows, columns), np.nan),
        np.empty((rows, nodes)),
        np.empty((rows, nodes)),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.zeros((rows, residual_count(nodes, order))),
    )


@_jit
def evaluate_shapes(P, free, slope_in, thd_in, periodic, common, problem, screen):
    """:func:`evaluate_steps` for steps given by their free coefficients ``a_2 .. a_{M-1}``
    (``free``, ``(B, M - 2)``), and :func:`pack`: one compiled call for what an optimiser asks
    of a batch (``periodic``: the periodic gait's, ``thd_in`` ignored).

    ``common``: ``(use_ref, shape_ref, cfg, grids, block)``, what every step problem of a
    planner shares (as :func:`evaluate_steps` takes them; ``block``: :func:`pack`'s);
    ``problem``: ``(fixed, step, ground, col, offsets, packed)``, the step's own, ``fixed``
    being ``(a_0, a_M, phi'(theta_plus), theta_plus, theta_minus, theta_dot_plus)`` [rad, rad,
    -, rad, rad, rad/s], ``offsets`` and ``packed`` the constraint layout's offsets and packed
    length. ``slope_in``, ``thd_in``: the start slope and ``theta_dot`` row by row (``(B,)``),
    or empty for ``fixed``'s (the start of a step that follows a step being optimised).
    ``screen``: :func:`evaluate_steps`'s (``-inf``: every row whole). ``a_1`` is the one of
    impact invariance (:func:`controllers.bezier.second_coeff`). Returns ``(a, out, g)``: the
    coefficients ``(B, M + 1)``, the :class:`StepOutputs` and the packed constraints
    ``(B, packed)``.
    """
    use_ref, shape_ref, cfg, grids, block = common
    fixed, step, ground, col, offsets, packed = problem
    nb, k = free.shape
    m = k + 2
    a0, a_last, slope, theta_plus, theta_minus, thd_plus = fixed
    a = np.empty((nb, m + 1))
    thd = np.empty(nb)
    for b in range(nb):
        a[b, 0] = a0
        for i in range(k):
            a[b, 2 + i] = free[b, i]
        a[b, m] = a_last
        sl = slope_in[b] if slope_in.size else slope
        a[b, 1] = second_coeff(a0, sl, theta_plus, theta_minus, m)
        thd[b] = thd_in[b] if thd_in.size else thd_plus
    out = allocate_outputs(nb, offsets[-1], grids.nodes.size, m)
    evaluate_steps(
        P, a, thd, periodic, use_ref, shape_ref, cfg, step, grids, ground, col, out, screen
    )
    g = np.empty((nb, packed))
    pack(out.constraints, offsets, block, g)
    return a, out, g


@_jit
def step_values(P, free, common, problem):
    """The cost ``(B,)`` and packed constraints ``(B, packed)`` of :func:`evaluate_shapes` (its
    arguments, the start given by the problem): what each SLSQP evaluation needs, and no more
    crosses back to Python."""
    _, out, g = evaluate_shapes(P, free, NO_ROWS, NO_ROWS, False, common, problem, -math.inf)
    return out.cost, g


@_jit
def step_residuals(P, free, common, problem):
    """:func:`step_values` and the cost's terms ``(B, R)`` (:attr:`StepOutputs.residuals`):
    what the Gauss-Newton scaling of a solve needs, without the full evaluation."""
    _, out, g = evaluate_shapes(P, free, NO_ROWS, NO_ROWS, False, common, problem, -math.inf)
    return out.cost, g, out.residuals


@_jit
def pair_values(P, free, n, common, first, second):
    """The cost ``(B,)`` and packed constraints ``(B, packed + packed2)`` of a step and the
    next one optimised together: ``free[:, :n]`` the first step's free coefficients,
    ``free[:, n:]`` the second's, which starts where the first ends (its start slope and
    ``theta_dot``, the impact's, row by row). ``common``, ``first``, ``second``: as
    :func:`evaluate_shapes` takes them (the second's start in its ``fixed`` is ignored). The
    cost is the sum of the two steps'.

    A row whose first step repeats an earlier row's (a forward difference in the second step's
    coefficients) reuses that row's first step: the same numbers, one evaluation fewer."""
    cost, g, _, _, _ = _pair(P, free, n, common, first, second)
    return cost, g


@_jit
def pair_residuals(P, free, n, common, first, second):
    """:func:`pair_values` and the pair's cost terms ``(B, R + R2)``, the first step's then the
    second's (:func:`step_residuals` for a pair)."""
    cost, g, r1, r2, at = _pair(P, free, n, common, first, second)
    res = np.empty((free.shape[0], r1.shape[1] + r2.shape[1]))
    res[:, : r1.shape[1]] = r1[at]
    res[:, r1.shape[1] :] = r2
    return cost, g, res


@_jit
def _pair(P, free, n, common, first, second):
    """:func:`pair_values`'s cost and constraints, with the two steps' residuals (the first
    step's by distinct row) and each row's first step among the distinct ones."""
    nb = free.shape[0]
    rows, at = _distinct_rows(free, n)  # at: each row's first step among those evaluated
    _, o1, g1 = evaluate_shapes(
        P, free[rows, :n], NO_ROWS, NO_ROWS, False, common, first, -math.inf
    )
    _, o2, g2 = evaluate_shapes(
        P,
        free[:, n:],
        o1.slope_plus[at],
        (o1.delta * o1.thetadot_minus)[at],
        False,
        common,
        second,
        -math.inf,
    )
    g = np.empty((nb, g1.shape[1] + g2.shape[1]))
    g[:, : g1.shape[1]] = g1[at]
    g[:, g1.shape[1] :] = g2
    return o1.cost[at] + o2.cost, g, o1.residuals, o2.residuals, at


@_jit
def _distinct_rows(free, n):
    """The rows of ``free`` whose first ``n`` entries differ from every earlier row's, and for
    each row the position among them of the one it equals."""
    nb = free.shape[0]
    rows = np.empty(nb, dtype=np.int64)
    at = np.empty(nb, dtype=np.int64)
    m = 0
    for b in range(nb):
        at[b] = m
        for j in range(m):
            if np.all(free[rows[j], :n] == free[b, :n]):
                at[b] = j
                break
        if at[b] == m:
            rows[m] = b
            m += 1
    return rows[:m], at
