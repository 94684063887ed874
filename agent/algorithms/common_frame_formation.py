"""De Carli, Restrepo and Robuffo Giordano (IEEE L-CSS 2024): cooperative localization in a
common frame from body-frame relative positions, feeding formation control.

Four parts, each at its own rate on the agent's clock (the paper's §IV rates):

* ``relative`` (200 Hz): the adaptive relative-state observer (7) on every edge (i, j)
  robot i senses; (8) when j senses i too.  (8) is one system per bidirectional edge
  (p̂_ij, p̂_ji, one ẑ_ψij): the robot with the smaller id runs all of it, with j's
  measurement ʲp_ji received on the edge, and sends ẑ_ψij; the other takes
  ẑ_ψji = Z ẑ_ψij.  Two copies of ẑ, one per robot, each fed the other's error
  ʲe_pji held over a step, drift apart: their difference is a neutral mode of (8)
  (ḋ = Ω d) that the held errors drive unstable at k_ψ|v|²dt ≈ 2 (measured: 0.4 apart
  at t = 0, 11 at 18 s); exchanging errors with one owner still leaves a loop through
  the network (residual 0.02–0.05 against 2e-3 for (7) alone);
* ``yaw`` (100 Hz): the common-frame yaw observer (13) over the communication
  neighbours, with z_ij from the renormalised ẑ_ψij (Remark 3) — i's own when it senses j,
  else the conjugate of the one j sends (Remark 4);
* ``position`` (50 Hz): the common-frame position observer (21), R̂_i = R_z(∠ẑ_i);
* ``control`` (every agent step): the formation law (30) with the saturation k_i
  (ν_max), its second sum turned into i's frame (planar_localization_terms), and the
  yaw rate from a smooth random spline (seeded per robot), as in §IV.

The commands go to the world's kinematic plant (1) on cmd/<i>: ``vel`` (body frame) and
``yaw_rate``.  The observers use the measured own velocity (sensor ``velocity_body``)
and yaw rate (gyro, e3 component): what the vehicle does, not what it was told.

Choices the paper leaves open (stated in the README too): unless the scenario states them
(``[agents.estimate] p``, ``yaw`` = ψ̂_i(0), and ``[[agents]] yaw_rate`` = the spline's
knots, so that an independent integration can start from the same state),
p̂_i(0) = p_i(0) + N(0, σ² I) with σ = ``p0_std`` (1 m) and ẑ_i(0) = e^{ιθ}, θ uniform on
(−π, π], both drawn from the run's seed and the robot's id, so robot i can re-draw a neighbour's ẑ_j(0) and start
ẑ_ψij(0) = z̄̂_i(0) ẑ_j(0), consistent around every cycle; ⁱp̂_ij(0) is the first
measurement ⁱp_ij (e_p = 0: only ẑ_ψij has to be learned).  The yaw spline: knots every
``yaw_knot`` s with values uniform in ±``yaw_rate_max``, joined by a C¹ cubic
(Catmull–Rom).

Symbols -> names: see planar_localization_terms; p*_i ``p_star[i]`` ([algorithm.params]).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from agent.algorithms import planar_localization_terms as pl
from zswarm.math.limits import MAX_ABS
from zswarm.scenario.algorithm import AlgorithmSpec, Field, Initial, InitialField, Part, Publish, Reader, StalePolicy, View

EDGE_OUT = {
    "vel": Field((3,), doc="v_i, body frame (m/s): V̄_i for the neighbour's (7)"),
    "yaw_rate": Field((), doc="ω_i (rad/s): Ω_ij"),
    "zc": Field((2,), doc="ẑ_i = [Re, Im] (13)"),
    "p_hat": Field((3,), doc="p̂_i (21)"),
    "p_meas": Field((3,), optional=True, doc="ⁱp_ij when i senses the receiver j: (21)/(30)'s in-terms there"),
    "z_rel": Field((2,), optional=True, doc="ẑ_ψij when i senses j: z_ji at j (Remark 4)"),
    "vel_next": Field((3,), optional=True, doc="the command just sent: v_i from this tick on (vel is v_i up to it)"),
    "yaw_rate_next": Field((), optional=True, doc="the same for ω_i"),
}


@dataclass(frozen=True, slots=True)
class Gains:
    k_pe: float
    k_psi: float
    k_z: float
    k_p: float
    k_c: float
    nu_max: float
    p0_std: float
    yaw_rate_max: float
    yaw_knot: float
    p_star: Mapping[int, np.ndarray]


@dataclass(frozen=True, slots=True)
class State:
    id: int
    seed: int
    p_rel: Mapping[int, np.ndarray]  # ⁱp̂_ij of the edges i senses
    z_rel: Mapping[int, np.ndarray]  # ẑ_ψij of the edges i senses (2-vectors, not renormalised)
    zc: complex  # ẑ_i
    p_hat: np.ndarray  # p̂_i
    yaw_knots: np.ndarray  # ω at t = 0, yaw_knot, 2 yaw_knot, ...
    e_p: Mapping[int, np.ndarray] = field(default_factory=dict)  # ⁱe_pij after the last relative step
    p_rev: Mapping[int, np.ndarray] = field(default_factory=dict)  # ʲp̂_ji of the bidirectional edges this robot runs (8) for
    prev: Mapping[Any, Any] = field(default_factory=dict)  # the last relative step's measurements ⁱp_ij, ʲp_ji
    t_yaw: float = 0.0  # agent-clock time of the last yaw step (ẑ_i is as of then)
    t_pos: float = 0.0  # ... and of the last position step (p̂_i)
    v_cmd: np.ndarray = field(default_factory=lambda: np.zeros(3))
    w_cmd: float = 0.0
    yaw0: Mapping[int, float] = field(default_factory=dict)  # ψ̂_j(0) the scenario states (a neighbour's, to start ẑ_ψij)


@dataclass(frozen=True, slots=True)
class Outputs:
    v: np.ndarray
    w: float
    mu: np.ndarray


def _draw(seed: int, i: int) -> tuple[float, np.ndarray]:
    """Robot i's initial yaw-estimate angle and position-estimate noise (unit std)."""
    rng = np.random.default_rng([seed % (1 << 63), i, 0xDC])
    theta = math.pi - 2.0 * math.pi * float(rng.random())  # uniform on (−π, π]
    return theta, rng.normal(size=3)


@dataclass(frozen=True, slots=True)
class FormationParams:
    """[algorithm.params] of (30): the desired offsets p*_i, one per robot in the agents' order."""

    p_star: tuple[tuple[float, float, float], ...]
    jumps: ClassVar[bool] = False

    @classmethod
    def load(cls, r: Reader, d: Any, fld: str) -> FormationParams:
        d = r.table(d if d is not None else {}, fld, {"p_star"}, {"p_star"})
        ps = d["p_star"]
        if not isinstance(ps, list) or not ps:
            raise r.err(f"{fld}.p_star", "must be a list of desired offsets [x, y, z] (m), one per agent in the agents' order", ps)
        return cls(tuple(r.vec3(x, f"{fld}.p_star[{n}]") for n, x in enumerate(ps)))

    def check_agents(self, r: Reader, fld: str, ids: tuple[int, ...]) -> None:
        if len(self.p_star) != len(ids):
            raise r.err(f"{fld}.p_star", f"lists {len(self.p_star)} offsets for {len(ids)} agents (one per agent, in the agents' order)")

    def gains(self, ids: tuple[int, ...]) -> dict[str, Any]:
        return {"p_star": {i: np.array(self.p_star[n]) for n, i in enumerate(ids)}}


# A robot's yaw-rate spline knots (its ω_i at 0, yaw_knot, 2·yaw_knot, ...) when stated:
# at most this many (the drawn spline has 4096), each within the wire's ±MAX_ABS.
MAX_YAW_KNOTS = 4096


def _knots(r: Reader, v: Any, fld: str) -> tuple[float, ...]:
    if not isinstance(v, list) or not 1 <= len(v) <= MAX_YAW_KNOTS:
        raise r.err(fld, f"must be a list of 1 to {MAX_YAW_KNOTS} yaw rates (rad/s), the spline's knots at 0, yaw_knot, 2 yaw_knot, ...", v)
    return tuple(r.num(x, f"{fld}[{n}]", maxv=MAX_ABS, minv=-MAX_ABS) for n, x in enumerate(v))


# What a robot can be given instead of drawing it from the seed (De Carli et al. §IV draws them).
INITIAL = {
    "p": InitialField("vector", (0.0, 0.0, 0.0), "p̂_i(0) (else p_i(0) + p0_std·n, n drawn from the seed)"),
    "yaw": InitialField("angle", None, "ψ̂_i(0), the angle of ẑ_i(0) (else drawn from the seed)"),
    "yaw_rate": InitialField("custom", None, "[[agents]] yaw_rate: the yaw-rate spline's knots (rad/s)", table="agent", parse=_knots),
}


def initial_state(init: Initial, gains: Gains) -> State:
    """p̂_i(0), ẑ_i(0) and the yaw-rate knots as the scenario states them, else drawn from the
    seed (see the module docstring); a stated knot list holds its last value past its end."""
    yaw0 = {j: float(v["yaw"]) for j, v in init.others.items() if "yaw" in v}
    theta, n = _initial_yaw(init.seed, init.id, yaw0)
    p_hat = np.asarray(init.p_hat if "p" in init.stated else np.asarray(init.p0, dtype=float) + gains.p0_std * n, dtype=float)
    if init.values.get("yaw_rate") is not None:
        knots = np.asarray(init.values["yaw_rate"], dtype=float)
        knots = np.concatenate([knots, np.full(3, knots[-1])])  # the spline reads two knots ahead
    else:
        rng = np.random.default_rng([init.seed % (1 << 63), init.id, 0x5B])
        knots = rng.uniform(-gains.yaw_rate_max, gains.yaw_rate_max, size=4096)
        knots[0] = 0.0  # start at rest in yaw, like the vehicle
    return State(init.id, init.seed, {}, {}, complex(math.cos(theta), math.sin(theta)), p_hat, knots, yaw0=yaw0)


def _initial_yaw(seed: int, i: int, stated: Mapping[int, float]) -> tuple[float, np.ndarray]:
    """Robot i's ψ̂_i(0) (stated, else drawn) and its position-estimate noise draw."""
    theta, n = _draw(seed, i)
    return stated.get(i, theta), n


def yaw_rate(state: State, t: float, gains: Gains) -> float:
    """The C¹ Catmull–Rom spline through the knots at multiples of ``yaw_knot``; past the
    last knot (8190 s at the default 2 s) the rate holds that knot's value."""
    h = gains.yaw_knot
    y = state.yaw_knots
    k = int(max(t, 0.0) / h)
    if k > len(y) - 3:
        return float(y[-2])
    s = max(t, 0.0) / h - k
    p0, p1, p2, p3 = y[max(k - 1, 0)], y[k], y[k + 1], y[k + 2]
    return float(0.5 * ((2 * p1) + (-p0 + p2) * s + (2 * p0 - 5 * p1 + 4 * p2 - p3) * s**2 + (-p0 + 3 * p1 - 3 * p2 + p3) * s**3))


def _turn(z: np.ndarray, angle: float) -> np.ndarray:
    """A unit-complex estimate [Re, Im] turned by ``angle`` (what a relative yaw ψ_ji does at
    ω_i − ω_j while a message carrying it travels)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * z[0] - s * z[1], s * z[0] + c * z[1]])


def _nbr_motion(f: Mapping[str, Any], a: float, period: float) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Neighbour j's body velocity and yaw rate from its message ``a`` old: (their means over
    the step just elapsed, (t − period, t]; their values since the message, (t − a, t]).

    On the kinematic plant (1) a robot moves at its command, held: ``vel`` is what it moved
    at up to its message (measured then), ``vel_next`` the command it sent with it, in force
    from then on.  A message from this very tick (a ≈ 0) describes the step with ``vel``;
    one from the previous tick (a ≈ period) with ``vel_next``.  Using ``vel`` for both lags
    half the edges by a step: relative-yaw floors of 3–8e-3 there, 1e-6 on the others."""
    v, w = np.asarray(f["vel"], dtype=float), float(f["yaw_rate"])
    if f.get("vel_next") is None:
        return v, w, v, w
    vn, wn = np.asarray(f["vel_next"], dtype=float), float(f["yaw_rate_next"])
    k = min(a / period, 1.0) if period > 0.0 else 1.0
    return v + k * (vn - v), w + k * (wn - w), vn, wn


def _own(view: View) -> tuple[np.ndarray, float]:
    s = view.sense
    v = np.asarray(s.get("velocity_body", np.zeros(3)), dtype=float)
    g = s.get("gyro")
    return v, float(g[2]) if g is not None else 0.0


# --------------------------------------------------------------------------- (7)/(8), 200 Hz


@dataclass(frozen=True, slots=True)
class RelInputs:
    v_i: np.ndarray
    w_i: float
    # (j, ⁱp_ij, v_j, ω_j over the step, ʲp_ji when i runs (8) for the edge, ẑ_ψji as sent by j
    # when j does, the age a of j's message, v_j and ω_j since it)
    edges: tuple[tuple[int, np.ndarray, np.ndarray, float, np.ndarray | None, np.ndarray | None, float, np.ndarray, float], ...]


def relative_inputs(view: View, gains: Gains) -> RelInputs:
    v_i, w_i = _own(view)
    meas = view.sense.get("rel_pos", {})
    edges = []
    for j in view.senses:
        p_ij = meas.get(j)
        m = view.neighbor(j)
        if p_ij is None or m is None:
            continue  # no measurement or nothing heard from j yet: (7) needs v_j, ω_j
        f = m.fields
        both = f.get("p_meas") is not None  # j senses i too: (8), run by the smaller id
        p_ji = np.asarray(f["p_meas"], dtype=float) if both and view.id < j else None
        a = max(m.age, 0.0)
        v_j, w_j, v_a, w_a = _nbr_motion(f, a, view.period)
        z_ji = _turn(np.asarray(f["z_rel"], dtype=float), (w_i - w_a) * a) if both and j < view.id and f.get("z_rel") is not None else None
        edges.append((j, np.asarray(p_ij, dtype=float), v_j, w_j, p_ji, z_ji, a, v_a, w_a))
    return RelInputs(v_i, w_i, tuple(edges))


def relative_step(state: State, inputs: RelInputs, dt: float, gains: Gains) -> tuple[State, None]:
    """(7) per sensed edge, (8) for the bidirectional edges this robot runs; RK4 from the last
    step to this one (t) with the measurements ⁱp_ij (and ʲp_ji) linear between the two
    steps' values (second order in dt for the smooth relative positions, where holding them
    is first order), and the velocities held over the step: the robot's own at its value
    measured at t (on the kinematic plant (1) a body velocity is a command held from its
    arrival, which follows the previous measurement by the command's transit, so the value
    measured at t is the one in force over nearly the whole step; interpolating it instead
    was measured 4× worse), the neighbour's as _nbr_motion reads it from j's message."""
    p_rel, p_rev, z_rel, e_out = dict(state.p_rel), dict(state.p_rev), dict(state.z_rel), {}
    prev = dict(state.prev)
    k_pe, k_psi = gains.k_pe, gains.k_psi
    v_i, w_i = inputs.v_i, inputs.w_i
    for j, p_ij, v_j, w_j, p_ji, z_from_j, age, v_a, w_a in inputs.edges:
        if z_from_j is not None:  # j runs (8) for this edge: ẑ_ψij = Z ẑ_ψji
            z_rel[j] = pl.Z @ z_from_j
            p_rel.pop(j, None)
            continue
        if j not in p_rel:  # first measurement of edge (i, j): stated initialisation
            p_rel[j] = p_ij.copy()
            if j not in z_rel:
                theta_j, _ = _initial_yaw(state.seed, j, state.yaw0)
                z_ij = state.zc.conjugate() * complex(math.cos(theta_j), math.sin(theta_j)) / abs(state.zc)
                z_rel[j] = np.array([z_ij.real, z_ij.imag])
        q0 = prev.get(("p", j), p_ij)
        prev[("p", j)] = p_ij
        if p_ji is None:
            x = np.concatenate([p_rel[j], z_rel[j]])

            def f(s: float, x: np.ndarray, q0: np.ndarray = q0, p_ij: np.ndarray = p_ij, v_j: np.ndarray = v_j, w_j: float = w_j) -> np.ndarray:
                dp, dz = pl.relative_state_rates(x[:3], x[3:], q0 + s * (p_ij - q0), v_i, w_i, v_j, w_j, k_pe, k_psi)
                return np.concatenate([dp, dz])

        else:  # (8): x = [ⁱp̂_ij, ʲp̂_ji, ẑ_ψij]
            # ʲp_ji was measured ``age`` before t: brought to t along (1),
            # ʲṗ_ji = −ω_j e3 × ʲp_ji − v_j + R_z(ψ_ji) v_i with R_z(ψ_ji) = R_z(ψ̂_ij)ᵀ (first
            # order in the age; left as measured, it misleads (8) by |ʲṗ_ji|·a — measured over
            # Zenoh: edge 3–7 stuck at 0.055 while every (7) edge was below 0.007)
            zr = z_rel[j]
            c, sn = float(zr[0]) / max(float(np.hypot(zr[0], zr[1])), 1e-12), float(zr[1]) / max(float(np.hypot(zr[0], zr[1])), 1e-12)
            v_i_in_j = np.array([c * v_i[0] + sn * v_i[1], -sn * v_i[0] + c * v_i[1], v_i[2]])
            p_ji = p_ji + age * (np.array([w_a * p_ji[1], -w_a * p_ji[0], 0.0]) - v_a + v_i_in_j)
            if j not in p_rev:
                p_rev[j] = p_ji.copy()
            r0 = prev.get(("r", j), p_ji)
            prev[("r", j)] = p_ji
            x = np.concatenate([p_rel[j], p_rev[j], z_rel[j]])

            def f(s: float, x: np.ndarray, q0: np.ndarray = q0, p_ij: np.ndarray = p_ij, v_j: np.ndarray = v_j, w_j: float = w_j, r0: np.ndarray = r0, p_ji: np.ndarray = p_ji) -> np.ndarray:
                pji = r0 + s * (p_ji - r0)
                dp_ji, _ = pl.relative_state_rates(x[3:6], pl.Z @ x[6:], pji, v_j, w_j, v_i, w_i, k_pe, k_psi)
                dp, dz = pl.relative_state_rates(x[:3], x[6:], q0 + s * (p_ij - q0), v_i, w_i, v_j, w_j, k_pe, k_psi, (x[3:6] - pji, v_i))
                return np.concatenate([dp, dp_ji, dz])

        k1 = f(0.0, x)
        k2 = f(0.5, x + 0.5 * dt * k1)
        k3 = f(0.5, x + 0.5 * dt * k2)
        k4 = f(1.0, x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        p_rel[j], z_rel[j] = x[:3], x[-2:]
        if p_ji is not None:
            p_rev[j] = x[3:6]
        e_out[j] = x[:3] - p_ij
    return replace(state, p_rel=p_rel, p_rev=p_rev, z_rel=z_rel, e_p=e_out, prev=prev), None


# --------------------------------------------------------------------------- (13), 100 Hz


@dataclass(frozen=True, slots=True)
class YawInputs:
    t: float
    w_i: float
    nbrs: tuple[tuple[int, complex, np.ndarray | None], ...]  # (j, ẑ_j, ẑ_ψji when j senses i)


def yaw_inputs(view: View, gains: Gains) -> YawInputs:
    _, w_i = _own(view)
    nbrs = []
    for j in view.neighbors:
        m = view.neighbor(j)
        if m is None:
            continue
        z_ji = m.fields.get("z_rel")
        a = max(m.age, 0.0)
        _, _, _, w_j = _nbr_motion(m.fields, a, view.period)
        # ẑ_j brought to this step: it turned by ω_j (its own term of (13)) since it was sent;
        # so did ẑ_ψji, by ω_i − ω_j.  Left as sent, i's term z̄_ij ẑ_j and j's own copy of the
        # edge disagree by (ω_i − ω_j)·a: (13)'s coupling is then no longer Hermitian and turns
        # the common rotation α (measured: 0.2 rad over 40 s, 0.035 rad/s at its fastest).
        zc_j = complex(*np.asarray(m.fields["zc"], dtype=float)) * cmath.exp(1j * w_j * a)
        nbrs.append((j, zc_j, None if z_ji is None else _turn(np.asarray(z_ji, dtype=float), (w_i - w_j) * a)))
    return YawInputs(view.t, w_i, tuple(nbrs))


def yaw_step(state: State, inputs: YawInputs, dt: float, gains: Gains) -> tuple[State, None]:
    terms = []
    for j, zc_j, z_ji in inputs.nbrs:
        if j in state.z_rel:
            terms.append((pl.relative_yaw(state.z_rel[j]), zc_j))  # i's own estimate of edge (i, j)
        elif z_ji is not None:
            terms.append((pl.relative_yaw(z_ji).conjugate(), zc_j))  # z_ij = z̄_ji (Remark 4)
    return replace(state, zc=pl.common_yaw_step(state.zc, inputs.w_i, terms, gains.k_z, dt), t_yaw=inputs.t), None


# --------------------------------------------------------------------------- (21), 50 Hz


@dataclass(frozen=True, slots=True)
class PosInputs:
    t: float
    v_i: np.ndarray
    w_i: float
    out_terms: tuple[tuple[np.ndarray, np.ndarray], ...]  # (p̂_j, ⁱp_ij)
    in_terms: tuple[tuple[np.ndarray, np.ndarray, np.ndarray, float], ...]  # (p̂_j, R̂_j, ʲp_ji, age)


def _rz(zc: complex) -> np.ndarray:
    return pl.Rz(math.atan2(zc.imag, zc.real))


def position_inputs(view: View, gains: Gains) -> PosInputs:
    """(21)'s terms at this step's time t.  A neighbour's message is ``a`` old: its
    out-term estimate of p_j is brought to t by j's own drift, p̂_j + a R̂_j v_j; its
    in-term p̂_j + R̂_j ʲp_ji estimates p_i as of t − a and is brought to t by i's own
    motion, + a R̂_i v_i (position_step).  Taking either as of t leaves a bias of
    a·|v| (5–10 ms at 0.5–1 m/s: 5 mm per term)."""
    v_i, w_i = _own(view)
    meas = view.sense.get("rel_pos", {})
    out_t, in_t = [], []
    for j in view.neighbors:
        m = view.neighbor(j)
        if m is None:
            continue
        f = m.fields
        zc_j = complex(*np.asarray(f["zc"], dtype=float))
        R_j, p_hat_j, a = _rz(zc_j), np.asarray(f["p_hat"], dtype=float), max(m.age, 0.0)
        if j in view.senses and meas.get(j) is not None:
            out_t.append((p_hat_j + a * (R_j @ _nbr_motion(f, a, view.period)[2]), np.asarray(meas[j], dtype=float)))
        if f.get("p_meas") is not None:  # j senses i
            in_t.append((p_hat_j, R_j, np.asarray(f["p_meas"], dtype=float), a))
    return PosInputs(view.t, v_i, w_i, tuple(out_t), tuple(in_t))


def position_step(state: State, inputs: PosInputs, dt: float, gains: Gains) -> tuple[State, None]:
    w = inputs.w_i * (inputs.t - state.t_yaw)  # R̂_i at t: (13)'s own term since the yaw part's last step
    R_i = _rz(state.zc * complex(math.cos(w), math.sin(w)))
    own = R_i @ inputs.v_i
    in_terms = [(p_hat_j + a * own, R_j, p_ji) for p_hat_j, R_j, p_ji, a in inputs.in_terms]
    p = pl.position_step(state.p_hat, R_i, inputs.v_i, list(inputs.out_terms), in_terms, gains.k_p, dt, inputs.w_i)
    return replace(state, p_hat=p, t_pos=inputs.t), None


# --------------------------------------------------------------------------- (30), every step


@dataclass(frozen=True, slots=True)
class CtrlInputs:
    t: float
    out_terms: tuple[tuple[int, np.ndarray], ...]  # (j, ⁱp_ij)
    in_terms: tuple[tuple[int, complex, np.ndarray], ...]  # (j, ẑ_j, ʲp_ji)


def control_inputs(view: View, gains: Gains) -> CtrlInputs:
    meas = view.sense.get("rel_pos", {})
    out_t = tuple((j, np.asarray(meas[j], dtype=float)) for j in view.senses if meas.get(j) is not None)
    in_t = []
    for j in view.neighbors:
        m = view.neighbor(j)
        if m is not None and m.fields.get("p_meas") is not None:
            in_t.append((j, complex(*np.asarray(m.fields["zc"], dtype=float)), np.asarray(m.fields["p_meas"], dtype=float)))
    return CtrlInputs(view.t, out_t, tuple(in_t))


def control_step(state: State, inputs: CtrlInputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    ps = gains.p_star
    me = ps[state.id]
    v, mu = pl.formation_velocity(
        _rz(state.zc),
        me,
        [(ps[j], p_ij) for j, p_ij in inputs.out_terms],
        [(ps[j], _rz(zc_j), p_ji) for j, zc_j, p_ji in inputs.in_terms],
        gains.k_c,
        gains.nu_max,
    )
    w = yaw_rate(state, inputs.t, gains)
    return replace(state, v_cmd=v, w_cmd=w), Outputs(v, w, mu)


# --------------------------------------------------------------------------- publishing


def current(state: State, view: View) -> tuple[complex, np.ndarray]:
    """ẑ_i and p̂_i brought from their parts' last steps (100 Hz, 50 Hz) to this step with the
    observers' own-motion terms, ι ω_i ẑ_i of (13) and R̂_i v_i of (21): what a neighbour and
    the recorder get at 200 Hz (without it p̂_i would be up to 20 ms old, 1 cm at 0.5 m/s)."""
    v_i, w_i = _own(view)
    zc = state.zc * complex(math.cos(w_i * (view.t - state.t_yaw)), math.sin(w_i * (view.t - state.t_yaw)))
    return zc, state.p_hat + (view.t - state.t_pos) * (_rz(zc) @ v_i)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    v_i, w_i = _own(view)
    zcc, p_hat = current(state, view)
    zc = np.array([zcc.real, zcc.imag])
    meas = view.sense.get("rel_pos", {})
    edges: dict[int, dict[str, Any]] = {}
    for j in view.out_neighbors:
        e: dict[str, Any] = {"vel": v_i, "yaw_rate": w_i, "zc": zc, "p_hat": p_hat}
        if j in state.z_rel and meas.get(j) is not None:
            e.update(p_meas=np.asarray(meas[j], dtype=float), z_rel=state.z_rel[j])
        edges[j] = e
    est: dict[str, Any] = {"R_hat": _rz(zcc), "p_hat": p_hat, "zc": zc}
    for j, z in state.z_rel.items():
        est[f"z_rel_{j}"] = z
    command = None
    if outputs is not None:
        est.update(v_cmd=outputs.v, w_cmd=outputs.w, mu=outputs.mu)
        command = {"vel": outputs.v, "yaw_rate": outputs.w}
        for e in edges.values():
            e.update(vel_next=outputs.v, yaw_rate_next=outputs.w)
    return Publish(edges, est, command)


COMMAND = {"vel": Field((3,), doc="v_i, body frame (m/s), De Carli (1)"), "yaw_rate": Field((), doc="ω_i (rad/s)")}

SPEC = AlgorithmSpec(
    description="De Carli et al. (7)/(8), (13), (21) at 200/100/50 Hz and formation control (30)",
    gains={
        "k_pe": 20.0,
        "k_psi": 600.0,
        "k_z": 40.0,
        "k_p": 1.0,
        "k_c": 0.5,
        "nu_max": 1.0,
        "p0_std": 1.0,
        "yaw_rate_max": 0.5,
        "yaw_knot": 2.0,
    },
    sensors=frozenset({"rel_pos", "velocity_body", "gyro"}),
    edge_in=EDGE_OUT,
    edge_out=EDGE_OUT,
    parts=(
        Part("relative", relative_inputs, relative_step, 200.0),
        Part("yaw", yaw_inputs, yaw_step, 100.0),
        Part("position", position_inputs, position_step, 50.0),
        Part("control", control_inputs, control_step),
    ),
    command=COMMAND,
    graph="sensing",
    report="formation",
    params=FormationParams,
    initial=INITIAL,
    stale=StalePolicy(0.2, "hold"),
    sensor_use={"rel_pos": "ⁱp_ij (2), every part", "velocity_body": "v_i in (7) and (21)", "gyro": "ω_i in (7) and (13)"},
)
