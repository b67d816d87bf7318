"""Physical parameters of the compass-gait biped, with validation and presets.

The parameter set follows Manchester et al. (2011), Appendix B and Table 1. Presets live as
YAML files in ``configs/robots/`` and are loaded with :meth:`RobotParams.from_preset`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from configs import CONFIG_DIR

from ..config_util import dataclass_from_mapping, read_yaml_mapping

# Layout of the flat parameter vector consumed by the compiled model kernels (envs.physics.model).
P1, P2, P3, P4, P5, P6, P7, P8 = range(8)  # coefficients p1 .. p8 (RobotParams.coefficients)
PB = 8  # hip torque per unit input, RobotParams.input_gain = kI * ktau [N m per input unit]
PFC = 9  # Coulomb friction [N m]
PFV = 10  # viscous friction [N m s/rad]
PL = 11  # leg length [m]
PLC = 12  # centre of mass from the foot [m]
PM = 13  # leg mass [kg]
PMH = 14  # inertial hip mass [kg]
PMHG = 15  # gravitational hip mass [kg]
PG = 16  # gravity [m/s^2]
PIC = 17  # leg inertia [kg m^2]
PUMAX = 18  # input limit [input units]
PRETRACT = 19  # swing-foot retraction, fraction of l
PARM = 20  # arming distance of the swing foot, fraction of l
N_PARAMS = 21

# Physically meaningful ranges (upper bounds) of the parameters: far beyond any compass-gait
# robot, they keep absurd values (1e300 kg, a 1e100 N m motor) out of the fixed-step integrator.
MAX_MASS = 1e3  # m, mH, |mHg| [kg]
MAX_LENGTH = 10.0  # l [m]
MAX_INERTIA = 1e3  # Ic [kg m^2]
MAX_GRAVITY = 100.0  # g [m/s^2]
MAX_CURRENT_GAIN = 1e3  # kI [A per input unit]
MAX_TORQUE_CONSTANT = 1e3  # ktau [N m/A]
MAX_HIP_TORQUE = 1e4  # the actuator's torque limit kI ktau u_max, and Fc [N m]
#: fastest leg-tip speed of a valid state [m/s]: the simulator's rate bound is ``MAX_TIP_SPEED /
#: l`` (:attr:`RobotParams.max_rate`); a faster state has diverged
MAX_TIP_SPEED = 100.0
#: the simulator's default RK4 substep [s] (:class:`envs.physics.SimConfig`)
DEFAULT_SUBSTEP = 2.5e-3
#: ``h * lambda`` kept by the viscous hip friction's decay rate ``lambda`` [1/s] over an RK4
#: substep ``h`` [s]: a margin below RK4's stability limit 2.785 on the negative real axis
RK4_DECAY_LIMIT = 2.5

#: the physical parameters a model error perturbs (:meth:`RobotParams.perturbed`): masses,
#: hip gravitational mass, leg inertia, leg length, centre of mass, hip friction and the motor's
#: torque constant. Not perturbed: ``g`` (the planet), ``kI`` and ``u_max`` (the controller's
#: side of the actuator) and the foot geometry (fractions of ``l``, so it scales with ``l``).
PHYSICAL_PARAMS = ("m", "mH", "mHg", "Ic", "l", "lc", "Fc", "Fv", "ktau")

#: the error for a setting that moved to :class:`RobotParams` (``key``: the field), e.g. the
#: swing-foot geometry that the simulator and planner settings held
MOVED_TO_ROBOT = (
    "it is a robot parameter now, read by the simulator, the planner and the state estimator "
    "alike: set RobotParams.{key} (robot YAML key '{key}', or RobotParams.replace({key}=...))"
)


@dataclass(frozen=True)
class RobotParams:
    """Compass-gait robot parameters (SI units).

    Attributes:
        m: mass of one leg [kg], > 0.
        mH: hip mass in the inertia terms [kg], >= 0.
        mHg: hip mass in the gravity terms [kg]; may be negative (boom counterweight), but the
            total gravitational mass ``2 m + mHg`` must be positive.
        l: leg length [m], > 0.
        lc: distance of a leg's centre of mass from its foot [m], in [0, l].
        Ic: leg inertia about its centre of mass [kg m^2], >= 0.
        g: gravitational acceleration [m/s^2], > 0.
        kI: current per unit input [A], > 0.
        ktau: motor torque constant [N m/A], > 0.
        Fc: hip Coulomb friction [N m], >= 0.
        Fv: hip viscous friction [N m s/rad], >= 0, at most
            :meth:`viscous_friction_limit` of the default 2.5 ms substep (the explicit RK4
            substep stays stable; a simulator with a longer substep checks its own limit).
        u_max: actuator limit on the input [input units], > 0; hip torque is
            ``input_gain * u`` with ``input_gain = kI * ktau``, at most ``MAX_HIP_TORQUE``.
        retract: swing-foot retraction: right after lift-off the swing leg is shortened by
            ``retract * l`` [fraction of l], in [0, 0.5].
        arm_distance: the full-length swing foot is armed for touchdown once it is
            ``arm_distance * l`` ahead of the stance foot (horizontally) [fraction of l], in
            [0, 2].
        name: label of the parameter set.

    The simulator, the gait planner and the state estimator all read ``retract`` and
    ``arm_distance`` from here (the retractable-foot rule of :mod:`envs.physics.kernel`).

    Upper bounds (the ``MAX_*`` constants of this module): masses 1e3 kg, ``l`` 10 m, ``Ic``
    1e3 kg m^2, ``g`` 100 m/s^2, ``kI`` 1e3 A, ``ktau`` 1e3 N m/A, ``Fc`` and the hip torque
    limit ``kI ktau u_max`` 1e4 N m.
    """

    m: float
    mH: float
    mHg: float
    l: float  # noqa: E741
    lc: float
    Ic: float = 0.0
    g: float = 9.81
    kI: float = 1.0
    ktau: float = 1.0
    Fc: float = 0.0
    Fv: float = 0.0
    u_max: float = 40.0
    retract: float = 0.05
    arm_distance: float = 0.1
    name: str = "custom"

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "name":
                continue
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise ValueError(f"RobotParams.{f.name} must be a real number, got {v!r}")
            if not math.isfinite(float(v)):
                raise ValueError(f"RobotParams.{f.name} must be finite, got {v!r}")
            object.__setattr__(self, f.name, float(v))
        _require(0 < self.l <= MAX_LENGTH, "l", self.l, f"(0, {MAX_LENGTH:g}] m (leg length)")
        _require(0 < self.m <= MAX_MASS, "m", self.m, f"(0, {MAX_MASS:g}] kg (leg mass)")
        _require(
            0 <= self.mH <= MAX_MASS, "mH", self.mH, f"[0, {MAX_MASS:g}] kg (inertial hip mass)"
        )
        _require(0 <= self.lc <= self.l, "lc", self.lc, f"[0, l] = [0, {self.l}] m (on the leg)")
        _require(0 <= self.Ic <= MAX_INERTIA, "Ic", self.Ic, f"[0, {MAX_INERTIA:g}] kg m^2")
        _require(0 < self.g <= MAX_GRAVITY, "g", self.g, f"(0, {MAX_GRAVITY:g}] m/s^2")
        _require(
            2 * self.m + self.mHg > 0 and self.mHg <= MAX_MASS,
            "mHg",
            self.mHg,
            f"(-2 m, {MAX_MASS:g}] = ({-2 * self.m}, {MAX_MASS:g}] kg (total gravitational mass "
            "must be positive)",
        )
        _require(0 < self.kI <= MAX_CURRENT_GAIN, "kI", self.kI, f"(0, {MAX_CURRENT_GAIN:g}] A")
        _require(
            0 < self.ktau <= MAX_TORQUE_CONSTANT,
            "ktau",
            self.ktau,
            f"(0, {MAX_TORQUE_CONSTANT:g}] N m/A",
        )
        _require(0 <= self.Fc <= MAX_HIP_TORQUE, "Fc", self.Fc, f"[0, {MAX_HIP_TORQUE:g}] N m")
        u_top = MAX_HIP_TORQUE / self.input_gain
        _require(
            0 < self.u_max <= u_top,
            "u_max",
            self.u_max,
            f"(0, {u_top:.6g}] input units (a hip torque limit kI * ktau * u_max of at most "
            f"{MAX_HIP_TORQUE:g} N m)",
        )
        _require(0 <= self.retract <= 0.5, "retract", self.retract, "[0, 0.5] (fraction of l)")
        _require(
            0 <= self.arm_distance <= 2, "arm_distance", self.arm_distance, "[0, 2] (fraction of l)"
        )
        # Positive definiteness of M for all q1: M11 = p1 > 0 and det(M) > 0.
        p1 = (self.l - self.lc) ** 2 * self.m + self.Ic
        _require(p1 > 0, "Ic", self.Ic, "> 0 when lc == l (swing-leg inertia about the hip is 0)")
        fv_top = self.viscous_friction_limit(DEFAULT_SUBSTEP)
        _require(
            0 <= self.Fv <= fv_top,
            "Fv",
            self.Fv,
            f"[0, {fv_top:.4g}] N m s/rad (stiffer hip friction makes the explicit RK4 substep "
            f"of {DEFAULT_SUBSTEP * 1e3:g} ms unstable for this robot's leg inertia)",
        )

    # ------------------------------------------------------------------ derived quantities
    @property
    def input_gain(self) -> float:
        """Hip torque per unit input, ``kI * ktau`` [N m per input unit] (``b`` of
        ``B = [b, 0]``; compiled kernels read it as :func:`envs.physics.model.input_gain`)."""
        return self.kI * self.ktau

    @property
    def tau_max(self) -> float:
        """Largest hip torque the actuator can produce, ``input_gain * u_max`` [N m]."""
        return self.input_gain * self.u_max

    @property
    def max_rate(self) -> float:
        """Fastest joint rate of a valid state, ``MAX_TIP_SPEED / l`` [rad/s] (a leg tip at
        100 m/s): start states must stay within it, and a faster simulated state has diverged
        (``"invalid"``)."""
        return MAX_TIP_SPEED / self.l

    def viscous_friction_limit(self, substep: float) -> float:
        """Largest hip viscous friction ``Fv`` [N m s/rad] that an explicit RK4 substep of
        ``substep`` [s] integrates stably.

        The friction makes the hip rate decay at ``Fv (M^-1)_11`` [1/s]; the bound keeps
        ``substep`` times the fastest such rate (over all ``q1``) at :data:`RK4_DECAY_LIMIT`.
        """
        c = self.coefficients()
        p1, p2, p3 = c["p1"], c["p2"], c["p3"]
        cos_q1 = np.linspace(-1.0, 1.0, 2001)
        det = p1 * (p1 + p3) - (cos_q1 * p2) ** 2
        inv11 = float(np.max((p3 + 2.0 * p1 - 2.0 * cos_q1 * p2) / det))
        return RK4_DECAY_LIMIT / (substep * inv11)

    @property
    def total_mass(self) -> float:
        """Inertial mass of the robot, ``2 m + mH`` [kg]."""
        return 2 * self.m + self.mH

    def coefficients(self) -> dict[str, float]:
        """The coefficients ``p1 .. p8`` of Appendix B of the paper."""
        m, mH, mHg, l, lc, Ic, g = self.m, self.mH, self.mHg, self.l, self.lc, self.Ic, self.g
        p7 = mH + 2 * m
        return {
            "p1": (l - lc) ** 2 * m + Ic,
            "p2": m * l * (l - lc),
            "p3": mH * l**2 + 2 * m * l * lc,
            "p4": m * g * (l - lc),
            "p5": g * (mHg * l + 2 * m * lc),
            "p6": m * (l - lc),
            "p7": p7,
            "p8": lc * p7 + mH * (l - lc),
        }

    def vector(self) -> np.ndarray:
        """Flat float64 vector for the compiled kernels (layout: the ``P*`` constants)."""
        c = self.coefficients()
        v = np.zeros(N_PARAMS)
        v[:8] = [c[f"p{i}"] for i in range(1, 9)]
        v[PB] = self.input_gain
        v[PFC], v[PFV] = self.Fc, self.Fv
        v[PL], v[PLC], v[PM], v[PMH], v[PMHG] = self.l, self.lc, self.m, self.mH, self.mHg
        v[PG], v[PIC], v[PUMAX] = self.g, self.Ic, self.u_max
        v[PRETRACT], v[PARM] = self.retract, self.arm_distance
        return v

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict[str, Any]:
        """Plain dict (YAML/JSON serialisable)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RobotParams:
        """Build from a dict ``d`` of the fields (SI units); unknown or missing keys raise
        ``ValueError``."""
        return dataclass_from_mapping(cls, d, "robot", item="parameter")

    @classmethod
    def from_yaml(cls, path: str | Path) -> RobotParams:
        """Load from the YAML file at ``path`` (the fields, SI units)."""
        return cls.from_dict(read_yaml_mapping(path, "robot", allow_empty=False))

    @classmethod
    def from_preset(cls, name: str) -> RobotParams:
        """Load the preset ``name`` from ``configs/robots/NAME.yaml`` (``paper`` or ``classic``,
        ...)."""
        presets = available_presets()
        if name not in presets:
            raise ValueError(f"unknown robot preset {name!r}; available: {presets}")
        return cls.from_yaml(CONFIG_DIR / "robots" / f"{name}.yaml")

    def replace(self, **changes: Any) -> RobotParams:
        """Copy with some fields changed (validated)."""
        d = self.to_dict()
        d.update(changes)
        return RobotParams.from_dict(d)

    def perturbed(self, errors: dict[str, float]) -> RobotParams:
        """Copy with relative errors on physical parameters: ``value * (1 + error)``.

        The centre of mass moves with the leg: ``lc`` is scaled by the error of ``l`` and then
        by its own, so ``lc / l`` changes by ``lc``'s error only; ``retract`` and
        ``arm_distance`` are fractions of ``l`` and scale with it. A parameter that is zero
        (``Fc`` of a frictionless robot) stays zero.

        Args:
            errors: ``{name: relative error}`` for names in :data:`PHYSICAL_PARAMS`, each
                error a finite number > -1 (``0.05`` is 5 % more).

        Raises:
            ValueError: an unknown name or a bad error, or a result that is not a valid robot
                (the message names the parameter and its allowed range; nothing is clipped).
        """
        unknown = sorted(set(errors) - set(PHYSICAL_PARAMS), key=str)
        if unknown:
            raise ValueError(
                f"unknown physical parameter(s) {unknown}; allowed: {list(PHYSICAL_PARAMS)}"
            )
        for name, e in errors.items():
            ok = not isinstance(e, bool) and isinstance(e, (int, float, np.integer, np.floating))
            if not (ok and math.isfinite(e) and e > -1.0):
                raise ValueError(f"relative error of {name} = {e!r}; allowed: finite > -1")
        changes = {name: getattr(self, name) * (1.0 + float(e)) for name, e in errors.items()}
        changes["lc"] = changes.get("lc", self.lc) * (1.0 + float(errors.get("l", 0.0)))
        return self.replace(**changes)


def available_presets() -> list[str]:
    """Names of the robot presets shipped in ``configs/robots``."""
    return sorted(p.stem for p in (CONFIG_DIR / "robots").glob("*.yaml"))


def as_params(robot: RobotParams | str | dict[str, Any]) -> RobotParams:
    """Coerce a preset name, a dict or a :class:`RobotParams` into :class:`RobotParams`."""
    if isinstance(robot, RobotParams):
        return robot
    if isinstance(robot, str):
        return RobotParams.from_preset(robot)
    if isinstance(robot, dict):
        return RobotParams.from_dict(robot)
    raise ValueError(f"robot must be a preset name, a dict or RobotParams, got {type(robot)}")


def _require(ok: bool, field: str, value: float, allowed: str) -> None:
    if not ok:
        raise ValueError(f"RobotParams.{field} = {value!r} is out of range; allowed: {allowed}")
