"""Compiled evaluation of one step's constraints and cost, for a batch of Bezier shapes.

The planner's optimiser evaluates a step thousands of times per footstep (SLSQP iterations and
their finite-difference Jacobians, global searches). This kernel computes, row by row and in one
compiled loop, what :class:`controllers.planner._StepModel` documents: the reduced dynamics
along the constraint, ``theta_dot^2`` and the step time, the nominal input and stance-foot
reaction, the swing-foot geometry against the terrain (retractable-foot rule, vertical faces),
the touchdown and impact conditions, and the cost. Every model quantity comes from
:mod:`envs.model` (its functions compile for scalars) and the reduced dynamics from
:mod:`controllers.reduced`; only the loops live here.

Layout of the constraint matrix ``G`` (one row per shape, every entry ``>= 0`` when satisfied),
in the order of ``controllers.planner._CONSTRAINTS``; ``N = n + 1`` Chebyshev nodes, ``K + 1``
points of the uniform check grid, ``F`` vertical faces between the stance foot and the foothold:

==========================  =============  ==========================================
group                       entries        meaning
==========================  =============  ==========================================
``theta_dot^2``             ``N + K + 1``  bounded away from zero (both grids)
``alpha``                   ``N``          the reduced inertia keeps its sign
``torque``                  ``N``          nominal input within the limit
``clearance``               ``K``          swing foot above the terrain
``stance friction``         ``2 N``        normal force and friction cone
``armed``                   ``2``          armed before touchdown, clear when armed
``faces``                   ``1 + F``      clearance over vertical faces crossed
``touchdown``               ``1``          transversal touchdown
``duration``                ``2``          step duration bounds
``impact``                  ``2``          impact impulse into the ground, in the cone
``trailing foot``           ``1``          the trailing foot leaves the ground
``post-impact theta_dot``   ``1``          positive start speed of the next step
``periodic``                ``2``          (periodic gait only) stable, real fixed point
==========================  =============  ==========================================
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from envs import model
from envs.params import PL
from envs.terrain import terrain_height

from . import reduced as rd

# scalar settings passed to the kernel, by index
(
    S_MIN_THD,
    S_FMIN,
    S_ALPHA_SCALE,
    S_U_LIM,
    S_U_MAX,
    S_RETRACT,
    S_ARM,
    S_ARM_CLEAR,
    S_CLEAR,
    S_RAMP,
    S_RET_CLEAR,
    S_FACE_CLEAR,
    S_TD_SLOPE,
    S_MU,
    S_DUR_MIN,
    S_DUR_MAX,
    S_WEIGHT,
    S_MASS,
    S_XS,
    S_YS,
    S_SLOPE_STANCE,
    S_SLOPE_FOOT,
    S_FOOT_X,
    S_THETA_PLUS,
    S_SPAN,
    S_W_SPEED,
    S_W_TORQUE,
    S_W_END,
    S_W_SLOPE,
    S_W_SHAPE,
    S_WSCALE,
    S_V_TARGET,
    S_THM_REF,
    S_SLOPE_REF,
    S_D_REF,
    S_COUNT,
) = range(36)

# per-row results, by index
(
    R_COST,
    R_T,
    R_THD_MINUS,
    R_DELTA,
    R_SLOPE_PLUS,
    R_SPEED,
    R_ARM_THETA,
    R_THD_PLUS,
    R_GAIN,
    R_COUNT,
) = range(10)

_jit = njit(cache=True, error_model="numpy")


def group_sizes(n_nodes: int, n_check: int, n_faces: int, periodic: bool) -> list[int]:
    """Entries of each constraint group (``n_nodes = n + 1``, ``n_check = K + 1``)."""
    sizes = [
        n_nodes + n_check,
        n_nodes,
        n_nodes,
        n_check - 1,
        2 * n_nodes,
        2,
        1 + n_faces,
        1,
        2,
        2,
        1,
        1,
    ]
    return sizes + [2] if periodic else sizes


@_jit
def _cumint(v, q, half, out):
    """``out[k] = int_{theta_0}^{theta_k} v`` on the Chebyshev grid (``q``: node matrix)."""
    n = v.size
    for k in range(n):
        s = 0.0
        for j in range(n):
            s += q[k, j] * v[j]
        out[k] = half * s


@_jit
def evaluate_steps(
    P,
    a,
    thd_plus_in,
    periodic,
    use_ref,
    S,
    snodes,
    B0,
    B1,
    B2,
    Bg,
    sg,
    qint,
    interp,
    clear_req,
    tx,
    ty,
    face_x,
    face_top,
    face_full,
    shape_ref,
    offsets,
    G,
    R,
    F,
    U,
):
    """Evaluate the steps with Bezier coefficients ``a`` (``(B, M + 1)``), one row each.

    ``thd_plus_in``: start ``theta_dot`` per row (ignored when ``periodic``: the fixed point of
    the step-to-step map is used). ``use_ref``: the cost pulls towards the reference gait
    (``S_THM_REF``, ``S_SLOPE_REF``, ``shape_ref``) instead of minimising effort. ``S``: scalar
    settings (``S_*`` indices). ``snodes``: Chebyshev nodes as fractions of the step's phase
    range. ``B0..B2``: Bernstein basis and derivatives on the Chebyshev nodes, ``Bg`` on the
    check grid ``sg``; ``qint``: Chebyshev cumulative-integral matrix; ``interp``: nodes ->
    check grid interpolation; ``clear_req``: clearance required along the check grid [m];
    ``tx, ty``: terrain polyline; ``face_*``: faces between stance foot and foothold
    (abscissa, top height, 1 if the full-length foot crosses it); ``shape_ref``: the periodic
    gait's normalised shape; ``offsets``: start column of each group in ``G``.

    Writes ``G`` (constraints), ``R`` (``R_*`` results), ``F`` (``theta_dot^2`` on the nodes)
    and ``U`` (nominal input on the nodes).
    """
    nb, m1 = a.shape
    m = m1 - 1
    nn = B0.shape[0]
    nk = Bg.shape[0]
    nt = tx.size
    nf = face_x.size
    span = S[S_SPAN]
    th0 = S[S_THETA_PLUS]
    half = 0.5 * span
    xs, ys = S[S_XS], S[S_YS]
    l = P[PL]  # noqa: E741
    min_thd = S[S_MIN_THD]
    thd_ref = max(min_thd, 1e-3)
    lo = 0.25 * min_thd * min_thd
    ns = S[S_SLOPE_STANCE]
    cn = 1.0 / math.sqrt(1.0 + ns * ns)
    sn = ns * cn
    sl = S[S_SLOPE_FOOT]
    ic = 1.0 / math.sqrt(1.0 + sl * sl)
    ih = sl * ic
    weight = S[S_WEIGHT]
    mass = S[S_MASS]
    arm = S[S_ARM]
    ret = S[S_RETRACT]
    al_min = 0.02 * S[S_ALPHA_SCALE]  # alpha floor in the integrals (kept away from 0)
    ph = np.empty(nn)
    dph = np.empty(nn)
    ddph = np.empty(nn)
    th = np.empty(nn)
    al = np.empty(nn)
    be = np.empty(nn)
    ga = np.empty(nn)
    w = np.empty(nn)
    kint = np.empty(nn)
    hint = np.empty(nn)
    psi = np.empty(nn)
    thd = np.empty(nn)
    tcum = np.empty(nn)
    cfull = np.empty(nk)
    cret = np.empty(nk)
    fxf = np.empty(nk)
    fyf = np.empty(nk)
    fxr = np.empty(nk)
    fyr = np.empty(nk)
    ahead = np.empty(nk)
    for b in range(nb):
        # constraint and its phase derivatives on the nodes
        for k in range(nn):
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for i in range(m1):
                s0 += a[b, i] * B0[k, i]
                s1 += a[b, i] * B1[k, i]
                s2 += a[b, i] * B2[k, i]
            ph[k] = s0
            dph[k] = s1 / span
            ddph[k] = s2 / (span * span)
            th[k] = th0 + span * snodes[k]
        # reduced dynamics and its integral theta_dot^2 = psi theta_dot0^2 + Gam
        for k in range(nn):
            a_, b_, g_ = rd.reduced_coefficients(P, ph[k], th[k], dph[k], ddph[k])
            al[k] = a_
            be[k] = b_
            ga[k] = g_
            w[k] = 2.0 * b_ / max(a_, al_min)
        _cumint(w, qint, half, kint)
        for k in range(nn):
            w[k] = -2.0 * ga[k] / max(al[k], al_min) * math.exp(kint[k])
        _cumint(w, qint, half, hint)
        for k in range(nn):
            psi[k] = math.exp(-kint[k])
            hint[k] = psi[k] * hint[k]  # Gam
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
            f = psi[k] * thp * thp + hint[k]
            F[b, k] = f
            thd[k] = math.sqrt(max(f, lo))
            w[k] = 1.0 / thd[k]
        _cumint(w, qint, half, tcum)
        T = tcum[nn - 1]
        # nominal input and stance-foot reaction along the motion
        o = offsets
        for k in range(nn):
            f = max(F[b, k], lo)
            a_safe = max(al[k], al_min)
            q1dd, q2dd = rd.nominal_accelerations(a_safe, be[k], ga[k], dph[k], ddph[k], f)
            u = rd.nominal_input(P, ph[k], th[k], dph[k], ddph[k], thd[k])
            U[b, k] = u
            rx, ry = model.ground_reaction(P, ph[k], th[k], dph[k] * thd[k], thd[k], q1dd, q2dd)
            fn = cn * ry - sn * rx
            ft = cn * rx + sn * ry
            G[b, o[0] + k] = (F[b, k] - S[S_FMIN]) / (thd_ref * thd_ref)
            G[b, o[1] + k] = al[k] / S[S_ALPHA_SCALE] - 0.05
            G[b, o[2] + k] = (S[S_U_LIM] - abs(u)) / S[S_U_MAX]
            G[b, o[4] + k] = fn / weight
            G[b, o[4] + nn + k] = (S[S_MU] * fn - abs(ft)) / weight
        for k in range(nk):
            s = 0.0
            for j in range(nn):
                s += interp[k, j] * F[b, j]
            G[b, o[0] + nn + k] = (s - S[S_FMIN]) / (thd_ref * thd_ref)
        # swing foot on the check grid, full length and retracted
        i_arm = -1
        for k in range(nk):
            s0 = 0.0
            for i in range(m1):
                s0 += a[b, i] * Bg[k, i]
            thg = th0 + span * sg[k]
            x, y = model.swing_foot_position(P, s0, thg, xs, ys, 0.0)
            fxf[k] = x
            fyf[k] = y
            cfull[k] = y - terrain_height(tx, ty, nt, x)
            x, y = model.swing_foot_position(P, s0, thg, xs, ys, ret)
            fxr[k] = x
            fyr[k] = y
            cret[k] = y - terrain_height(tx, ty, nt, x)
            ahead[k] = fxf[k] - xs - arm
            if i_arm < 0 and ahead[k] >= 0.0:
                i_arm = k
        s_arm = sg[i_arm] if i_arm >= 0 else 1.0
        g_arm = -math.inf
        for k in range(nk):
            rise = min(max((sg[k] - s_arm) / S[S_RAMP], 0.0), 1.0)
            req = min(clear_req[k], S[S_ARM_CLEAR] + (S[S_CLEAR] - S[S_ARM_CLEAR]) * rise)
            if k < nk - 1:
                if i_arm >= 0 and k >= i_arm:
                    G[b, o[3] + k] = (cfull[k] - req) / l
                else:
                    G[b, o[3] + k] = (cret[k] - S[S_RET_CLEAR]) / l
                g_arm = max(g_arm, min(ahead[k] / l, (cfull[k] - req) / l))
        G[b, o[5]] = g_arm
        # the simulator arms the foot as soon as it is ahead (and above the ground): between
        # the grid points around the crossing the full-length foot must already clear the ground
        s_cross = s_arm
        G[b, o[5] + 1] = 1.0
        if i_arm > 0:
            wk = -ahead[i_arm - 1] / (ahead[i_arm] - ahead[i_arm - 1])
            s_cross = sg[i_arm - 1] + wk * (sg[i_arm] - sg[i_arm - 1])
            c_cross = cfull[i_arm - 1] + wk * (cfull[i_arm] - cfull[i_arm - 1])
            G[b, o[5] + 1] = (c_cross - S[S_ARM_CLEAR]) / l
        # vertical faces crossed: the full-length foot once ahead, else the retracted one
        G[b, o[6]] = 1.0
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
                    val = (yy - face_top[j] - S[S_FACE_CLEAR]) / l
                    break
            G[b, o[6] + 1 + j] = val
        # touchdown transversality: clearance decreasing along theta
        e = nn - 1
        vx1, vy1 = model.swing_foot_velocity(P, ph[e], th[e], dph[e], 1.0)
        G[b, o[7]] = (-(vy1 - sl * vx1) - S[S_TD_SLOPE]) / l
        G[b, o[8]] = (T - S[S_DUR_MIN]) / S[S_DUR_MIN]
        G[b, o[8] + 1] = (S[S_DUR_MAX] - T) / S[S_DUR_MIN]
        # impact: impulse into the ground within the cone, trailing foot leaves the ground
        q1m, q2m, w1m, w2m = ph[e], th[e], dph[e] * thd[e], thd[e]
        q1p, q2p, w1p, w2p = model.impact(P, q1m, q2m, w1m, w2m)
        delta, slope_plus = rd.impact_along_constraint(P, q1m, dph[e])
        vxm, vym = model.centre_of_mass_velocity(P, q1m, q2m, w1m, w2m)
        vxp, vyp = model.centre_of_mass_velocity(P, q1p, q2p, w1p, w2p)
        ix, iy = mass * (vxp - vxm), mass * (vyp - vym)
        imp_n = ic * iy - ih * ix
        imp_t = ic * ix + ih * iy
        sc = mass * l * thd_ref
        G[b, o[9]] = imp_n / sc
        G[b, o[9] + 1] = (S[S_MU] * imp_n - abs(imp_t)) / sc
        tvx, tvy = model.swing_foot_velocity(P, q1p, q2p, w1p, w2p)
        G[b, o[10]] = (cn * tvy - sn * tvx) / (l * thd_ref)
        G[b, o[11]] = (delta * thd[e] - min_thd) / thd_ref
        if periodic:
            G[b, o[12]] = 1.0 - gain - 0.02
            G[b, o[12] + 1] = td2 / (min_thd * min_thd) - 1.0
        # cost: speed; with a reference gait also the end speed, post-impact slope and shape
        v = (S[S_FOOT_X] - xs) / T
        vt = S[S_V_TARGET]
        cost = S[S_W_SPEED] * ((v - vt) / vt) ** 2
        if not use_ref:
            su = 0.0
            for k in range(nn):
                su += (U[b, k] / S[S_U_MAX]) ** 2
            cost += S[S_W_TORQUE] * su / nn
        else:
            ws = S[S_WSCALE]
            dr = S[S_D_REF] * S[S_THM_REF]
            cost += ws * S[S_W_END] * ((delta * thd[e] - dr) / dr) ** 2
            cost += ws * S[S_W_SLOPE] * (slope_plus - S[S_SLOPE_REF]) ** 2
            chord = a[b, m] - a[b, 0]
            den = max(abs(chord), 1e-6)
            sh = 0.0
            for i in range(2, m):
                rel = (a[b, i] - (a[b, 0] + chord * i / m)) / den
                sh += (rel - shape_ref[i]) ** 2
            cost += ws * S[S_W_SHAPE] * sh
        R[b, R_COST] = cost
        R[b, R_T] = T
        R[b, R_THD_MINUS] = thd[e]
        R[b, R_DELTA] = delta
        R[b, R_SLOPE_PLUS] = slope_plus
        R[b, R_SPEED] = v
        R[b, R_ARM_THETA] = th0 + span * s_cross if i_arm >= 0 else math.nan
        R[b, R_THD_PLUS] = thp
        R[b, R_GAIN] = gain


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
