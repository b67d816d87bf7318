"""Hybrid simulator of the compass-gait biped: swing phases, located touchdowns, impacts, failures.

One compiled per-walker function (:func:`_walker_step`) advances one walker by one control
period under a held hip torque: fixed-step RK4 substeps, touchdown located by root finding on
the substep length, the impact map of :mod:`envs.model`, leg swap, failure checks. The batched
kernel runs it over walkers with ``numba.prange``; the single-walker kernel runs the same
function over a batch of one, so one walker and a batch take the same code path and give the
same numbers bit for bit.

Rules of the hybrid model (see also the README section "Simulator"):

* **Retractable feet.** Right after lift-off the swing foot is retracted by
  ``retract * l`` along the leg. It is *armed* (extended, latched until the next touchdown)
  as soon as, at the end of a substep, its full-length position is ahead of the stance foot
  by at least ``arm_distance * l`` (horizontally) and above the ground. A touchdown is the
  first downward zero crossing of the full-length clearance (foot height minus ground height)
  of an armed foot; a crossing of an unarmed foot counts if the foot is ahead by
  ``arm_distance * l`` at the crossing (it was armed in between). Before arming, the
  *retracted* foot point going below the ground is a **trip**; an armed foot whose clearance
  jumps through zero (it runs into a vertical face: the located crossing converges in time but
  the clearance just before it exceeds ``face_tol``) is a **trip** too.
* **Impact.** At touchdown the impact map ``envs.model.impact`` is applied, the legs swap,
  the stance foot moves to the foothold ``(x_foot, h(x_foot))`` and ``stance_leg`` (which
  physical leg, 0 or 1) flips. The impact is checked: the impulse on the new stance foot,
  ``(2 m + mH) (v_com+ - v_com-)``, must push (non-negative component along the ground normal
  under the foothold) and lie in the friction cone ``|tangential| <= mu * normal``, and the
  trailing (full-length) foot must leave the ground: its post-impact velocity must have a
  positive component along the ground normal under it. Otherwise the run ends with **stuck**;
  more than ``max_impacts`` impacts in one control period is **stuck** as well. A stuck walker
  is frozen at its pre-impact state.
* **Failures** are checked at the end of every substep and right after each impact: **fall**
  (hip height above the ground below ``fall_height * l``, or ``|q2| > q2_limit``),
  **liftoff** (normal component of the stance-foot ground reaction ``envs.model.ground_reaction``
  negative; normal of the ground segment under the stance foot, the segment to its right on
  a vertex), **slip** (tangential over normal reaction beyond ``mu``), **invalid** (non-finite
  state). A failed walker keeps its state at the failure instant and is not advanced again
  until it is reset.

Time is held in float64 seconds; the hip input of the kernels is the hip torque in N m (the
actuator limit ``u_max`` is the environment's business, not the simulator's).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numba
import numpy as np
from numba import njit, prange

from . import model
from .params import N_PARAMS, PB, PL, PM, PMH, RobotParams, as_params
from .terrain import Terrain, as_terrain, terrain_height, terrain_slope

# OpenMP worker threads spin while they wait; on a machine whose cores are busy with other
# processes the batched kernels then ran up to 8x slower than single-threaded. The workqueue
# layer degrades gracefully. A choice made with NUMBA_THREADING_LAYER is respected.
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

# ---------------------------------------------------------------------------- layouts
# float state x[N, 7]
X_Q1, X_Q2, X_Q1D, X_Q2D, X_XS, X_YS, X_T = range(7)
N_X = 7
# int flags f[N, 4]
F_LEG, F_ARMED, F_STATUS, F_NIMP = range(4)
N_F = 4
# per-impact event record ev[N, K, 11]: time, foothold (x, y), pre-impact q1 q2 q1d q2d, post
E_T, E_FX, E_FY = 0, 1, 2
E_PRE, E_POST = 3, 7
N_E = 11
# per-step output out[N, 3]: motor work (net, positive, absolute) over the step [J]
O_WNET, O_WPOS, O_WABS = range(3)
N_O = 3
# config vector
C_SUBSTEP, C_RETRACT, C_ARM, C_FALL_H, C_Q2MAX, C_MU, C_TTOL, C_FACE, C_REACT, C_IMPACT = range(10)
N_C = 10

#: failure codes (index) and names; code 0 means "running"
FAILURES = ("", "fall", "trip", "liftoff", "slip", "stuck", "invalid")
OK, FALL, TRIP, LIFTOFF, SLIP, STUCK, INVALID = range(7)

_jit = njit(cache=True, fastmath=False, error_model="numpy")


@dataclass(frozen=True)
class SimConfig:
    """Simulator settings.

    Attributes:
        substep: largest RK4 substep [s], > 0; each control period ``dt`` is split into
            ``ceil(dt / substep)`` equal substeps.
        retract: swing-foot retraction as a fraction of the leg length ``l``, in [0, 0.5].
        arm_distance: how far (horizontally) the full-length swing foot must be ahead of the
            stance foot before it is armed, fraction of ``l``, in [0, 2].
        fall_height: hip height above the ground below which the walker has fallen, fraction
            of ``l``, in [0, 1).
        q2_limit: largest ``|q2|`` [rad] before the walker has fallen, in (0, pi/2].
        mu: friction coefficient of the feet (``inf`` disables slip checks), > 0.
        time_tol: touchdown time tolerance [s] of the root finder, in (0, 1e-9].
        face_tol: clearance jump [m] that marks a foot hitting a vertical face, > 0.
        check_reaction: check lift-off and slip of the stance foot during the swing phase.
        check_impact: check the impact impulse and the trailing foot's take-off.
        max_impacts: most impacts recorded within one control period; more is "stuck".
    """

    substep: float = 2.5e-3
    retract: float = 0.05
    arm_distance: float = 0.1
    fall_height: float = 0.5
    q2_limit: float = 1.2
    mu: float = 1.0
    time_tol: float = 1e-13
    face_tol: float = 1e-8
    check_reaction: bool = True
    check_impact: bool = True
    max_impacts: int = 4

    def __post_init__(self) -> None:
        def req(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ValueError(
                    f"SimConfig.{name} = {getattr(self, name)!r} is out of range; "
                    f"allowed: {allowed}"
                )

        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("check_reaction", "check_impact"):
                req(isinstance(v, (bool, np.bool_)), f.name, "True or False")
                continue
            if f.name == "max_impacts":
                req(isinstance(v, (int, np.integer)) and 1 <= v <= 64, f.name, "integer 1..64")
                continue
            req(isinstance(v, (int, float, np.floating, np.integer)), f.name, "a real number")
            req(not math.isnan(float(v)), f.name, "not NaN")
        req(0 < self.substep <= 0.1, "substep", "(0, 0.1] s")
        req(0 <= self.retract <= 0.5, "retract", "[0, 0.5] (fraction of l)")
        req(0 <= self.arm_distance <= 2, "arm_distance", "[0, 2] (fraction of l)")
        req(0 <= self.fall_height < 1, "fall_height", "[0, 1) (fraction of l)")
        req(0 < self.q2_limit <= math.pi / 2, "q2_limit", "(0, pi/2] rad")
        req(self.mu > 0, "mu", "> 0 (inf disables the slip check)")
        req(0 < self.time_tol <= 1e-9, "time_tol", "(0, 1e-9] s")
        req(0 < self.face_tol < 1e-2, "face_tol", "(0, 0.01) m")

    @classmethod
    def accurate(cls, **changes: Any) -> SimConfig:
        """Small substeps (0.25 ms): energy drift below 1e-9 relative over 1 s."""
        return cls(**{"substep": 2.5e-4, **changes})

    def vector(self) -> np.ndarray:
        """Flat float64 vector for the kernels (layout: the ``C_*`` constants)."""
        c = np.zeros(N_C)
        c[C_SUBSTEP], c[C_RETRACT], c[C_ARM] = self.substep, self.retract, self.arm_distance
        c[C_FALL_H], c[C_Q2MAX], c[C_MU] = self.fall_height, self.q2_limit, self.mu
        c[C_TTOL], c[C_FACE] = self.time_tol, self.face_tol
        c[C_REACT], c[C_IMPACT] = float(self.check_reaction), float(self.check_impact)
        return c


# ---------------------------------------------------------------------------- compiled core
@_jit
def _rk4(P, q1, q2, w1, w2, u, h, k1a, k1b):
    """One RK4 step of length ``h`` under input ``u`` from a state whose accelerations
    ``(k1a, k1b)`` are known. Returns the new state and the motor work over the step
    (net, positive, absolute) by the same quadrature."""
    hh = 0.5 * h
    a2, b2 = model.accelerations(P, q1 + hh * w1, q2 + hh * w2, w1 + hh * k1a, w2 + hh * k1b, u)
    w1_2, w2_2 = w1 + hh * k1a, w2 + hh * k1b
    a3, b3 = model.accelerations(P, q1 + hh * w1_2, q2 + hh * w2_2, w1 + hh * a2, w2 + hh * b2, u)
    w1_3, w2_3 = w1 + hh * a2, w2 + hh * b2
    a4, b4 = model.accelerations(P, q1 + h * w1_3, q2 + h * w2_3, w1 + h * a3, w2 + h * b3, u)
    w1_4, w2_4 = w1 + h * a3, w2 + h * b3
    h6 = h / 6.0
    nq1 = q1 + h6 * (w1 + 2.0 * w1_2 + 2.0 * w1_3 + w1_4)
    nq2 = q2 + h6 * (w2 + 2.0 * w2_2 + 2.0 * w2_3 + w2_4)
    nw1 = w1 + h6 * (k1a + 2.0 * a2 + 2.0 * a3 + a4)
    nw2 = w2 + h6 * (k1b + 2.0 * b2 + 2.0 * b3 + b4)
    tau = P[PB] * u
    p1, p2, p3, p4 = tau * w1, tau * w1_2, tau * w1_3, tau * w1_4
    wnet = h6 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)
    wpos = h6 * (max(p1, 0.0) + 2.0 * max(p2, 0.0) + 2.0 * max(p3, 0.0) + max(p4, 0.0))
    wabs = h6 * (abs(p1) + 2.0 * abs(p2) + 2.0 * abs(p3) + abs(p4))
    return nq1, nq2, nw1, nw2, wnet, wpos, wabs


@_jit
def _clearance(P, tx, ty, n, q1, q2, xs, ys, retract):
    """Height of the swing-foot point (leg shortened by ``retract`` [m]) above the ground [m],
    and its x [m]."""
    fx, fy = model.swing_foot_position(P, q1, q2, xs, ys, retract)
    return fy - terrain_height(tx, ty, n, fx), fx


@_jit
def _normal(tx, ty, n, x):
    """Unit normal ``(nx, ny)`` of the ground segment under ``x``."""
    s = terrain_slope(tx, ty, n, x)
    r = 1.0 / math.sqrt(1.0 + s * s)
    return -s * r, r


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
        r = _rk4(P, q1, q2, w1, w2, u, m, k1a, k1b)
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
    """Failure code of the stance-foot ground reaction (OK, LIFTOFF or SLIP)."""
    fx, fy = model.ground_reaction(P, q1, q2, w1, w2, a1, a2)
    fn = fx * nx + fy * ny
    if fn < 0.0:
        return LIFTOFF
    ft = fx * ny - fy * nx
    if abs(ft) > cfg[C_MU] * fn:
        return SLIP
    return OK


@_jit
def _state_check(P, cfg, tx, ty, n, q1, q2, w1, w2, xs, ys):
    """Failure code of a state (OK, INVALID or FALL)."""
    if not (math.isfinite(q1) and math.isfinite(q2) and math.isfinite(w1) and math.isfinite(w2)):
        return INVALID
    if abs(q2) > cfg[C_Q2MAX]:
        return FALL
    hx, hy = model.hip_position(P, q1, q2, xs, ys)
    if hy - terrain_height(tx, ty, n, hx) < cfg[C_FALL_H] * P[PL]:
        return FALL
    return OK


@_jit
def _walker_step(P, cfg, tx, ty, n, x, f, tau, dt, ev, out):
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
    u = tau / P[PB]
    l = P[PL]
    retract = cfg[C_RETRACT] * l
    arm = cfg[C_ARM] * l
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
    status = OK
    t_fail = t0
    for k in range(nsub):
        off = k * h  # time offset of the start of the current segment
        seg = h  # remaining length of this substep
        while True:
            r = _rk4(P, q1, q2, w1, w2, u, seg, k1a, k1b)
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
                rr = _rk4(P, q1, q2, w1, w2, u, tt, k1a, k1b)
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
                rr = _rk4(P, q1, q2, w1, w2, u, te, k1a, k1b)
                q1, q2, w1, w2 = rr[0], rr[1], rr[2], rr[3]
                out[O_WNET] += rr[4]
                out[O_WPOS] += rr[5]
                out[O_WABS] += rr[6]
                status = TRIP
                t_fail = t0 + off + te
                break
            if t_td < math.inf:
                # ---- touchdown at off + t_td
                rr = _rk4(P, q1, q2, w1, w2, u, t_td, k1a, k1b)
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
                    mt = 2.0 * P[PM] + P[PMH]
                    vxm, vym = model.centre_of_mass_velocity(P, p1, p2, pw1, pw2)
                    vxp, vyp = model.centre_of_mass_velocity(P, n1, n2, nw1, nw2)
                    ix, iy = mt * (vxp - vxm), mt * (vyp - vym)
                    mx, my = _normal(tx, ty, n, fxp)
                    inn = ix * mx + iy * my
                    itt = ix * my - iy * mx
                    vfx, vfy = model.swing_foot_velocity(P, n1, n2, nw1, nw2)
                    if inn < 0.0 or abs(itt) > cfg[C_MU] * inn or vfx * nx + vfy * ny <= 0.0:
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

    Returns -1, or the index of the first non-finite torque (then nothing is changed).
    """
    bad = _check_torque(tau)
    if bad >= 0:
        return bad
    for i in range(x.shape[0]):
        _walker_step(P[i], cfg, tx[i], ty[i], tn[i], x[i], f[i], tau[i], dt, ev[i], out[i])
    return -1


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def step_parallel(P, cfg, tx, ty, tn, x, f, tau, dt, ev, out):
    """Same as :func:`step_serial` with the walkers spread over threads."""
    bad = _check_torque(tau)
    if bad >= 0:
        return bad
    for i in prange(x.shape[0]):
        _walker_step(P[i], cfg, tx[i], ty[i], tn[i], x[i], f[i], tau[i], dt, ev[i], out[i])
    return -1


@_jit
def _initial_flags(P, cfg, tx, ty, n, q1, q2, xs, ys):
    """(armed, retracted clearance) of a start state."""
    c, fx = _clearance(P, tx, ty, n, q1, q2, xs, ys, 0.0)
    r, _ = _clearance(P, tx, ty, n, q1, q2, xs, ys, cfg[C_RETRACT] * P[PL])
    armed = c > 0.0 and fx - xs >= cfg[C_ARM] * P[PL]
    return armed, r


# ---------------------------------------------------------------------------- Python API
@dataclass(frozen=True)
class StepEvents:
    """What happened to each walker during the last :meth:`Simulator.step`.

    The arrays are views of the simulator's buffers, overwritten by the next step (copy them
    to keep them).

    Attributes:
        n_impacts: (N,) int, touchdowns during the step.
        impact_time: (N, K) float, impact times [s]; entries ``>= n_impacts[i]`` are stale.
        foothold: (N, K, 2) float, new stance-foot positions [m].
        pre_impact: (N, K, 4) float, ``(q1, q2, q1d, q2d)`` just before each impact.
        post_impact: (N, K, 4) float, the same just after (legs swapped).
        work: (N, 3) float, motor work over the step [J]: net ``int tau q1d dt``, positive
            part ``int max(tau q1d, 0) dt``, absolute ``int |tau q1d| dt``.
        status: (N,) int, failure code (0 running; see :data:`FAILURES`).
        new_failure: (N,) bool, the walker failed during this step.
    """

    n_impacts: np.ndarray
    impact_time: np.ndarray
    foothold: np.ndarray
    pre_impact: np.ndarray
    post_impact: np.ndarray
    work: np.ndarray
    status: np.ndarray
    new_failure: np.ndarray


class Simulator:
    """A batch of ``num_walkers`` compass-gait walkers stepped together by control periods.

    Each walker has its own parameters and terrain (set at construction or later with
    :meth:`set_terrain`). State lives in preallocated numpy arrays; :meth:`step` does no
    allocation. One walker is a batch of one.

    Args:
        params: a :class:`RobotParams` (or preset name) for all walkers, or one per walker.
        terrain: a :class:`Terrain` (or spec) for all walkers, or one per walker.
        num_walkers: batch size N >= 1.
        dt: control period [s] (the torque is held over it), in (0, 1].
        config: :class:`SimConfig` (default settings if None).
        parallel: use the multi-threaded kernel (same numbers); default: when N >= 16 and
            numba has more than one thread.
    """

    def __init__(
        self,
        params: RobotParams | str | Sequence[RobotParams],
        terrain: Terrain | dict[str, Any] | Sequence[Terrain],
        num_walkers: int = 1,
        *,
        dt: float = 0.01,
        config: SimConfig | None = None,
        parallel: bool | None = None,
    ) -> None:
        if isinstance(num_walkers, bool) or not isinstance(num_walkers, (int, np.integer)):
            raise ValueError(f"num_walkers must be an integer >= 1, got {num_walkers!r}")
        if num_walkers < 1:
            raise ValueError(f"num_walkers = {num_walkers} out of range; allowed: >= 1")
        self.num_walkers = n = int(num_walkers)
        self.dt = _check_dt(dt)
        self.config = config if config is not None else SimConfig()
        if not isinstance(self.config, SimConfig):
            raise ValueError(f"config must be a SimConfig, got {type(self.config).__name__}")
        self._cfg = self.config.vector()
        if parallel is None:
            parallel = n >= 16 and numba.get_num_threads() > 1
        self._parallel = bool(parallel)
        self._kernel = step_parallel if self._parallel else step_serial
        self._P = np.zeros((n, N_PARAMS))
        self.params: list[RobotParams] = [None] * n  # type: ignore[list-item]
        self.set_params(params)
        self.terrains: list[Terrain] = [None] * n  # type: ignore[list-item]
        self._tx = np.zeros((n, 2))
        self._ty = np.zeros((n, 2))
        self._tn = np.ones(n, dtype=np.int64)
        self.set_terrain(terrain)
        k = self.config.max_impacts
        self._x = np.zeros((n, N_X))
        self._f = np.zeros((n, N_F), dtype=np.int64)
        self._f[:, F_STATUS] = -1  # not reset yet
        self._ready = False
        self._tau = np.zeros(n)
        self._ev = np.zeros((n, k, N_E))
        self._out = np.zeros((n, N_O))
        self._status_before = np.zeros(n, dtype=np.int64)
        self._new_failure = np.zeros(n, dtype=bool)
        self.events = StepEvents(
            n_impacts=self._f[:, F_NIMP],
            impact_time=self._ev[:, :, E_T],
            foothold=self._ev[:, :, E_FX : E_FY + 1],
            pre_impact=self._ev[:, :, E_PRE : E_PRE + 4],
            post_impact=self._ev[:, :, E_POST : E_POST + 4],
            work=self._out,
            status=self._f[:, F_STATUS],
            new_failure=self._new_failure,
        )

    # ------------------------------------------------------------------ set-up
    def set_params(self, params: Any, index: int | None = None) -> None:
        """Robot parameters for all walkers (``index`` None) or for walker ``index``."""
        idx = range(self.num_walkers) if index is None else [self._index(index)]
        if isinstance(params, (list, tuple)) and index is None:
            if len(params) != self.num_walkers:
                raise ValueError(f"params: got {len(params)} entries for {self.num_walkers}")
            plist = [as_params(p) for p in params]
        else:
            plist = [as_params(params)] * len(idx)
        for i, p in zip(idx, plist):
            self.params[i] = p
            self._P[i] = p.vector()

    def set_terrain(self, terrain: Any, index: int | None = None) -> None:
        """Terrain for all walkers (``index`` None) or for walker ``index`` (e.g. on reset)."""
        idx = range(self.num_walkers) if index is None else [self._index(index)]
        if isinstance(terrain, (list, tuple)) and index is None:
            if len(terrain) != self.num_walkers:
                raise ValueError(f"terrain: got {len(terrain)} entries for {self.num_walkers}")
            tlist = [as_terrain(t) for t in terrain]
        else:
            tlist = [as_terrain(terrain)] * len(idx)
        need = max(t.xs.size for t in tlist)
        if need > self._tx.shape[1]:
            tx = np.zeros((self.num_walkers, need))
            ty = np.zeros((self.num_walkers, need))
            tx[:, : self._tx.shape[1]] = self._tx
            ty[:, : self._ty.shape[1]] = self._ty
            self._tx, self._ty = tx, ty
        for i, t in zip(idx, tlist):
            self.terrains[i] = t
            m = t.xs.size
            self._tx[i, :m] = t.xs
            self._ty[i, :m] = t.ys
            self._tn[i] = m

    def _index(self, i: Any) -> int:
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
            raise ValueError(f"walker index must be an integer, got {i!r}")
        if not -self.num_walkers <= i < self.num_walkers:
            raise ValueError(f"walker index {i} out of range 0..{self.num_walkers - 1}")
        return int(i) % self.num_walkers

    # ------------------------------------------------------------------ reset / step
    def reset(
        self,
        q0: Sequence[float] | np.ndarray,
        qd0: Sequence[float] | np.ndarray,
        foot: Sequence[float] | np.ndarray | None = None,
        *,
        index: int | Sequence[int] | np.ndarray | None = None,
        stance_leg: int = 0,
        t: float = 0.0,
    ) -> None:
        """Put walkers in a start state (swing phase, stance foot on the ground).

        Args:
            q0: ``(q1, q2)`` [rad], shape (2,) for every selected walker or (M, 2).
            qd0: ``(q1d, q2d)`` [rad/s], same shapes.
            foot: stance-foot position ``(x, y)`` [m], shape (2,) or (M, 2); default: ``x = 0``
                on the ground. It must lie on the ground (within 1e-6 m).
            index: walkers to reset: None (all), an int, a sequence of ints or a bool mask.
            stance_leg: which physical leg (0 or 1) is the stance leg.
            t: start time [s].

        Raises:
            ValueError: non-finite or out-of-range states (``|q2| > q2_limit``, hip below
                ``fall_height * l``, retracted swing foot below the ground, foot off the ground).
        """
        idx = self._select(index)
        m = idx.size
        q = _rows("q0", q0, m)
        qd = _rows("qd0", qd0, m)
        if stance_leg not in (0, 1):
            raise ValueError(f"stance_leg = {stance_leg!r}; allowed: 0 or 1")
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"t = {t!r} must be finite")
        cfg = self.config
        for j, i in enumerate(idx):
            ter = self.terrains[i]
            if foot is None:
                fx, fy = 0.0, ter.height(0.0)
            else:
                fx, fy = _rows("foot", foot, m)[j]
                if abs(fy - ter.height(fx)) > 1e-6:
                    raise ValueError(
                        f"foot = ({fx}, {fy}) is not on the ground (height {ter.height(fx)} m)"
                    )
            p = self.params[i]
            q1, q2 = q[j]
            if abs(q2) > cfg.q2_limit:
                raise ValueError(f"q0[1] = {q2} out of range; allowed |q2| <= {cfg.q2_limit}")
            hx, hy = fx + p.l * math.sin(q2), fy + p.l * math.cos(q2)
            if hy - ter.height(hx) < cfg.fall_height * p.l:
                raise ValueError(
                    f"start state has the hip {hy - ter.height(hx):.4g} m above the ground; "
                    f"allowed: >= fall_height * l = {cfg.fall_height * p.l}"
                )
            armed, r = _initial_flags(
                self._P[i], self._cfg, self._tx[i], self._ty[i], self._tn[i], q1, q2, fx, fy
            )
            if not armed and r < -1e-12:
                raise ValueError(
                    f"start state has the retracted swing foot {-r:.4g} m below the ground"
                )
            self._x[i] = (q1, q2, qd[j, 0], qd[j, 1], fx, fy, t)
            self._f[i] = (stance_leg, int(armed), OK, 0)
            self._ev[i] = 0.0
            self._out[i] = 0.0

    def _select(self, index: Any) -> np.ndarray:
        if index is None:
            return np.arange(self.num_walkers)
        a = np.asarray(index)
        if a.dtype == bool:
            if a.shape != (self.num_walkers,):
                raise ValueError(f"mask must have shape ({self.num_walkers},), got {a.shape}")
            return np.nonzero(a)[0]
        return np.array([self._index(int(i)) for i in np.atleast_1d(a)], dtype=np.int64)

    def step(self, torque: float | np.ndarray, dt: float | None = None) -> StepEvents:
        """Advance all running walkers by one control period under held hip torques.

        Args:
            torque: hip torque [N m] (no actuator limit applied), a float for all walkers or
                an array of shape (N,).
            dt: this period's length [s]; default the simulator's ``dt``.

        Returns:
            :attr:`events` (views, overwritten by the next step).

        Raises:
            ValueError: non-finite torque (no walker is advanced), or walkers never reset.
        """
        if isinstance(torque, float) or (
            isinstance(torque, (int, np.number)) and not isinstance(torque, bool)
        ):
            self._tau[:] = torque
        else:
            a = np.asarray(torque, dtype=np.float64)
            if a.shape != (self.num_walkers,) and a.size != 1:
                raise ValueError(f"torque must be a float or shape ({self.num_walkers},)")
            self._tau[:] = a.reshape(-1) if a.size == self.num_walkers else a.reshape(())
        h = self.dt if dt is None else _check_dt(dt)
        if not self._ready:
            if self._f[:, F_STATUS].min() < 0:
                raise ValueError("step() before reset(): reset every walker first")
            self._ready = True
        st = self._f[:, F_STATUS]
        np.copyto(self._status_before, st)
        bad = self._kernel(
            self._P,
            self._cfg,
            self._tx,
            self._ty,
            self._tn,
            self._x,
            self._f,
            self._tau,
            h,
            self._ev,
            self._out,
        )
        if bad >= 0:
            raise ValueError(f"torque[{bad}] = {self._tau[bad]!r} must be finite")
        np.not_equal(st, self._status_before, out=self._new_failure)
        return self.events

    # ------------------------------------------------------------------ state access
    @property
    def q(self) -> np.ndarray:
        """(N, 2) view: ``(q1, q2)`` [rad]."""
        return self._x[:, X_Q1 : X_Q2 + 1]

    @property
    def qd(self) -> np.ndarray:
        """(N, 2) view: ``(q1d, q2d)`` [rad/s]."""
        return self._x[:, X_Q1D : X_Q2D + 1]

    @property
    def stance_foot(self) -> np.ndarray:
        """(N, 2) view: stance-foot position [m]."""
        return self._x[:, X_XS : X_YS + 1]

    @property
    def t(self) -> np.ndarray:
        """(N,) view: time [s] (the failure time for failed walkers)."""
        return self._x[:, X_T]

    @property
    def stance_leg(self) -> np.ndarray:
        """(N,) view: physical leg (0 or 1) in stance; flips at every impact."""
        return self._f[:, F_LEG]

    @property
    def armed(self) -> np.ndarray:
        """(N,) view: the swing foot is extended (armed for touchdown)."""
        return self._f[:, F_ARMED]

    @property
    def status(self) -> np.ndarray:
        """(N,) view: failure code, 0 while running (names in :data:`FAILURES`)."""
        return self._f[:, F_STATUS]

    @property
    def terrain_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Padded terrain vertices ``(tx (N, K), ty (N, K), tn (N,))`` as the kernels see them
        (``envs.terrain.terrain_height(tx[i], ty[i], tn[i], x)``). :meth:`set_terrain` may
        reallocate them: fetch them again after it."""
        return self._tx, self._ty, self._tn

    def failure(self, i: int = 0) -> str | None:
        """Failure reason of walker ``i`` or None while it runs."""
        s = int(self._f[self._index(i), F_STATUS])
        return FAILURES[s] if s > 0 else None

    def state(self, i: int = 0) -> np.ndarray:
        """Copy of walker ``i``'s state ``(q1, q2, q1d, q2d)``."""
        return self._x[self._index(i), :4].copy()


def _check_dt(dt: Any) -> float:
    try:
        v = float(dt)
    except (TypeError, ValueError):
        raise ValueError(f"dt must be a number of seconds, got {dt!r}") from None
    if not (math.isfinite(v) and 0 < v <= 1.0):
        raise ValueError(f"dt = {dt!r} out of range; allowed: (0, 1] s")
    return v


def _rows(name: str, value: Any, m: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None
    if a.shape == (2,):
        a = np.broadcast_to(a, (m, 2))
    if a.shape != (m, 2):
        raise ValueError(f"{name} must have shape (2,) or ({m}, 2), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {value!r} must be finite")
    return a


# ---------------------------------------------------------------------------- simulate()
@dataclass
class SimResult:
    """Trajectory of one walker from :func:`simulate`.

    Samples are taken at the end of every control period and on both sides of every impact
    (two samples with the same time: pre-impact then post-impact, legs swapped).

    Attributes:
        t: (M,) time [s].
        q: (M, 2) ``(q1, q2)`` [rad] (``q1`` inter-leg angle, ``q2`` stance-leg angle).
        qd: (M, 2) ``(q1d, q2d)`` [rad/s].
        stance_foot: (M, 2) stance-foot position [m].
        stance_leg: (M,) physical stance leg (0 or 1).
        torque: (M,) hip torque [N m] held over the period ending at the sample.
        impact_times: (k,) touchdown times [s].
        footholds: (k, 2) touchdown positions [m].
        failure: failure reason (``"fall"``, ``"trip"``, ``"liftoff"``, ``"slip"``,
            ``"stuck"``, ``"invalid"``) or None.
        failure_time: time of the failure [s] or None.
        work: motor work over the run [J]: (net, positive, absolute).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    stance_foot: np.ndarray
    stance_leg: np.ndarray
    torque: np.ndarray
    impact_times: np.ndarray
    footholds: np.ndarray
    failure: str | None
    failure_time: float | None
    work: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def step_periods(self) -> np.ndarray:
        """Durations between consecutive impacts [s]."""
        return np.diff(self.impact_times)

    @property
    def step_lengths(self) -> np.ndarray:
        """Distances between consecutive footholds [m]."""
        return (
            np.hypot(*np.diff(self.footholds, axis=0).T)
            if len(self.footholds) > 1
            else (np.zeros(0))
        )


TorqueSpec = float | Callable[[float, np.ndarray, np.ndarray], float] | None


def simulate(
    params: RobotParams | str,
    terrain: Terrain | dict[str, Any] | str,
    q0: Sequence[float],
    qd0: Sequence[float],
    duration: float,
    torque: TorqueSpec = None,
    *,
    foot: Sequence[float] | None = None,
    dt: float = 0.01,
    config: SimConfig | None = None,
    stance_leg: int = 0,
    stop_at_impacts: int | None = None,
) -> SimResult:
    """Simulate one walker for ``duration`` seconds.

    Args:
        params: robot parameters or a preset name.
        terrain: a :class:`Terrain`, a spec dict, or a kind name (``"flat"``).
        q0: start ``(q1, q2)`` [rad]; qd0: start ``(q1d, q2d)`` [rad/s].
        duration: simulated time [s], > 0.
        torque: hip torque [N m] (not limited by ``u_max``): None (passive), a float, or a
            callable ``torque(t, q, qd) -> float`` evaluated at the start of every control
            period and held over it (zero-order hold).
        foot: stance-foot position ``(x, y)`` [m]; default ``x = 0`` on the ground.
        dt: control period and output sampling interval [s].
        config: simulator settings (:class:`SimConfig`; ``SimConfig.accurate()`` for
            reference-quality runs).
        stance_leg: physical stance leg at the start (0 or 1).
        stop_at_impacts: stop at the end of the control period in which this many
            touchdowns have happened (None: run the whole duration).

    Returns:
        :class:`SimResult`. A failure ends the run early.
    """
    T = float(duration)
    if not (math.isfinite(T) and T > 0):
        raise ValueError(f"duration = {duration!r} out of range; allowed: finite > 0 s")
    if torque is not None and not callable(torque):
        tv = float(torque)
        if not math.isfinite(tv):
            raise ValueError(f"torque = {torque!r} must be finite")
        const = tv
        torque_fn = None
    else:
        const = 0.0
        torque_fn = torque
    sim = Simulator(params, terrain, 1, dt=dt, config=config, parallel=False)
    sim.reset(q0, qd0, foot, stance_leg=stance_leg)
    x, f, ev = sim._x[0], sim._f[0], sim._ev[0]
    ts, xs_, legs, taus = [float(x[X_T])], [x[:6].copy()], [int(f[F_LEG])], [0.0]
    imp_t: list[float] = []
    holds: list[tuple[float, float]] = []
    work = np.zeros(3)
    nsteps = int(math.ceil(T / sim.dt - 1e-9))
    for k in range(nsteps):
        h = min(sim.dt, T - k * sim.dt)
        if h <= 1e-12:
            break
        if torque_fn is not None:
            tv = float(torque_fn(float(x[X_T]), x[0:2].copy(), x[2:4].copy()))
            if not math.isfinite(tv):
                raise ValueError(f"torque(t={x[X_T]:.6g}) returned {tv!r}; must be finite")
        else:
            tv = const
        foot_before = tuple(xs_[-1][4:6])
        leg_before = legs[-1]
        sim.step(tv, h)
        work += sim._out[0]
        for j in range(int(f[F_NIMP])):
            e = ev[j]
            ts += [float(e[E_T]), float(e[E_T])]
            xs_ += [
                np.array([*e[E_PRE : E_PRE + 4], *foot_before]),
                np.array([*e[E_POST : E_POST + 4], e[E_FX], e[E_FY]]),
            ]
            legs += [leg_before, 1 - leg_before]
            taus += [tv, tv]
            leg_before = 1 - leg_before
            foot_before = (float(e[E_FX]), float(e[E_FY]))
            imp_t.append(float(e[E_T]))
            holds.append(foot_before)
        ts.append(float(x[X_T]))
        xs_.append(x[:6].copy())
        legs.append(int(f[F_LEG]))
        taus.append(tv)
        if f[F_STATUS] != OK:
            break
        if stop_at_impacts is not None and len(imp_t) >= stop_at_impacts:
            break
    arr = np.array(xs_)
    status = int(f[F_STATUS])
    return SimResult(
        t=np.array(ts),
        q=arr[:, 0:2].copy(),
        qd=arr[:, 2:4].copy(),
        stance_foot=arr[:, 4:6].copy(),
        stance_leg=np.array(legs, dtype=np.int64),
        torque=np.array(taus),
        impact_times=np.array(imp_t),
        footholds=np.array(holds, dtype=np.float64).reshape(-1, 2),
        failure=FAILURES[status] if status else None,
        failure_time=float(x[X_T]) if status else None,
        work=work,
    )


# ---------------------------------------------------------------------------- passive gait
@dataclass(frozen=True)
class LimitCycle:
    """A periodic passive gait down a slope, on the post-impact Poincare section.

    Attributes:
        state: post-impact ``(q1, q2, q1d, q2d)`` of the cycle.
        period: step period [s].
        step_length: distance between consecutive footholds [m].
        jacobian: (3, 3) Jacobian of the step-to-step map in the section coordinates
            ``(q2, q1d, q2d)`` (central finite differences).
        eigenvalues: its eigenvalues (moduli below 1: stable).
    """

    state: np.ndarray
    period: float
    step_length: float
    jacobian: np.ndarray
    eigenvalues: np.ndarray


def slope_section_state(z: Sequence[float], slope: float) -> tuple[np.ndarray, np.ndarray]:
    """Section coordinates ``z = (q2, q1d, q2d)`` right after an impact on a constant slope of
    ``slope`` [rad] (negative downhill) -> ``(q, qd)``: both feet on the ground, so
    ``q1 = 2 (q2 + slope)``."""
    q2, q1d, q2d = (float(v) for v in z)
    return np.array([2.0 * (q2 + slope), q2]), np.array([q1d, q2d])


def slope_step_map(
    params: RobotParams | str,
    slope: float,
    z: Sequence[float],
    config: SimConfig | None = None,
) -> tuple[np.ndarray, float, float]:
    """One passive step from the post-impact section point ``z`` (see
    :func:`slope_section_state`): returns the next section point, the step period [s] and the
    step length [m]. Raises ``RuntimeError`` if the walker fails or does not step within 5 s."""
    q0, qd0 = slope_section_state(z, slope)
    res = simulate(params, Terrain.slope(slope), q0, qd0, 5.0, config=config, stop_at_impacts=1)
    if res.failure is not None or len(res.impact_times) < 1:
        raise RuntimeError(f"no passive step from {list(z)}: failure {res.failure}")
    k = int(np.nonzero(np.diff(res.t) == 0)[0][0]) + 1
    znew = np.array([res.q[k, 1], res.qd[k, 0], res.qd[k, 1]])
    return znew, float(res.impact_times[0]), float(np.hypot(*res.footholds[0]))


def passive_limit_cycle(
    params: RobotParams | str,
    slope: float,
    guess: Sequence[float],
    config: SimConfig | None = None,
    tol: float = 1e-11,
    fd_step: float = 1e-6,
) -> LimitCycle:
    """Fixed point of the passive step-to-step map down a slope by Newton's method.

    Args:
        params: robot parameters or preset name.
        slope: ground angle [rad], negative downhill.
        guess: starting section point ``(q2, q1d, q2d)`` just after an impact.
        config: simulator settings (default :meth:`SimConfig.accurate`).
        tol: convergence tolerance on the section point.
        fd_step: finite-difference step of the Jacobian.

    Raises:
        RuntimeError: the walker fails, or Newton does not converge in 20 iterations.
    """
    cfg = config if config is not None else SimConfig.accurate()
    z = np.asarray(guess, dtype=np.float64).copy()
    if z.shape != (3,) or not np.all(np.isfinite(z)):
        raise ValueError(f"guess must be 3 finite numbers (q2, q1d, q2d), got {guess!r}")

    def jac(z: np.ndarray) -> np.ndarray:
        J = np.empty((3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = fd_step
            J[:, j] = (
                slope_step_map(params, slope, z + e, cfg)[0]
                - slope_step_map(params, slope, z - e, cfg)[0]
            ) / (2 * fd_step)
        return J

    for _ in range(20):
        fz = slope_step_map(params, slope, z, cfg)[0]
        dz = np.linalg.solve(jac(z) - np.eye(3), z - fz)
        z = z + dz
        if np.max(np.abs(dz)) < tol:
            break
    else:
        raise RuntimeError("passive limit cycle: Newton did not converge")
    J = jac(z)
    _, period, length = slope_step_map(params, slope, z, cfg)
    q, qd = slope_section_state(z, slope)
    return LimitCycle(
        state=np.r_[q, qd],
        period=period,
        step_length=length,
        jacobian=J,
        eigenvalues=np.linalg.eigvals(J),
    )
