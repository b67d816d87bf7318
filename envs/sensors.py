"""Simulated sensors of the compass-gait robot and the decoder of their observation vector.

The paper's robot (Manchester et al. 2011, Section 5) carries two optical encoders: one measures
the angle between the legs (hip encoder ``alpha_A - alpha_B``), the other the absolute angle
``alpha_A`` of one physical leg (leg ``A``; the other leg is ``B``), and two foot contact switches
that tell the stance leg. Their geometry and its decoding into the paper's coordinates
(:func:`encoders_to_q`, :func:`q_to_encoders`, :func:`stance_from_contacts`) live in
:mod:`envs.physics.encoders`. A terrain scanner adds ``N`` ground heights
ahead of the stance foot.

Observation vector (``observation="sensors"``, float32), laid out by :class:`SensorLayout`:

====================  ======================================================================
index                 content
====================  ======================================================================
0                     hip encoder ``alpha_A - alpha_B`` [rad], quantised, noisy
1                     leg-A encoder ``alpha_A`` [rad], quantised, noisy
2                     contact switch of foot A (1.0 closed, 0.0 open)
3                     contact switch of foot B
4 .. 4+N-1            terrain scan: ground height [m] at ``x_s + offset + i * spacing``
                      (``x_s`` the stance foot's x), *relative to the stance foot's height*
                      (positive = higher than the stance foot), quantised, noisy, clipped to
                      ``[-scan_range, scan_range]``
====================  ======================================================================

Noise is Gaussian (ziggurat method), added before quantisation (so readings stay on the encoder
grid), drawn from a per-walker stream inside the compiled kernel; each stream is seeded from the
environment's ``np_random`` at every reset, so the same seed gives the same noise. An optional
latency delays the whole vector by a whole number of control periods (at a reset the delay line
is filled with the first reading).

Decoding: ``SensorLayout(N).decode(obs)`` (or :func:`decode`) returns named readings, the stance
leg inferred from the contact switches and ``q = (q1, q2)`` in paper coordinates.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numba import njit

from .config_util import dataclass_from_mapping
from .physics.encoders import encoders_to_q, stance_from_contacts
from .physics.terrain import terrain_height

# indices of the sensor observation (``observation="sensors"``)
HIP = 0
LEG_A = 1
CONTACT_A = 2
CONTACT_B = 3
SCAN = 4
N_FIXED = 4

# indices of the true-state observation (``observation="state"``)
STATE_Q1 = 0
STATE_Q2 = 1
STATE_Q1D = 2
STATE_Q2D = 3
STATE_STANCE_B = 4
STATE_SCAN = 5

#: the :class:`SensorConfig` fields of :meth:`SensorConfig.kernel_vector`, in order
KERNEL_FIELDS = ("encoder_resolution", "encoder_noise", "scan_noise", "scan_resolution",
                 "scan_range")  # fmt: skip
K_ENCODER_RESOLUTION = KERNEL_FIELDS.index("encoder_resolution")
K_ENCODER_NOISE = KERNEL_FIELDS.index("encoder_noise")
K_SCAN_NOISE = KERNEL_FIELDS.index("scan_noise")
K_SCAN_RESOLUTION = KERNEL_FIELDS.index("scan_resolution")
K_SCAN_RANGE = KERNEL_FIELDS.index("scan_range")

ANGLE_BOUND = math.pi  # encoders read in [-pi, pi]
VELOCITY_BOUND = 100.0  # state-observation joint rates are clipped to this [rad/s]


@dataclass(frozen=True)
class SensorConfig:
    """Settings of the simulated sensors.

    Attributes:
        encoder_resolution: encoder quantisation step [rad], >= 0 (0: no quantisation); the
            default is one count of a 4096-count encoder, ``2 pi / 4096``.
        encoder_noise: standard deviation of the Gaussian noise on each encoder [rad], >= 0.
        scan_count: number ``N`` of terrain heights, >= 0.
        scan_offset: distance of the first scan point ahead of the stance foot [m].
        scan_spacing: distance between scan points [m], > 0.
        scan_noise: standard deviation of the Gaussian noise on each height [m], >= 0.
        scan_resolution: quantisation step of the heights [m], >= 0 (0: none).
        scan_range: heights are clipped to ``[-scan_range, scan_range]`` [m], > 0.
        latency: delay of the whole observation in control periods, integer >= 0.
    """

    encoder_resolution: float = 2.0 * math.pi / 4096.0
    encoder_noise: float = 0.0
    scan_count: int = 10
    scan_offset: float = 0.05
    scan_spacing: float = 0.05
    scan_noise: float = 0.0
    scan_resolution: float = 0.0
    scan_range: float = 0.5
    latency: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ValueError(f"sensors.{f.name} must be a number, got {v!r}")
            if not math.isfinite(float(v)):
                raise ValueError(f"sensors.{f.name} must be finite, got {v!r}")
        for name in ("scan_count", "latency"):
            v = getattr(self, name)
            if int(v) != v or v < 0:
                raise ValueError(f"sensors.{name} = {v!r} out of range; allowed: integer >= 0")
            object.__setattr__(self, name, int(v))
        for name in ("encoder_resolution", "encoder_noise", "scan_noise", "scan_resolution"):
            v = float(getattr(self, name))
            if v < 0:
                raise ValueError(f"sensors.{name} = {v!r} out of range; allowed: >= 0")
            object.__setattr__(self, name, v)
        for name in ("scan_spacing", "scan_range"):
            v = float(getattr(self, name))
            if v <= 0:
                raise ValueError(f"sensors.{name} = {v!r} out of range; allowed: > 0")
            object.__setattr__(self, name, v)
        object.__setattr__(self, "scan_offset", float(self.scan_offset))

    @classmethod
    def from_dict(cls, d: dict[str, Any] | SensorConfig | None) -> SensorConfig:
        """Build from a dict ``d`` of the fields (unknown keys raise ``ValueError``); ``None``
        gives the defaults and a :class:`SensorConfig` is returned as it is."""
        if d is None:
            return cls()
        return dataclass_from_mapping(cls, d, "sensor")

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (YAML serialisable)."""
        return asdict(self)

    def replace(self, **changes: Any) -> SensorConfig:
        """Copy with some fields changed (validated)."""
        d = self.to_dict()
        d.update(changes)
        return SensorConfig.from_dict(d)

    @property
    def scan_offsets(self) -> np.ndarray:
        """x offsets [m] of the scan points from the stance foot."""
        return self.scan_offset + self.scan_spacing * np.arange(self.scan_count, dtype=np.float64)

    def kernel_vector(self) -> np.ndarray:
        """Flat float64 settings vector of :func:`measure_walker`: the :data:`KERNEL_FIELDS`
        (entry ``K_<FIELD>``)."""
        return np.array([getattr(self, name) for name in KERNEL_FIELDS])


@dataclass(frozen=True)
class SensorLayout:
    """Named slices of the sensor observation vector; build it with ``SensorLayout(scan_count)``.

    Use :meth:`decode` to turn an observation into named readings and paper coordinates.

    Args:
        scan_count: number of terrain-height readings in the observation.
        scan_offsets: x offsets [m] of the scan points from the stance foot (empty if unknown;
            :meth:`from_config` fills them in).
    """

    scan_count: int
    scan_offsets: tuple[float, ...] = ()

    hip = HIP
    leg_a = LEG_A
    contact_a = CONTACT_A
    contact_b = CONTACT_B

    @classmethod
    def from_config(cls, config: SensorConfig) -> SensorLayout:
        """The layout of the observations of sensors ``config``."""
        return cls(config.scan_count, tuple(float(v) for v in config.scan_offsets))

    @property
    def size(self) -> int:
        """Length of the observation vector."""
        return N_FIXED + self.scan_count

    @property
    def contacts(self) -> slice:
        """Slice of the two contact switches (``[A, B]``)."""
        return slice(CONTACT_A, CONTACT_B + 1)

    @property
    def scan(self) -> slice:
        """Slice of the terrain heights."""
        return slice(SCAN, SCAN + self.scan_count)

    def decode(self, obs: np.ndarray, previous_stance: int | None = None) -> dict[str, Any]:
        """Named readings of one observation (or a batch, leading axes kept).

        Args:
            obs: the observation, shape ``(..., size)``.
            previous_stance: stance leg (0 = A, 1 = B) kept when the contact switches do not
                name one (see :func:`stance_from_contacts`); None: leg A.

        Returns a dict with ``hip`` and ``leg_a`` (encoder angles [rad]), ``contacts`` (``[A, B]``),
        ``stance_leg`` (0 for leg A, 1 for leg B; see :func:`stance_from_contacts`), ``q``
        (``[..., 2]``: ``q1, q2`` in paper coordinates, from the encoders and the inferred
        stance leg) and ``scan`` (heights [m] relative to the stance foot at ``scan_offsets``).
        """
        o = np.asarray(obs, dtype=np.float64)
        if o.shape[-1] != self.size:
            raise ValueError(f"observation has {o.shape[-1]} entries; this layout has {self.size}")
        hip, leg_a = o[..., HIP], o[..., LEG_A]
        stance = stance_from_contacts(o[..., CONTACT_A], o[..., CONTACT_B], previous_stance)
        q1, q2 = encoders_to_q(hip, leg_a, stance)
        return {
            "hip": hip,
            "leg_a": leg_a,
            "contacts": o[..., self.contacts],
            "stance_leg": stance,
            "q": np.stack([q1, q2], axis=-1),
            "scan": o[..., self.scan],
            "scan_offsets": np.asarray(self.scan_offsets),
        }


def decode(
    obs: np.ndarray, layout: SensorLayout, previous_stance: int | None = None
) -> dict[str, Any]:
    """Named readings of a sensor observation: ``layout.decode(obs, previous_stance)``."""
    return layout.decode(obs, previous_stance)


# ---------------------------------------------------------------------------- noise streams
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@njit(cache=True)
def _next_u64(state, i):
    """splitmix64 step of stream ``i``."""
    z = state[i] + _GOLDEN
    state[i] = z
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@njit(cache=True)
def _uniform(state, i):
    """Uniform in [0, 1) with 53 random bits."""
    return float(_next_u64(state, i) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


def _ziggurat_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tables of the 128-layer ziggurat for the standard normal (Marsaglia and Tsang 2000)."""
    kn = np.zeros(128, dtype=np.int64)
    wn = np.zeros(128)
    fn = np.zeros(128)
    m1 = 2147483648.0
    dn = tn = 3.442619855899
    vn = 9.91256303526217e-3
    q = vn / math.exp(-0.5 * dn * dn)
    kn[0] = int((dn / q) * m1)
    kn[1] = 0
    wn[0] = q / m1
    wn[127] = dn / m1
    fn[0] = 1.0
    fn[127] = math.exp(-0.5 * dn * dn)
    for i in range(126, 0, -1):
        dn = math.sqrt(-2.0 * math.log(vn / dn + math.exp(-0.5 * dn * dn)))
        kn[i + 1] = int((dn / tn) * m1)
        tn = dn
        fn[i] = math.exp(-0.5 * dn * dn)
        wn[i] = dn / m1
    return kn, wn, fn


_ZKN, _ZWN, _ZFN = _ziggurat_tables()
_ZR = 3.442619855899  # start of the tail


@njit(cache=True)
def _normal(state, i):
    """Standard normal from stream ``i`` (ziggurat; layer from the low 7 bits of a 64-bit draw,
    the signed abscissa from its high 32 bits, so the two are independent)."""
    while True:
        u = _next_u64(state, i)
        iz = np.int64(u & np.uint64(127))
        hz = np.int64(np.int32(np.uint32(u >> np.uint64(32))))
        if abs(hz) < _ZKN[iz]:
            return hz * _ZWN[iz]
        x = hz * _ZWN[iz]
        if iz == 0:
            # the tail beyond _ZR (Marsaglia's method)
            while True:
                xt = -math.log(1.0 - _uniform(state, i)) / _ZR
                yt = -math.log(1.0 - _uniform(state, i))
                if yt + yt >= xt * xt:
                    break
            return _ZR + xt if hz > 0 else -_ZR - xt
        if _ZFN[iz] + _uniform(state, i) * (_ZFN[iz - 1] - _ZFN[iz]) < math.exp(-0.5 * x * x):
            return x


@njit(cache=True)
def standard_normal(state, i, out):
    """Fill ``out`` with standard normals from stream ``i`` (for tests of the noise model)."""
    for k in range(out.size):
        out[k] = _normal(state, i)


def seed_streams(rng: np.random.Generator, count: int = 1) -> np.ndarray:
    """``count`` stream states drawn from a NumPy generator (the env's ``np_random``)."""
    return rng.integers(0, 2**63, size=count, dtype=np.int64).astype(np.uint64)


# ---------------------------------------------------------------------------- measurement
@njit(cache=True)
def _quantise(x, res):
    if res > 0.0:
        return res * np.rint(x / res)
    return x


@njit(cache=True)
def _clip(x, bound):
    if x > bound:
        return bound
    if x < -bound:
        return -bound
    return x


@njit(cache=True)
def scan_walker(i, xs, ys, tx, ty, tn, offsets, scan):
    """Exact terrain heights ahead of walker ``i``'s stance foot into ``scan[i]`` [m].

    ``scan[i, k] = h(xs + offsets[k]) - ys``; they change only when the stance foot moves (at
    an impact or a reset), so the environments recompute them only then.
    """
    if offsets.size == 0:
        return
    txi, tyi, m = tx[i], ty[i], tn[i]
    for k in range(offsets.size):
        scan[i, k] = terrain_height(txi, tyi, m, xs + offsets[k]) - ys


@njit(cache=True)
def measure_walker(i, q1, q2, leg, settings, scan, streams, obs):
    """Sensor readings of walker ``i`` written into ``obs[i]`` (float32 row of ``4 + N``).

    Args:
        i: walker index (row of ``scan`` and ``obs``; noise stream ``streams[i]``, advanced in
            place).
        q1, q2: joint angles [rad] (paper coordinates).
        leg: physical stance leg, 0 = A, 1 = B.
        settings: :meth:`SensorConfig.kernel_vector`.
        scan: ``(n, N)`` exact terrain heights relative to the stance foot (:func:`scan_walker`).
        obs: ``(n, 4 + N)`` float32 output.
    """
    enc_res, enc_noise = settings[K_ENCODER_RESOLUTION], settings[K_ENCODER_NOISE]
    scan_noise, scan_res = settings[K_SCAN_NOISE], settings[K_SCAN_RESOLUTION]
    scan_range = settings[K_SCAN_RANGE]
    if leg == 1:
        hip, leg_a = -q1, q2 - q1
    else:
        hip, leg_a = q1, q2
    if enc_noise > 0.0:
        hip += enc_noise * _normal(streams, i)
        leg_a += enc_noise * _normal(streams, i)
    obs[i, HIP] = _clip(_quantise(hip, enc_res), math.pi)
    obs[i, LEG_A] = _clip(_quantise(leg_a, enc_res), math.pi)
    obs[i, CONTACT_A] = 1.0 if leg == 0 else 0.0
    obs[i, CONTACT_B] = 1.0 if leg == 1 else 0.0
    for k in range(scan.shape[1]):
        h = scan[i, k]
        if scan_noise > 0.0:
            h += scan_noise * _normal(streams, i)
        obs[i, SCAN + k] = _clip(_quantise(h, scan_res), scan_range)


@njit(cache=True)
def state_walker(i, q1, q2, q1d, q2d, leg, scan, scan_range, obs):
    """Privileged observation of walker ``i`` into ``obs[i]`` (float32 row of ``5 + N``).

    Layout: ``q1, q2`` [rad], ``q1dot, q2dot`` [rad/s] (clipped to +-VELOCITY_BOUND), stance
    flag (1.0 when leg B is the stance leg), then the ``N`` exact terrain heights relative to
    the stance foot at the scan offsets (clipped to +-scan_range).
    """
    obs[i, STATE_Q1] = _clip(q1, math.pi)
    obs[i, STATE_Q2] = _clip(q2, math.pi)
    obs[i, STATE_Q1D] = _clip(q1d, VELOCITY_BOUND)
    obs[i, STATE_Q2D] = _clip(q2d, VELOCITY_BOUND)
    obs[i, STATE_STANCE_B] = 1.0 if leg == 1 else 0.0
    for k in range(scan.shape[1]):
        obs[i, STATE_SCAN + k] = _clip(scan[i, k], scan_range)


def observation_bounds(config: SensorConfig, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Finite ``(low, high)`` float32 bounds of the observation vector for ``mode``."""
    n = config.scan_count
    r = config.scan_range
    if mode == "sensors":
        high = np.array([ANGLE_BOUND, ANGLE_BOUND, 1.0, 1.0] + [r] * n, dtype=np.float32)
        low = -high
        low[CONTACT_A] = low[CONTACT_B] = 0.0
    elif mode == "state":
        high = np.array(
            [ANGLE_BOUND, ANGLE_BOUND, VELOCITY_BOUND, VELOCITY_BOUND, 1.0] + [r] * n,
            dtype=np.float32,
        )
        low = -high
        low[STATE_STANCE_B] = 0.0
    else:
        raise ValueError(f"observation = {mode!r}; allowed: 'sensors', 'state'")
    return low, high
