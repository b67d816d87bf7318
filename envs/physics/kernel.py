"""Compiled core of the hybrid simulator: swing phases, located touchdowns, impacts, failures.

One compiled per-walker function (:func:`walker_step`) advances one walker by one control
period under a held hip torque: fixed-step RK4 substeps (:func:`envs.physics.model.swing_rk4`),
touchdown located by root finding on the substep length, the impact map of
:mod:`envs.physics.model`, leg swap, failure checks. The batched kernel
(:func:`step_parallel`) runs it over walkers with ``numba.prange``; :func:`step_serial` runs
the same function one walker after the other, so one walker and a batch take the same code path
and give the same numbers bit for bit. :class:`envs.physics.Simulator` owns the
buffers these kernels work on; their layouts are the ``X_*``, ``F_*``, ``E_*``, ``O_*`` and
``C_*`` constants below.

Rules of the hybrid model (see also the README section "Simulator"):

* **Retractable feet.** Right after lift-off the swing foot is retracted by
  ``retract * l`` along the leg (``retract`` and ``arm_distance`` are robot parameters,
  :class:`envs.physics.RobotParams`). It is *armed* (extended, latched until the next touchdown)
  as soon as, at the end of a substep, its full-length position is ahead of the stance foot
  by at least ``arm_distance * l`` (horizontally) and above the ground. A touchdown is the
  first downward zero crossing of the full-length clearance (foot height minus ground height)
  of an armed foot; a crossing of an unarmed foot counts if the foot is ahead by
  ``arm_distance * l`` at the crossing (it was armed in between). Before arming, the
  *retracted* foot point going below the ground is a **trip**; an armed foot whose clearance
  jumps through zero (it runs into a vertical face: the located crossing converges in time but
  the clearance just before it exceeds ``face_tol``) is a **trip** too.
* **Impact.** At touchdown the impact map :func:`envs.physics.model.impact` is applied, the
  legs swap, the stance foot moves to the foothold ``(x_foot, h(x_foot))`` and ``stance_leg``
  (which physical leg, 0 or 1) flips. The impact is checked: the impulse on the new stance foot,
  ``(2 m + mH) (v_com+ - v_com-)``, must push (non-negative component along the ground normal
  under the foothold) and lie in the friction cone ``|tangential| <= mu * normal``, and the
  trailing (full-length) foot must leave the ground: its post-impact velocity must have a
  positive component along the ground normal under it
  (:func:`envs.physics.model.impact_admissible`). Otherwise the run ends with **stuck**;
  more than ``max_impacts`` impacts in one control period is **stuck** as well. A stuck walker
  is frozen at its pre-impact state.
* **Failures** are checked at the end of every substep and right after each impact: **fall**
  (hip height above the ground below ``fall_height * l``, or ``|q2| > q2_limit``),
  **liftoff** (normal component of the stance-foot ground reaction
  :func:`envs.physics.model.stance_reaction` negative; normal of the ground segment under the
  stance foot, the segment to its right on a vertex), **slip** (tangential over normal
  reaction beyond ``mu``). A failed walker keeps its state at the failure instant and is not
  advanced again until it is reset.
* **Divergence.** The end state of every RK4 substep is checked before anything else (events
  included), and so is every post-impact state: a non-finite value, ``|q1|`` or ``|q2|`` above
  :data:`ANGLE_LIMIT` or a rate ``|q1d|``, ``|q2d|`` above the robot's
  :attr:`envs.physics.RobotParams.max_rate` (``MAX_TIP_SPEED / l``) means the fixed-step
  integration has blown up (a stiff hip friction, an absurd torque or start state): the run
  ends with **invalid**, and the walker is put back to its last valid state, the start of the
  substep that diverged (time, stance foot, stance leg, work and impact records included), so
  that what it reports stays finite.

Time is held in float64 seconds; the hip input of the kernels is the hip torque in N m (the
actuator limit ``u_max`` is the environment's business, not the simulator's); the dynamics take
it in input units (:func:`envs.physics.model.input_from_torque`) and the motor work turns it
back into N m (:func:`envs.physics.model.torque_from_input`), see :mod:`envs.physics.actuator`.
"""

from __future__ import annotations

import math
import os

import numba
from numba import njit, prange

from . import model
from .params import MAX_TIP_SPEED, PARM, PL, PRETRACT
from .terrain import terrain_height, terrain_slope

# OpenMP worker threads spin while they wait; on a machine whose cores are busy with other
# processes the batched kernels then ran up to 8x slower than single-threaded. The workqueue
# layer degrades gracefully. A choice made with NUMBA_THREADING_LAYER is respected.
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

# ---------------------------------------------------------------------------- layouts
# float state x[N, 7]: q1, q2 [rad], q1d, q2d [rad/s], stance foot xs, ys [m], time t [s]
X_Q1, X_Q2, X_Q1D, X_Q2D, X_XS, X_YS, X_T = range(7)
N_X = 7
# int flags f[N, 4]: stance leg (0 or 1), swing foot armed (0 or 1), status code, impacts
F_LEG, F_ARMED, F_STATUS, F_NIMP = range(4)
N_F = 4
# per-impact event record ev[N, K, 11]: time [s], foothold (x, y) [m], pre-impact q1 q2 q1d q2d,
# post-impact q1 q2 q1d q2d [rad, rad/s]
E_T, E_FX, E_FY = 0, 1, 2
E_PRE, E_POST = 3, 7
N_E = 11
# per-step output out[N, 3]: motor work (net, positive, absolute) over the step [J]
O_WNET, O_WPOS, O_WABS = range(3)
N_O = 3
# config vector (SimConfig.vector(); lengths as fractions of l, flags 0.0 or 1.0); the foot
# geometry (retraction, arming distance) is the robot's: P[PRETRACT], P[PARM]
C_SUBSTEP, C_FALL_H, C_Q2MAX, C_MU, C_TTOL, C_FACE, C_REACT, C_IMPACT = range(8)
N_C = 8

#: failure codes (index) and names; code 0 means "running"
FAILURES = ("", "fall", "trip", "liftoff", "slip", "stuck", "invalid")
OK, FALL, TRIP, LIFTOFF, SLIP, STUCK, INVALID = range(7)

#: largest ``|q1|``, ``|q2|`` [rad] of a valid state: a walker cannot wind its legs round twice
#: without a foot meeting the ground, so beyond it the integration has diverged
ANGLE_LIMIT = 4.0 * math.pi

_jit = njit(cache=True, fastmath=False, error_model="numpy")


# ---------------------------------------------------------------------------- compiled core
@_jit
def _clearance(P, tx, ty, n, q1, q2, xs, ys, retract):
    """Height of the swing-foot point (leg shortened by ``retract`` [m]) above the ground [m],
    and its x [m]."""
    fx, fy = model.swing_foot_position(P, q1, q2, xs, ys, retract)
    return fy - terrain_height(tx, ty, n, fx), fx


@_jit
def _normal(tx, ty, n, x):
    """Upward unit normal ``(nx, ny)`` of the ground segment under ``x`` [m] (the segment to
    its right on a vertex)."""
    return model.ground_normal(terrain_slope(tx, ty, n, x))


@_jit
def _locate(P, tx, ty, n, q1, q2, w1, w2, xs, ys, u, k1a, k1b, h, f0, f1, retract, ttol):
    """Earliest zero of the clearance of the foot point (leg shortened by ``retract``) along
    the RK4 step of length ``tau`` in ``(0, h]``, given ``f0 > 0 >= f1`` at the ends.

    Illinois (regula falsi with halving) on ``tau``; returns ``(tau, f_left)`` with ``tau`` the
    right end of the final bracket (clearance <= 0) and ``f_left`` the clearance at its left
    end (a large value means the clearance jumped: a vertical face).
    """
    a, b = 0.0, h
    fa, fb = f0, f1
    ga = f0  # unscaled clearance at the left end
    side = 0
    for _ in range(200):
        if b - a <= ttol:
            break
        m = b - fb * (b - a) / (fb - fa)
        if not (m > a and m < b):
            m = 0.5 * (a + b)
        # a secant point within the tolerance of an end is nudged inwards, so that the next
        # evaluation brackets the root to the tolerance (the end needs not move any more)
        if m - a < 0.5 * ttol:
            m = a + 0.5 * ttol
        elif b - m < 0.5 * ttol:
            m = b - 0.5 * ttol
        r = model.swing_rk4(P, q1, q2, w1, w2, u, m, k1a, k1b)
        fm, _ = _clearance(P, tx, ty, n, r[0], r[1], xs, ys, retract)
        if fm > 0.0:
            a, fa, ga = m, fm, fm
            if side == 1:
                fb *= 0.5
            side = 1
        else:
            b, fb = m, fm
            if fm == 0.0:
                ga = 0.0
                break
            if side == -1:
                fa *= 0.5
            side = -1
    return b, ga


@_jit
def _reaction_check(P, cfg, q1, q2, w1, w2, a1, a2, nx, ny):
    """Failure code of the stance-foot ground reaction (OK, LIFTOFF or SLIP) at the state
    ``(q1, q2, w1, w2)`` with accelerations ``(a1, a2)``, ground normal ``(nx, ny)``."""
    fn, ft = model.stance_reaction(P, q1, q2, w1, w2, a1, a2, nx, ny)
    if fn < 0.0:
        return LIFTOFF
    if model.outside_friction_cone(fn, ft, cfg[C_MU]):
        return SLIP
    return OK


@_jit
def _diverged(q1, q2, w1, w2, rate_max):
    """True for a state the integration cannot have reached validly: a non-finite value,
    ``|q1|`` or ``|q2|`` above :data:`ANGLE_LIMIT` [rad], a rate above ``rate_max`` [rad/s]."""
    return not (
        abs(q1) <= ANGLE_LIMIT
        and abs(q2) <= ANGLE_LIMIT
        and abs(w1) <= rate_max
        and abs(w2) <= rate_max
    )


@_jit
def _state_check(P, cfg, tx, ty, n, q1, q2, w1, w2, xs, ys):
    """Failure code of a state (OK, INVALID or FALL)."""
    if _diverged(q1, q2, w1, w2, MAX_TIP_SPEED / P[PL]):
        return INVALID
    if abs(q2) > cfg[C_Q2MAX]:
        return FALL
    hx, hy = model.hip_position(P, q1, q2, xs, ys)
    if hy - terrain_height(tx, ty, n, hx) < cfg[C_FALL_H] * P[PL]:
        return FALL
    return OK


@_jit
def walker_step(P, cfg, tx, ty, n, x, f, tau, dt, ev, out):
    """Advance one walker by one control period ``dt`` [s] under hip torque ``tau`` [N m].

    ``x`` (7,), ``f`` (4,) are the walker's state rows (updated in place), ``ev`` (K, 11) and
    ``out`` (3,) its event and work records for this step (overwritten).
    """
    f[F_NIMP] = 0
    out[O_WNET] = 0.0
    out[O_WPOS] = 0.0
    out[O_WABS] = 0.0
    if f[F_STATUS] != OK:
        return
    kmax = ev.shape[0]
    u = model.input_from_torque(P, tau)
    l = P[PL]
    retract = P[PRETRACT] * l
    arm = P[PARM] * l
    ttol = cfg[C_TTOL]
    react = cfg[C_REACT] != 0.0
    q1, q2, w1, w2 = x[X_Q1], x[X_Q2], x[X_Q1D], x[X_Q2D]
    xs, ys, t0 = x[X_XS], x[X_YS], x[X_T]
    armed = f[F_ARMED] != 0
    nsub = max(1, int(math.ceil(dt / cfg[C_SUBSTEP] - 1e-9)))
    h = dt / nsub
    nx, ny = _normal(tx, ty, n, xs)
    k1a, k1b = model.accelerations(P, q1, q2, w1, w2, u)
    c0, _ = _clearance(P, tx, ty, n, q1, q2, xs, ys, 0.0)
    r0, _ = _clearance(P, tx, ty, n, q1, q2, xs, ys, retract)
    rate_max = MAX_TIP_SPEED / l
    status = OK
    t_fail = t0
    for k in range(nsub):
        off = k * h  # time offset of the start of the current segment
        seg = h  # remaining length of this substep
        # the last valid state, restored if this substep diverges
        v_q1, v_q2, v_w1, v_w2, v_xs, v_ys, v_armed = q1, q2, w1, w2, xs, ys, armed
        v_leg, v_nimp = f[F_LEG], f[F_NIMP]
        v_wnet, v_wpos, v_wabs = out[O_WNET], out[O_WPOS], out[O_WABS]
        while True:
            r = model.swing_rk4(P, q1, q2, w1, w2, u, seg, k1a, k1b)
            if _diverged(r[0], r[1], r[2], r[3], rate_max):
                status = INVALID
                break
            c1, fx1 = _clearance(P, tx, ty, n, r[0], r[1], xs, ys, 0.0)
            r1 = 1.0
            if not armed:
                r1, _ = _clearance(P, tx, ty, n, r[0], r[1], xs, ys, retract)
            # candidate events: touchdown (full-length foot) and trip (retracted foot)
            t_td = math.inf
            t_trip = math.inf
            td_face = False
            if c0 > 0.0 and c1 <= 0.0:
                tt, fl = _locate(
                    P, tx, ty, n, q1, q2, w1, w2, xs, ys, u, k1a, k1b, seg, c0, c1, 0.0, ttol
                )
                rr = model.swing_rk4(P, q1, q2, w1, w2, u, tt, k1a, k1b)
                fxr, _ = model.swing_foot_position(P, rr[0], rr[1], xs, ys, 0.0)
                if armed or fxr - xs >= arm:
                    t_td = tt
                    td_face = fl > cfg[C_FACE]
            elif armed and c0 <= 0.0:
                t_td = 0.0
            if not armed and r0 > 0.0 and r1 <= 0.0:
                t_trip, _ = _locate(
                    P, tx, ty, n, q1, q2, w1, w2, xs, ys, u, k1a, k1b, seg, r0, r1, retract, ttol
                )
            if t_trip < t_td or (td_face and t_td < math.inf):
                te = min(t_trip, t_td)
                rr = model.swing_rk4(P, q1, q2, w1, w2, u, te, k1a, k1b)
                q1, q2, w1, w2 = rr[0], rr[1], rr[2], rr[3]
                out[O_WNET] += rr[4]
                out[O_WPOS] += rr[5]
                out[O_WABS] += rr[6]
                status = TRIP
                t_fail = t0 + off + te
                break
            if t_td < math.inf:
                # ---- touchdown at off + t_td
                rr = model.swing_rk4(P, q1, q2, w1, w2, u, t_td, k1a, k1b)
                out[O_WNET] += rr[4]
                out[O_WPOS] += rr[5]
                out[O_WABS] += rr[6]
                p1, p2, pw1, pw2 = rr[0], rr[1], rr[2], rr[3]
                te = t0 + off + t_td
                fxp, _ = model.swing_foot_position(P, p1, p2, xs, ys, 0.0)
                fyp = terrain_height(tx, ty, n, fxp)
                n1, n2, nw1, nw2 = model.impact(P, p1, p2, pw1, pw2)
                nimp = f[F_NIMP]
                if nimp >= kmax:
                    status = STUCK
                elif cfg[C_IMPACT] != 0.0:
                    # impulse on the new stance foot, and take-off of the trailing foot
                    mx, my = _normal(tx, ty, n, fxp)
                    if not model.impact_admissible(
                        P, p1, p2, pw1, pw2, n1, n2, nw1, nw2, mx, my, nx, ny, cfg[C_MU]
                    ):
                        status = STUCK
                if status != OK:
                    q1, q2, w1, w2 = p1, p2, pw1, pw2
                    t_fail = te
                    break
                ev[nimp, E_T] = te
                ev[nimp, E_FX] = fxp
                ev[nimp, E_FY] = fyp
                ev[nimp, E_PRE] = p1
                ev[nimp, E_PRE + 1] = p2
                ev[nimp, E_PRE + 2] = pw1
                ev[nimp, E_PRE + 3] = pw2
                ev[nimp, E_POST] = n1
                ev[nimp, E_POST + 1] = n2
                ev[nimp, E_POST + 2] = nw1
                ev[nimp, E_POST + 3] = nw2
                f[F_NIMP] = nimp + 1
                f[F_LEG] = 1 - f[F_LEG]
                q1, q2, w1, w2 = n1, n2, nw1, nw2
                xs, ys = fxp, fyp
                nx, ny = _normal(tx, ty, n, xs)
                armed = False
                k1a, k1b = model.accelerations(P, q1, q2, w1, w2, u)
                status = _state_check(P, cfg, tx, ty, n, q1, q2, w1, w2, xs, ys)
                if status == OK and react:
                    status = _reaction_check(P, cfg, q1, q2, w1, w2, k1a, k1b, nx, ny)
                if status != OK:
                    t_fail = te
                    break
                c0, _ = _clearance(P, tx, ty, n, q1, q2, xs, ys, 0.0)
                r0, _ = _clearance(P, tx, ty, n, q1, q2, xs, ys, retract)
                off += t_td
                seg -= t_td
                if seg <= 0.0:
                    break
                continue
            # ---- no event: accept the substep
            q1, q2, w1, w2 = r[0], r[1], r[2], r[3]
            out[O_WNET] += r[4]
            out[O_WPOS] += r[5]
            out[O_WABS] += r[6]
            c0, r0 = c1, r1
            k1a, k1b = model.accelerations(P, q1, q2, w1, w2, u)
            te = t0 + off + seg
            status = _state_check(P, cfg, tx, ty, n, q1, q2, w1, w2, xs, ys)
            if status == OK and react:
                status = _reaction_check(P, cfg, q1, q2, w1, w2, k1a, k1b, nx, ny)
            if status != OK:
                t_fail = te
                break
            if not armed and c1 > 0.0 and fx1 - xs >= arm:
                armed = True
            break
        if status == INVALID:
            q1, q2, w1, w2, xs, ys, armed = v_q1, v_q2, v_w1, v_w2, v_xs, v_ys, v_armed
            f[F_LEG], f[F_NIMP] = v_leg, v_nimp
            out[O_WNET], out[O_WPOS], out[O_WABS] = v_wnet, v_wpos, v_wabs
            t_fail = t0 + k * h
        if status != OK:
            break
    x[X_Q1], x[X_Q2], x[X_Q1D], x[X_Q2D] = q1, q2, w1, w2
    x[X_XS], x[X_YS] = xs, ys
    if status != OK:
        x[X_T] = t_fail
        f[F_STATUS] = status
    else:
        x[X_T] = t0 + dt
    f[F_ARMED] = 1 if armed else 0


@_jit
def _check_torque(tau):
    for i in range(tau.shape[0]):
        if not math.isfinite(tau[i]):
            return i
    return -1


@njit(cache=True, fastmath=False, error_model="numpy")
def step_serial(P, cfg, tx, ty, tn, x, f, tau, dt, ev, out):
    """Advance every walker by ``dt`` [s], one after the other (small batches, one walker).

    Args: per-walker parameter vectors ``P`` (N, N_PARAMS), the config vector ``cfg``
    (``C_*``), padded terrain vertices ``tx, ty`` (N, K) [m] with counts ``tn`` (N,), state
    ``x`` (N, 7) and flags ``f`` (N, 4) (updated in place), hip torques ``tau`` (N,) [N m],
    event records ``ev`` (N, max_impacts, 11) and work ``out`` (N, 3) [J] (overwritten).

    Returns -1, or the index of the first non-finite torque (then nothing is changed).
    """
    bad = _check_torque(tau)
    if bad >= 0:
        return bad
    for i in range(x.shape[0]):
        walker_step(P[i], cfg, tx[i], ty[i], tn[i], x[i], f[i], tau[i], dt, ev[i], out[i])
    return -1


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def step_parallel(P, cfg, tx, ty, tn, x, f, tau, dt, ev, out):
    """Same as :func:`step_serial` with the walkers spread over threads."""
    bad = _check_torque(tau)
    if bad >= 0:
        return bad
    for i in prange(x.shape[0]):
        walker_step(P[i], cfg, tx[i], ty[i], tn[i], x[i], f[i], tau[i], dt, ev[i], out[i])
    return -1


@_jit
def initial_flags(P, cfg, tx, ty, n, q1, q2, xs, ys):
    """``(armed, retracted clearance [m])`` of a start state ``(q1, q2)`` [rad] with the stance
    foot at ``(xs, ys)`` [m]: whether the swing foot starts armed, and the height of the
    retracted swing-foot point above the ground."""
    c, fx = _clearance(P, tx, ty, n, q1, q2, xs, ys, 0.0)
    r, _ = _clearance(P, tx, ty, n, q1, q2, xs, ys, P[PRETRACT] * P[PL])
    armed = c > 0.0 and fx - xs >= P[PARM] * P[PL]
    return armed, r
