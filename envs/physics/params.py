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
import yaml

from configs import CONFIG_DIR

from ..config_util import dataclass_from_mapping

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
        Fv: hip viscous friction [N m s/rad], >= 0.
        u_max: actuator limit on the input [input units], > 0; hip torque is
            ``input_gain * u`` with ``input_gain = kI * ktau``.
        retract: swing-foot retraction: right after lift-off the swing leg is shortened by
            ``retract * l`` [fraction of l], in [0, 0.5].
        arm_distance: the full-length swing foot is armed for touchdown once it is
            ``arm_distance * l`` ahead of the stance foot (horizontally) [fraction of l], in
            [0, 2].
        name: label of the parameter set.

    The simulator, the gait planner and the state estimator all read ``retract`` and
    ``arm_distance`` from here (the retractable-foot rule of :mod:`envs.physics.kernel`).
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
        _require(self.l > 0, "l", self.l, "> 0 m (leg length)")
        _require(self.m > 0, "m", self.m, "> 0 kg (leg mass)")
        _require(self.mH >= 0, "mH", self.mH, ">= 0 kg (inertial hip mass)")
        _require(0 <= self.lc <= self.l, "lc", self.lc, f"[0, l] = [0, {self.l}] m (on the leg)")
        _require(self.Ic >= 0, "Ic", self.Ic, ">= 0 kg m^2")
        _require(self.g > 0, "g", self.g, "> 0 m/s^2")
        _require(
            2 * self.m + self.mHg > 0,
            "mHg",
            self.mHg,
            f"> -2 m = {-2 * self.m} kg (total gravitational mass must be positive)",
        )
        _require(self.kI > 0, "kI", self.kI, "> 0 A")
        _require(self.ktau > 0, "ktau", self.ktau, "> 0 N m/A")
        _require(self.Fc >= 0, "Fc", self.Fc, ">= 0 N m")
        _require(self.Fv >= 0, "Fv", self.Fv, ">= 0 N m s/rad")
        _require(self.u_max > 0, "u_max", self.u_max, "> 0 input units")
        _require(0 <= self.retract <= 0.5, "retract", self.retract, "[0, 0.5] (fraction of l)")
        _require(
            0 <= self.arm_distance <= 2, "arm_distance", self.arm_distance, "[0, 2] (fraction of l)"
        )
        # Positive definiteness of M for all q1: M11 = p1 > 0 and det(M) > 0.
        p1 = (self.l - self.lc) ** 2 * self.m + self.Ic
        _require(p1 > 0, "Ic", self.Ic, "> 0 when lc == l (swing-leg inertia about the hip is 0)")

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
        with open(path) as fh:
            return cls.from_dict(yaml.safe_load(fh))

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
