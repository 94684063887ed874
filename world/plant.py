"""Plants the agents act on: rigid bodies (5.1) driven by the torques of cmd/<i>, and
vehicles with the kinematics of De Carli et al. (1) driven by body-frame velocity and
yaw-rate commands.

The world receives each agent's command on ``cmd/<i>`` through that link's
emulation (``[links.commands]`` defaults, ``[links.per_link."i->world"]``),
like every other link, and applies it to the plant with a **zero-order
hold**: over each world step ``[s, s + h]`` the input (torque, or velocity and
yaw rate) is the newest command released to the world at or before ``s``.  Integration is lazy (the world
advances the truth at its sample times), but a command applies only from
its release on, at the world step's resolution: causal, and exact for a
piecewise-constant torque.

Stale commands: a command whose stamp (the world time its content refers
to) is older than ``max_age`` is handled by the plant's policy
(``[world.commands] max_age, policy``):

* ``"zero"`` (default): the torque drops to 0 until a fresher command
  arrives.  A dead, cut-off or stalled agent then lets its body coast: with
  τ = 0 the kinetic energy of (5.1) is constant, whereas holding its last
  torque would keep accelerating the body (ω grows linearly under a constant
  τ) for as long as the agent is gone.
* ``"hold"``: keep applying the newest command whatever its age (what a
  motor driver without a watchdog does).

The default ``max_age`` of 0.5 s is 50 periods of a 100 Hz controller and
2.5 times the longest command delay the §5.6 sweep studies (200 ms), so
within it losses and delays are bridged by the hold, as a ZOH does; past it
the agent is taken for gone.  Expiries and the time spent zeroed (or holding
a stale torque) are counted per agent.

A command that does not decode, lacks one of the plant's input fields (``tau``
(3,) for rigid bodies; ``vel`` (3,) and ``yaw_rate`` () for vehicles) or one of
the right shape, carries a value that is not finite (wire.decode), or comes from another agent's key is counted
(``malformed``) and dropped, never applied.
"""

from __future__ import annotations

import heapq
import logging
import math
import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from world.dynamics import RigidBodies
from zswarm.scenario.links import LinkCounter, LinkModel, LinkSpec
from zswarm.scenario.world_config import COMMAND_POLICIES, PLANT_INPUTS, PLANTS, CommandPolicy
from zswarm.transport import wire

__all__ = ["PLANTS", "PLANT_INPUTS", "COMMAND_POLICIES", "CommandPolicy", "CommandInbox", "RigidBodyPlant", "KinematicPlant"]

log = logging.getLogger("zswarm.world")


class _CmdLink(LinkCounter):
    """Counters of one command link i->world (the agents' LinkCounter), and its emulation."""

    __slots__ = ("model",)

    def __init__(self, model: LinkModel | None) -> None:
        super().__init__()
        self.model = model

    def as_dict(self) -> dict[str, Any]:
        d = super().as_dict()
        if self.model is not None and self.model.spec.active:
            d.update(self.model.counters())
        return d


class CommandInbox:
    """The world's end of the command links: decode, validate, emulate the link, hold.

    ``now()`` is the world time (virtual in ``sim``, the wall clock in a run);
    bus callbacks may run on another thread, so everything is under a lock.
    """

    def __init__(
        self,
        ids: list[int],
        now: Callable[[], float],
        link_spec: Callable[[str], LinkSpec],
        seed: int,
        policy: CommandPolicy,
        fields: Mapping[str, tuple[int, ...]],
    ) -> None:
        self.ids = list(ids)
        self.index = {i: a for a, i in enumerate(self.ids)}
        self.now = now
        self.policy = policy
        self.fields = dict(fields)
        self._decode = wire.decoder("cmd")
        self._lock = threading.Lock()
        self.links: dict[int, _CmdLink] = {}
        for i in self.ids:
            spec = link_spec(f"{i}->world")
            self.links[i] = _CmdLink(LinkModel(spec, f"{i}->world", seed) if spec.active else None)
        self._pending: list[tuple[float, int, int, float, int, NDArray[np.float64]]] = []  # (release, n, agent, stamp, n again: the order taken, u)
        self._n = 0
        # The plant's input vector u: the command's fields flattened in their declared order.
        self.width = sum(int(np.prod(shape)) for shape in self.fields.values())
        self.u = np.zeros((len(self.ids), self.width))  # applied now, per agent (row order of ids)
        self.stamp = np.full(len(self.ids), -math.inf)  # stamp of the applied command (-inf: none yet)
        self.seq = np.full(len(self.ids), -1, dtype=np.int64)
        self.applied = np.zeros(len(self.ids), dtype=np.int64)  # commands that took effect
        self.superseded = np.zeros(len(self.ids), dtype=np.int64)  # released but older than the one applied
        self.expired = np.zeros(len(self.ids), dtype=np.int64)  # commands that went past max_age while applied
        self.stale_s = np.zeros(len(self.ids))  # world time under a command older than max_age (zeroed or held)
        self._expired_flag = np.zeros(len(self.ids), dtype=bool)
        self.malformed = 0
        self._logged: set[str] = set()

    def handler(self, agent_of_key: Callable[[str], int | None]) -> Callable[[str, bytes], None]:
        """The bus callback of ``cmd/*``."""

        def on_cmd(key: str, payload: bytes) -> None:
            i = agent_of_key(key)
            try:
                if i is None or i not in self.index:
                    raise wire.MessageError("key is not the command key of an agent of this scenario")
                msg = self._decode(payload)
                if msg.src != i:
                    raise wire.MessageError(f"src {msg.src} on agent {i}'s command key")
                values = msg.values
                for name, shape in self.fields.items():
                    v = values.get(name)
                    if v is None:
                        raise wire.MessageError(f"field {name!r} missing")
                    if np.shape(v) != shape:
                        raise wire.MessageError(f"field {name!r}: shape {np.shape(v)}, expected {shape}")
                u = np.concatenate([np.ravel(np.asarray(values[name], dtype=float)) for name in self.fields]) if self.fields else np.zeros(0)
            except ValueError as exc:  # MessageError is a ValueError: decode never raises anything else
                with self._lock:
                    self.malformed += 1
                    first = key not in self._logged
                    self._logged.add(key)
                if first:
                    log.warning("dropped malformed command on %s: %s (logged once per key)", key, exc)
                return
            rx = self.now()
            with self._lock:
                link = self.links[i]
                release: float | None = rx
                if link.model is not None:
                    release = link.model.admit(rx)
                    if release is None:
                        return  # lost on the emulated link (counted by the model)
                if not link.see(msg.seq, msg.inc, release - msg.t_local):
                    self.superseded[self.index[i]] += 1  # older than one already taken (reordered)
                    return
                # n orders the commands of a link as they were taken (links are FIFO: release
                # order is that order); a restarted agent's seq starts again at 0.
                heapq.heappush(self._pending, (release, self._n, i, msg.t, self._n, u))
                self._n += 1

        return on_cmd

    def inputs_at(self, s: float, h: float) -> NDArray[np.float64]:
        """The inputs (n, width) held over the world step ``[s, s + h]``: every command released at or
        before ``s`` is taken in release order (the newest by sequence wins), then the
        stale policy is applied.  Called once per world step, in time order."""
        with self._lock:
            while self._pending and self._pending[0][0] <= s + 1e-12:
                _, _, i, stamp, seq, u = heapq.heappop(self._pending)
                a = self.index[i]
                if seq <= self.seq[a]:
                    self.superseded[a] += 1  # released after a newer one (cannot happen on a FIFO link)
                    continue
                self.u[a], self.stamp[a], self.seq[a] = u, stamp, seq
                self.applied[a] += 1
                self._expired_flag[a] = False
        out = self.u
        old = (s - self.stamp) > self.policy.max_age
        old &= np.isfinite(self.stamp)
        if old.any():
            self.stale_s[old] += h
            newly = old & ~self._expired_flag
            self.expired[newly] += 1
            self._expired_flag |= old
            if self.policy.policy == "zero":
                out = np.where(old[:, None], 0.0, self.u)
        return out

    def counters(self) -> dict[str, Any]:
        with self._lock:
            links = {f"{i}->world": self.links[i].as_dict() for i in self.ids}
            per = {
                str(i): {
                    "applied": int(self.applied[a]),
                    "superseded": int(self.superseded[a]),
                    "expired": int(self.expired[a]),
                    "stale_s": round(float(self.stale_s[a]), 6),
                }
                for i, a in self.index.items()
            }
            return {"links": links, "commands": per, "commands_malformed": self.malformed, "command_policy": f"{self.policy.policy} after {self.policy.max_age:g} s"}


class RigidBodyPlant:
    """Rigid bodies (5.1) under the agents' torques, with the interface of PrescribedMotion
    (``advance_to``, ``R``, ``p``, ``omega_now``) that the world samples."""

    def __init__(self, R0: NDArray[np.float64], p0: NDArray[np.float64], w0: NDArray[np.float64], J: NDArray[np.float64], step: float, commands: CommandInbox) -> None:
        self.bodies = RigidBodies(R0, w0, J)
        self.p = np.array(p0, dtype=float).reshape(-1, 3)
        self.step = step
        self.commands = commands
        self.t = 0.0
        self.tau = np.zeros_like(self.bodies.w)  # the torques of the last world step (for the truth)

    @property
    def R(self) -> NDArray[np.float64]:
        return self.bodies.R

    def omega_now(self) -> NDArray[np.float64]:
        return self.bodies.w

    def velocity(self) -> NDArray[np.float64]:
        return np.zeros_like(self.p)

    def advance_to(self, t: float) -> None:
        """Integrate from ``self.t`` to ``t`` in world steps (the last one may be shorter),
        each under the torques held over it."""
        while self.t < t - 1e-12:
            h = min(self.step, t - self.t)
            if t - (self.t + h) < 1e-9:
                h = t - self.t  # no sliver of a step left before t
            self.tau = self.commands.inputs_at(self.t, h)
            self.bodies.step(self.tau, h)
            self.t += h
        self.t = max(self.t, t)


class KinematicPlant:
    """Vehicles with the kinematics (1) of De Carli et al.: ``ṗ_i = R_z(ψ_i) v_i``,
    ``ψ̇_i = ω_i``, v_i the body-frame velocity and ω_i the yaw rate commanded on
    cmd/<i> (``vel`` (3,), ``yaw_rate``), held over each world step.

    With the inputs constant over a step of length h the motion is integrated
    exactly: ``ψ⁺ = ψ + ωh`` and ``p⁺ = p + R_z(ψ) G(ωh) v h`` with the planar
    ``G(θ) = [[sin θ/θ, −(1 − cos θ)/θ], [(1 − cos θ)/θ, sin θ/θ]]`` (``∫₀ʰ R_z(ψ + ωs) ds``)
    and the vertical component ``v_z h``; so a run's truth depends on the world
    step only through when commands take effect.  Interface of PrescribedMotion
    (``advance_to``, ``R``, ``p``, ``omega_now``, ``velocity``).
    """

    def __init__(self, R0: NDArray[np.float64], p0: NDArray[np.float64], step: float, commands: CommandInbox) -> None:
        R0 = np.asarray(R0, dtype=float).reshape(-1, 3, 3)
        self.psi = np.arctan2(R0[:, 1, 0], R0[:, 0, 0])  # the scenario checks that R_i(0) is a yaw
        self.p = np.array(p0, dtype=float).reshape(-1, 3)
        self.step = step
        self.commands = commands
        self.t = 0.0
        self.u = np.zeros((len(self.p), 4))  # [v_x, v_y, v_z, ω] of the last world step (for the truth)

    @property
    def R(self) -> NDArray[np.float64]:
        c, s = np.cos(self.psi), np.sin(self.psi)
        R = np.zeros((len(self.psi), 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
        return R

    def omega_now(self) -> NDArray[np.float64]:
        """Body rates: the commanded yaw rate about e3."""
        w = np.zeros((len(self.psi), 3))
        w[:, 2] = self.u[:, 3]
        return w

    def velocity(self) -> NDArray[np.float64]:
        """Inertial velocities ``R_z(ψ_i) v_i`` under the current commands."""
        return np.einsum("nij,nj->ni", self.R, self.u[:, :3])

    @staticmethod
    def advance(psi: NDArray[np.float64], p: NDArray[np.float64], u: NDArray[np.float64], h: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The exact solution of (1) over ``h`` with ``u = [v, ω]`` held (batched)."""
        th = u[:, 3] * h
        small = np.abs(th) < 1e-4
        th_s = np.where(small, 1.0, th)
        a = np.where(small, 1.0 - th**2 / 6.0 + th**4 / 120.0, np.sin(th_s) / th_s)  # sin θ/θ
        b = np.where(small, th / 2.0 - th**3 / 24.0, (1.0 - np.cos(th_s)) / th_s)  # (1 − cos θ)/θ
        vx, vy = u[:, 0], u[:, 1]
        gx, gy = a * vx - b * vy, b * vx + a * vy  # G(θ) v (planar part)
        c, s = np.cos(psi), np.sin(psi)
        dp = np.stack([h * (c * gx - s * gy), h * (s * gx + c * gy), h * u[:, 2]], axis=1)
        return psi + th, p + dp

    def advance_to(self, t: float) -> None:
        """Integrate from ``self.t`` to ``t`` in world steps, each under the inputs held over it."""
        while self.t < t - 1e-12:
            h = min(self.step, t - self.t)
            if t - (self.t + h) < 1e-9:
                h = t - self.t
            self.u = self.commands.inputs_at(self.t, h)
            self.psi, self.p = self.advance(self.psi, self.p, self.u, h)
            self.t += h
        self.t = max(self.t, t)
        self.psi = np.mod(self.psi + np.pi, 2 * np.pi) - np.pi  # ψ in [−π, π)
