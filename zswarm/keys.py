"""Every Zenoh key expression zswarm uses, built in one place.

``zswarm/<run>/...``; the run id lets several runs share one Zenoh network.
"""

from __future__ import annotations

import re

ROOT = "zswarm"
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
    """Liveliness token of a process (role: world, agent, recorder)."""
    return f"{ROOT}/{run}/alive/{role}/{i}"


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
    """``(role, id)`` of a liveliness key, or None if it is not one."""
    parts = key.split("/")
    if len(parts) != 5 or parts[2] != "alive":
        return None
    try:
        return parts[3], int(parts[4])
    except ValueError:
        return None


def stream_of(run: str, key: str) -> str:
    """The recording channel of a key: the key without the ``zswarm/<run>/`` prefix."""
    prefix = f"{ROOT}/{run}/"
    return key[len(prefix) :] if key.startswith(prefix) else key


def stream_key(run: str, stream: str) -> str:
    """The key (or key prefix) of a recording channel: the inverse of :func:`stream_of`."""
    return f"{ROOT}/{run}/{stream}"
