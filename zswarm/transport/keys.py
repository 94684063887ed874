"""Every Zenoh key expression zswarm uses, built in one place.

``zswarm/<run>/...``; the run id lets several runs share one Zenoh network.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import os
import re
from dataclasses import dataclass

ROOT = "zswarm"
# The run's secret (``zswarm run`` makes one per run and hands it to its children in the
# environment; processes started by hand share one by setting it themselves).  With it, a
# process's liveliness token carries a tag only a holder of the secret can make, and run
# control (``ctl/...``) is signed (:mod:`zswarm.transport.wire`, ``mac``): a peer on the network can
# neither stand in for a process that is not up yet nor start or stop the run.  Without it
# (the default for processes started by hand) anything goes, as before.  A peer that can
# read the traffic still sees a tag once its process has declared it and can declare a copy
# (a process killed while such a copy stands is seen as alive by the others: the launcher
# sees it dead by its PID); only the access control of ``--secure`` stops that.
SECRET_ENV = "ZSWARM_RUN_SECRET"


def run_secret() -> bytes | None:
    """The run's secret from the environment (SECRET_ENV), or None."""
    s = os.environ.get(SECRET_ENV)
    return s.encode() if s else None


def alive_tag(secret: bytes, role: str, i: int) -> str:
    """The tag of ``role`` ``i``'s liveliness token under ``secret`` (24 hex digits)."""
    return hmac.new(secret, f"alive/{role}/{i}".encode(), hashlib.sha256).hexdigest()[:24]


_RUN_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def check_run_id(run: str) -> str:
    if not _RUN_ID.match(run):
        raise ValueError(f"run id must match {_RUN_ID.pattern} (got {run!r})")
    return run


def edge(run: str, src: int, dst: int) -> str:
    """What agent ``src`` sends to agent ``dst`` along the edge src -> dst."""
    return f"{ROOT}/{run}/edge/{src}/{dst}"


def edges_into(run: str, dst: int) -> str:
    return f"{ROOT}/{run}/edge/*/{dst}"


def sense(run: str, i: int) -> str:
    """World -> agent i sensor packets."""
    return f"{ROOT}/{run}/sense/{i}"


def cmd(run: str, i: int) -> str:
    """Agent i -> world: its command to the plant (a torque for the rigid bodies of (5.1))."""
    return f"{ROOT}/{run}/cmd/{i}"


def cmds_all(run: str) -> str:
    return f"{ROOT}/{run}/cmd/*"


def est(run: str, i: int) -> str:
    """Agent i -> recorder: its estimate."""
    return f"{ROOT}/{run}/est/{i}"


def stats(run: str, role: str, i: int) -> str:
    """Process counters (steps, link counts, malformed messages) for the recorder."""
    return f"{ROOT}/{run}/stats/{role}/{i}"


def truth(run: str) -> str:
    return f"{ROOT}/{run}/truth"


def ctl(run: str, what: str) -> str:
    """Run control: ``start``, ``stop``, ``progress``."""
    return f"{ROOT}/{run}/ctl/{what}"


def alive(run: str, role: str, i: int) -> str:
    """Liveliness token of a process (role: world, agent, recorder); with the run's secret,
    ``.../alive/<role>/<i>/<tag>`` (:func:`alive_tag`)."""
    base = f"{ROOT}/{run}/alive/{role}/{i}"
    secret = run_secret()
    return base if secret is None else f"{base}/{alive_tag(secret, role, i)}"


def alive_all(run: str) -> str:
    return f"{ROOT}/{run}/alive/**"


def recorded(run: str, role: str, i: int) -> str:
    """Asked (a Zenoh query) by a process that has sent its final stats, answered by the
    recorder once it has them: the process keeps its session open until then."""
    return f"{ROOT}/{run}/recorded/{role}/{i}"


def recorded_all(run: str) -> str:
    return f"{ROOT}/{run}/recorded/*/*"


def everything(run: str) -> str:
    return f"{ROOT}/{run}/**"


# --------------------------------------------------------------------------- parsing: the one parser


ROLES = ("world", "agent", "recorder")


@dataclass(frozen=True, slots=True)
class Key:
    """A zswarm key taken apart (:func:`parse`): the run, the kind of stream, and whose it is.

    ``src`` is the id of the process whose stream it is: an edge's tail j, ``est``/``cmd``'s
    agent, ``stats``/``alive``/``recorded``'s process, and 0 (the world) for ``truth``,
    ``sense`` and ``ctl``; ``dst`` the receiving agent of an edge or a sensor packet."""

    run: str
    kind: str  # edge, sense, cmd, est, stats, truth, ctl, alive, recorded
    src: int
    dst: int | None = None
    role: str | None = None  # stats, alive, recorded: world | agent | recorder
    what: str | None = None  # ctl: start | stop | progress
    tag: str | None = None  # alive: the token's tag (with the run's secret)

    @property
    def stream(self) -> str:
        """The key without the ``zswarm/<run>/`` prefix (a recording channel)."""
        if self.kind == "edge":
            return f"edge/{self.src}/{self.dst}"
        if self.kind == "sense":
            return f"sense/{self.dst}"
        if self.kind in ("cmd", "est"):
            return f"{self.kind}/{self.src}"
        if self.kind == "truth":
            return "truth"
        if self.kind == "ctl":
            return f"ctl/{self.what}"
        tail = f"/{self.tag}" if self.tag is not None else ""
        return f"{self.kind}/{self.role}/{self.src}{tail}"


def _id(s: str) -> int | None:
    """A process id in a key, written as zswarm writes it: ASCII digits without a leading
    zero (int() also takes "+3", " 3", "٣" and "03", each another key for the same id)."""
    return int(s) if s.isascii() and s.isdigit() and len(s) <= 10 and (s == "0" or s[0] != "0") else None


@functools.lru_cache(maxsize=4096)
def parse_stream(stream: str, run: str = "") -> Key | None:
    """A stream (a key without its ``zswarm/<run>/`` prefix) taken apart, or None if it is
    not one of zswarm's.  Cached (a run has a few hundred streams; the recorder parses every
    message's: 10 µs each, a third of sim's recording time, 2026-12-06); bounded, so junk
    keys cost only their parse."""
    p = stream.split("/")
    kind, n = p[0], len(p)
    if kind == "edge" and n == 3:
        j, i = _id(p[1]), _id(p[2])
        return None if j is None or i is None else Key(run, kind, j, i)
    if kind == "sense" and n == 2:
        i = _id(p[1])
        return None if i is None else Key(run, kind, 0, i)
    if kind in ("cmd", "est") and n == 2:
        i = _id(p[1])
        return None if i is None else Key(run, kind, i)
    if kind == "truth" and n == 1:
        return Key(run, kind, 0)
    if kind == "ctl" and n == 2:
        return Key(run, kind, 0, what=p[1])
    if kind in ("stats", "recorded") and n == 3 or kind == "alive" and n in (3, 4):
        i = _id(p[2])
        return None if i is None or p[1] not in ROLES else Key(run, kind, i, role=p[1], tag=p[3] if n == 4 else None)
    return None


def parse(key: str) -> Key | None:
    """A zswarm key (``zswarm/<run>/<stream>``) taken apart, or None if it is not one."""
    root, _, rest = key.partition("/")
    run, _, stream = rest.partition("/")
    if root != ROOT or not run or not stream:
        return None
    return parse_stream(stream, run)


def parse_recorded(run: str, key: str) -> tuple[str, int] | None:
    """``(role, id)`` of a :func:`recorded` key of ``run`` (an agent's or the world's), or None."""
    k = parse(key)
    if k is None or k.kind != "recorded" or k.run != run or k.role not in ("agent", "world"):
        return None
    return k.role, k.src


def parse_alive(key: str) -> tuple[str, int] | None:
    """``(role, id)`` of a liveliness key, or None if it is not one: with the run's secret,
    one without its tag or with another is not (a token a peer declared for a process that
    is not up).  Without the secret (reading a recording later) a tag is not checked."""
    k = parse(key)
    if k is None or k.kind != "alive" or k.role is None:
        return None
    secret = run_secret()
    if secret is not None and (k.tag is None or not hmac.compare_digest(k.tag, alive_tag(secret, k.role, k.src))):
        return None
    return k.role, k.src


def stream_of(run: str, key: str) -> str:
    """The recording channel of a key: the key without the ``zswarm/<run>/`` prefix."""
    prefix = f"{ROOT}/{run}/"
    return key[len(prefix) :] if key.startswith(prefix) else key


def stream_key(run: str, stream: str) -> str:
    """The key (or key prefix) of a recording channel: the inverse of :func:`stream_of`."""
    return f"{ROOT}/{run}/{stream}"


_DIGITS = re.compile(r"(\d+)")


def natural(key: str) -> list[int | str]:
    """The sort key of a key, stream or link name with its numbers compared as numbers
    (``edge/2/10`` after ``edge/2/9``, ``10->3`` after ``9->3``)."""
    return [int(p) if p.isdigit() else p for p in _DIGITS.split(key)]
