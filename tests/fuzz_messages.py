"""Hostile and broken messages for the fuzz tests (issue 14): a seeded generator.

Four families (see :meth:`Fuzzer.messages` for their shares), and valid messages among them:

* random bytes (0–300 of them);
* a valid message of the receiver's type with 1–8 of its bytes overwritten;
* a valid envelope whose fields are drawn from a zoo of values: arrays of the right
  shape with huge, tiny, NaN and infinite entries, wrong shapes, wrong types, huge
  integers, negative ids, long strings, maps keyed by anything;
* huge and deep structures: nesting 100 000 deep, maps of 100 000 entries, a
  1 MB binary, a string of 60 000 characters.

Deterministic for a seed, so a failure is reproduced by its index.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable, Iterator
from typing import Any

import msgpack
import numpy as np

from zswarm.math import so3
from zswarm.transport import wire

_ODD_FLOATS = [0.0, -0.0, 1.0, -1.0, 1e-308, 5e-324, 1e12, -1e12, 1e13, 1e200, -1e300, float("inf"), float("-inf"), float("nan")]
_ODD_INTS = [0, 1, -1, 2**31, 2**53, 2**63 - 1, 2**64 - 1, -(2**63)]


class Fuzzer:
    """Messages aimed at a receiver that expects ``valid(rng)`` (a maker of good payloads).

    Scalar draws use :class:`random.Random` (ten times cheaper per draw than numpy's
    generator: 10⁵ messages are made in seconds)."""

    def __init__(self, seed: int, valid: Callable[[np.random.Generator], bytes]) -> None:
        self.r = random.Random(seed)
        self.rng = np.random.default_rng(seed)  # for valid(): rotations, unit vectors
        self.valid = valid
        self._huge: list[bytes] = []
        # Bases of the mutated and zoo messages: 256 valid ones, made once (and unpacked).
        self._bases = [valid(self.rng) for _ in range(256)]
        self._unpacked = [msgpack.unpackb(b, raw=False, strict_map_key=False) for b in self._bases]

    def messages(self, n: int) -> Iterator[bytes]:
        """``n`` messages: random, mutated and zoo in turn, a huge one every 40th, and every
        10th a valid one (so that the receiver also steps, on whatever got through)."""
        kinds = (self.random_bytes, self.mutated, self.zoo)
        for k in range(n):
            if k % 40 == 39:
                yield self.huge()
            elif k % 10 == 9:
                yield self.valid(self.rng)
            else:
                yield kinds[k % 3]()

    def random_bytes(self) -> bytes:
        return self.r.randbytes(self.r.randrange(300))

    def mutated(self) -> bytes:
        p = bytearray(self.r.choice(self._bases))
        for _ in range(self.r.randrange(1, 9)):
            p[self.r.randrange(len(p))] = self.r.randrange(256)
        return bytes(p)

    def floats(self, n: int) -> bytes:
        r = self.r
        scale = 10.0 ** r.randrange(-3, 15)
        xs = [r.gauss(0.0, scale) for _ in range(n)]
        if r.random() < 0.3:
            xs[r.randrange(n)] = r.choice(_ODD_FLOATS)
        return struct.pack(f"<{n}d", *xs)

    def value(self, depth: int = 0) -> Any:
        r = self.r
        c = r.randrange(14 if depth < 3 else 8)
        if c == 0:
            return r.choice(_ODD_FLOATS)
        if c == 1:
            return r.choice(_ODD_INTS)
        if c == 2:
            shape = r.choice(([3], [3, 3]))
            return [shape, self.floats(3 if len(shape) == 1 else 9)]
        if c == 3:
            R = so3.exp(self.rng.standard_normal(3)) * (1.0 + r.choice((0.0, 1e-9, 1e-3)))
            return [[3, 3], R.tobytes()]
        if c == 4:
            return [[r.randrange(-2, 5) for _ in range(r.randrange(4))], r.randbytes(r.randrange(80))]
        if c == 5:
            return None
        if c == 6:
            return "x" * r.choice((0, 5, 5000))
        if c == 7:
            return r.random() < 0.5
        if c in (8, 9):
            return {self.key(): self.value(depth + 1) for _ in range(r.randrange(5))}
        if c in (10, 11):
            return [self.value(depth + 1) for _ in range(r.randrange(5))]
        if c == 12:
            return {r.randrange(-3, 10): [[3], self.floats(3)] for _ in range(r.randrange(4))}
        return [r.randrange(-3, 10), r.gauss(0.0, 1.0), 0.0, 1.0]

    def key(self) -> Any:
        r = self.r
        c = r.randrange(4)
        if c == 0:
            return r.choice(("gyro", "R", "x" * 70, ""))
        return r.randrange(-5, 10) if c == 1 else (None if c == 2 else f"k{r.randrange(9)}")

    def zoo(self) -> bytes:
        r = self.r
        base = self.r.choice(self._unpacked)
        mtype = r.choice([base["type"], *wire.KINDS])
        m: dict[Any, Any] = {"v": wire.VERSION if r.random() < 0.9 else self.value(), "type": mtype}
        for k in ("src", "seq", "inc", "t"):
            m[k] = base.get(k, 0) if r.random() < 0.5 else self.value()
        for k in [*wire.FIELDS[mtype], *(k for k in base if k not in wire.ENVELOPE)]:
            if r.random() < 0.7:
                m[k] = base[k] if k in base and r.random() < 0.4 else self.value()
        if r.random() < 0.2:
            m[self.key()] = self.value()
        return msgpack.packb(m, use_bin_type=True)

    def huge(self) -> bytes:
        """One of six huge payloads (each built once: they take milliseconds to pack)."""
        if not self._huge:
            self._huge = [self._make_huge(c) for c in range(6)]
        return self.r.choice(self._huge)

    def _make_huge(self, c: int) -> bytes:
        env = {
            "v": wire.VERSION,
            "type": msgpack.unpackb(self.valid(self.rng), raw=False, strict_map_key=False)["type"],
            "src": 0,
            "seq": 0,
            "inc": 0,
            "t": 0.0,
        }
        if c == 0:  # 100 000 nested one-element arrays (fixarray 0x91), then nil
            return b"\x91" * 100_000 + b"\xc0"
        if c == 1:
            return msgpack.packb({**env, "gyro": {j: [[3], bytes(24)] for j in range(100_000)}}, use_bin_type=True)
        if c == 2:
            return msgpack.packb({**env, "gyro": [[3], b"\x00" * (1 << 20)]}, use_bin_type=True)
        if c == 3:
            return msgpack.packb({**env, "reason": "y" * 60_000, "role": "z" * 60_000}, use_bin_type=True)
        if c == 4:  # a map header announcing 2**32 − 1 entries, then nothing
            return b"\xdf\xff\xff\xff\xff"
        return msgpack.packb({**env, "counters": {f"k{j}": list(range(10)) for j in range(2100)}}, use_bin_type=True)  # 23 100 entries


# ---------------------------------------------------------------- valid messages per receiver


def _unit(r: np.random.Generator) -> np.ndarray:
    b = r.standard_normal(3)
    return b / np.linalg.norm(b)


def valid_for_agent(sc: Any, i: int) -> Callable[[np.random.Generator], bytes]:
    """A valid sensor packet for agent ``i`` or a valid message from one of its in-neighbours
    (bearing_pose_fixed's fields), with per-source sequence numbers."""
    nbrs = list(sc.agent(i).neighbors)
    seq: dict[int, int] = {}

    def make(r: np.random.Generator) -> bytes:
        src = 0 if r.random() < 0.5 else nbrs[int(r.integers(0, len(nbrs)))]
        s = seq[src] = seq.get(src, -1) + 1
        t = 0.005 * s
        if src == 0:
            return wire.encode("sense", 0, s, t, inc=1, gyro=0.1 * r.standard_normal(3), bearings={j: _unit(r) for j in sc.graph_neighbors(i)})
        return wire.encode("edge", src, s, t, inc=1, t_local=t, R_hat=so3.exp(r.standard_normal(3)), p_hat=r.standard_normal(3), b=_unit(r))

    return make


def valid_cmd(sc: Any) -> Callable[[np.random.Generator], bytes]:
    """A valid torque command (the rigid bodies of (5.1)) from one of the agents."""
    seq: dict[int, int] = {}

    def make(r: np.random.Generator) -> bytes:
        i = int(sc.ids[int(r.integers(0, len(sc.ids)))])
        s = seq[i] = seq.get(i, -1) + 1
        return wire.encode("cmd", i, s, 0.005 * s, inc=1, t_local=0.005 * s, tau=0.1 * r.standard_normal(3))

    return make


def valid_for_recorder(sc: Any) -> Callable[[np.random.Generator], bytes]:
    """A valid message of any type a run records."""
    agent, cmd = valid_for_agent(sc, 3), valid_cmd(sc)
    ids = list(sc.ids)

    def make(r: np.random.Generator) -> bytes:
        c = int(r.integers(0, 6))
        if c < 2:
            return agent(r) if c == 0 else cmd(r)
        if c == 2:
            n = len(ids)
            return wire.encode(
                "truth", 0, 0, 0.0, ids=ids, R=np.stack([so3.exp(r.standard_normal(3)) for _ in ids]), p=r.standard_normal((n, 3)), w=r.standard_normal((n, 3))
            )
        if c == 3:
            return wire.encode("est", 3, 0, 0.0, t_local=0.0, R_hat=so3.exp(r.standard_normal(3)), p_hat=r.standard_normal(3), edges={"xi": {1: 0.5}})
        if c == 4:
            return wire.encode("stats", 3, 0, 0.0, role="agent", counters={"steps": int(r.integers(0, 100)), "final": False})
        return wire.encode("stop", 0, 0, 1.0, reason="duration")

    return make
