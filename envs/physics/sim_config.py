"""Settings of the hybrid simulator, :class:`SimConfig` (substep, fall limits, friction, event
tolerances and checks), as the compiled kernel reads them (:meth:`SimConfig.vector`, the ``C_*``
layout of :mod:`envs.physics.kernel`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from ..config_util import reject_moved_fields
from .kernel import C_FACE, C_FALL_H, C_IMPACT, C_MU, C_Q2MAX, C_REACT, C_SUBSTEP, C_TTOL, N_C
from .params import DEFAULT_SUBSTEP, MOVED_TO_ROBOT


@dataclass(frozen=True)
class SimConfig:
    """Simulator settings.

    Attributes:
        substep: largest RK4 substep [s], in (0, 0.1]; each control period ``dt`` is split
            into ``ceil(dt / substep)`` equal substeps. A substep longer than the default
            2.5 ms lowers the largest hip viscous friction the simulator accepts
            (:meth:`RobotParams.viscous_friction_limit`).
        fall_height: hip height above the ground below which the walker has fallen, fraction
            of ``l``, in [0, 1).
        q2_limit: largest ``|q2|`` [rad] before the walker has fallen, in (0, pi/2].
        mu: friction coefficient of the feet (``inf`` disables slip checks), > 0.
        time_tol: touchdown time tolerance [s] of the root finder, in (0, 1e-9].
        face_tol: clearance jump [m] that marks a foot hitting a vertical face, > 0.
        check_reaction: check lift-off and slip of the stance foot during the swing phase.
        check_impact: check the impact impulse and the trailing foot's take-off.
        max_impacts: most impacts recorded within one control period; more is "stuck".

    The foot geometry (``retract``, ``arm_distance``) is the robot's: :class:`RobotParams`.
    """

    MOVED_FIELDS: ClassVar[dict[str, str]] = {
        key: MOVED_TO_ROBOT.format(key=key) for key in ("retract", "arm_distance")
    }

    substep: float = DEFAULT_SUBSTEP
    fall_height: float = 0.5
    q2_limit: float = 1.2
    mu: float = 1.0
    time_tol: float = 1e-13
    face_tol: float = 1e-8
    check_reaction: bool = True
    check_impact: bool = True
    max_impacts: int = 4

    def __new__(cls, *args: Any, **kwargs: Any) -> SimConfig:
        """Reject the settings that moved to :class:`RobotParams`, naming the replacement."""
        reject_moved_fields(cls, kwargs)
        return super().__new__(cls)

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
        c[C_SUBSTEP] = self.substep
        c[C_FALL_H], c[C_Q2MAX], c[C_MU] = self.fall_height, self.q2_limit, self.mu
        c[C_TTOL], c[C_FACE] = self.time_tol, self.face_tol
        c[C_REACT], c[C_IMPACT] = float(self.check_reaction), float(self.check_impact)
        return c
