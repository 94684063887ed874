"""Every Zenoh key expression zswarm uses, built in one place.

``zswarm/<run>/...``; the run id lets several runs share one Zenoh network.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re

ROOT = "zswarm"
# The run's secret (``zswarm run`` makes one per run and hands it to its children in the
# environment; processes started by hand share one by setting it themselves).  With it, a
# process's liveliness token carries a tag only a holder of the secret can make, and run
# control (``ctl/...``) is signed (:mod:`zswarm.wire`, ``mac``): a peer on the network can
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


def parse_recorded(run: str, key: str) -> tuple[str, int] | None:
    """``(role, id)`` of a :func:`recorded` key of ``run``, or None if it is not one."""
    parts = key.split("/")
    if len(parts) != 5 or parts[:3] != [ROOT, run, "recorded"] or parts[3] not in ("agent", "world"):
        return None
    try:
        return parts[3], int(parts[4])
    except ValueError:
        return None


def everything(run: str) -> str:
    return f"{ROOT}/{run}/**"


def parse_alive(key: str) -> tuple[str, int] | None:
    """``(role, id)`` of a liveliness key, or None if it is not one: with the run's secret,
    one without its tag or with another is not (a token a peer declared for a process that
    is not up).  Without the secret (reading a recording later) a tag is not checked."""
    parts = key.split("/")
    if len(parts) not in (5, 6) or parts[2] != "alive":
        return None
    try:
        who = parts[3], int(parts[4])
    except ValueError:
        return None
    secret = run_secret()
    if secret is not None and (len(parts) != 6 or not hmac.compare_digest(parts[5], alive_tag(secret, *who))):
        return None
    return who


def stream_of(run: str, key: str) -> str:
    """The recording channel of a key: the key without the ``zswarm/<run>/`` prefix."""
    prefix = f"{ROOT}/{run}/"
    return key[len(prefix) :] if key.startswith(prefix) else key


def stream_key(run: str, stream: str) -> str:
    """The key (or key prefix) of a recording channel: the inverse of :func:`stream_of`."""
    return f"{ROOT}/{run}/{stream}"
