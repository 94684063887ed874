"""The vehicles of De Carli et al. (1), ``ṗ_i = R_z(ψ_i) v_i, ψ̇_i = ω_i``, under commands held
over world steps (world/plant.py KinematicPlant), and the relative-position sensor (2)."""

import math

import numpy as np

from world import sensors
from world.plant import CommandInbox, KinematicPlant
from zswarm.scenario import PLANT_INPUTS, CommandPolicy
from zswarm.scenario.links import LinkSpec
from zswarm.transport import wire

rng = np.random.default_rng(3)


def _rk4_reference(psi, p, u, h, n=2000):
    """(1) integrated with classical RK4 at h/n: the dt → 0 reference."""
    x = np.concatenate([p, [psi]])
    v, w = u[:3], u[3]

    def f(x):
        c, s = math.cos(x[3]), math.sin(x[3])
        return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2], w])

    d = h / n
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + d / 2 * k1)
        k3 = f(x + d / 2 * k2)
        k4 = f(x + d * k3)
        x = x + d / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x[3], x[:3]


def test_held_inputs_are_integrated_exactly():
    """One step under constant (v, ω) against RK4 at 1/2000 of it (truncation ~ n (ωd)⁵/120
    ≈ 1e-14 at ω = 2, d = 4e-4; round-off of 2000 additions ≈ 2000 · 2.2e-16 · 3 ≈ 1.3e-12):
    the closed form must agree to 5e-12, for large and tiny turns (the series branch
    below |ωh| = 1e-4 has error O(θ⁵) ≈ 1e-20)."""
    for w in (2.0, -0.7, 1e-3, 1e-6, 0.0):
        psi, p = rng.uniform(-math.pi, math.pi), rng.normal(size=3)
        u = np.concatenate([rng.normal(size=3), [w]])
        h = 0.8
        psi1, p1 = KinematicPlant.advance(np.array([psi]), p[None, :], u[None, :], h)
        psi_r, p_r = _rk4_reference(psi, p, u, h)
        assert abs(psi1[0] - psi_r) < 5e-12
        assert np.allclose(p1[0], p_r, atol=5e-12, rtol=0)


class _Fixed:
    """A stand-in inbox holding one input per agent (the plant only calls inputs_at)."""

    def __init__(self, u):
        self.u = np.array(u, dtype=float)
        self.calls = []

    def inputs_at(self, s, h):
        self.calls.append((s, h))
        return self.u


def test_plant_steps_cover_the_interval_and_the_result_does_not_depend_on_the_step():
    """Under held inputs the exact step makes the truth independent of the world step:
    ten 1 ms steps and one 10 ms step agree to round-off; ψ stays in [−π, π)."""
    R0 = np.array([np.eye(3), [[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]])
    p0 = np.array([[0.0, 0, 0], [1.0, 2, 3]])
    u = [[1.0, 0.5, 0.1, 0.3], [0.2, -0.4, 0.0, -2.0]]
    a, b = KinematicPlant(R0, p0, 1e-3, _Fixed(u)), KinematicPlant(R0, p0, 1e-2, _Fixed(u))
    a.advance_to(5.0)
    b.advance_to(5.0)
    assert np.allclose(a.p, b.p, atol=1e-11) and np.allclose(a.psi, b.psi, atol=1e-11)
    assert len(a.commands.calls) == 5000 and abs(sum(h for _, h in a.commands.calls) - 5.0) < 1e-9
    assert np.all(a.psi >= -math.pi) and np.all(a.psi < math.pi)
    assert np.allclose(a.R[1] @ a.R[1].T, np.eye(3), atol=1e-14) and a.R[1, 2, 2] == 1.0
    # the inertial velocity is R_z(ψ) v; the body rates are [0, 0, ω]
    assert np.allclose(a.velocity()[0], a.R[0] @ np.array(u[0][:3]), atol=1e-14)
    assert np.allclose(a.omega_now()[:, 2], [0.3, -2.0])


def test_commands_reach_the_plant_through_the_inbox_and_stale_ones_zero():
    """A ``vel``/``yaw_rate`` command on cmd/<i> is applied from its release on (ZOH); past
    max_age the "zero" policy stops the vehicle; a command without yaw_rate is malformed."""
    now = [0.0]
    inbox = CommandInbox([1, 2], lambda: now[0], lambda name: LinkSpec(), 1, CommandPolicy(0.5, "zero"), PLANT_INPUTS["kinematic"])
    on_cmd = inbox.handler(lambda key: int(key.rsplit("/", 1)[1]))
    plant = KinematicPlant(np.array([np.eye(3)] * 2), np.zeros((2, 3)), 1e-3, inbox)
    now[0] = 0.0
    on_cmd("zswarm/r/cmd/1", wire.encode("cmd", 1, 0, 0.0, t_local=0.0, vel=np.array([1.0, 0.0, 0.0]), yaw_rate=0.0))
    plant.advance_to(0.3)
    assert np.allclose(plant.p[0], [0.3, 0, 0], atol=1e-12) and np.allclose(plant.p[1], 0)
    plant.advance_to(1.0)  # the command's stamp is 0: from 0.5 s on it is stale and zeroed
    assert np.allclose(plant.p[0], [0.5, 0, 0], atol=2e-3)  # to within one world step
    assert inbox.expired[0] == 1
    on_cmd("zswarm/r/cmd/2", wire.encode("cmd", 2, 0, 1.0, t_local=1.0, vel=np.array([1.0, 0.0, 0.0])))
    assert inbox.malformed == 1


def test_relative_position_sensor():
    """(2): ⁱp_ij = R_iᵀ(p_j − p_i); the noise has the configured variance (chi-square bound:
    the sample variance of 30000 draws is within 5 % of 0.04 with ≫ 99.9 % probability,
    its relative std being √(2/30000) = 0.8 %)."""
    R = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    d = sensors.relative_position(R, np.array([1.0, 1, 0]), np.array([1.0, 3, 1]), 0.0, rng)
    assert np.allclose(d, [2.0, 0.0, 1.0])
    draws = np.array([sensors.relative_position(R, np.zeros(3), np.ones(3), 0.2, rng) for _ in range(10000)])
    assert abs(draws.var(axis=0).mean() / 0.04 - 1) < 0.05
