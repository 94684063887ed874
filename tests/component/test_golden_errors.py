"""Every bad-input message of the scenario loader stays word for word what it was (issue 30,
part 4: the typed schema must not change one message).

For three shipped scenarios (a leader-follower §3.2 one, a §4.5 hybrid one with params and a
tree, De Carli's formation with a kinematic plant and commands), every field of the tables the
typed schema reads ([scenario], [algorithm] and its gains and stale policy, [world] and its
commands and formation, [noise], [clock], [links] and its sensors, commands and per_link,
an agent's [agents.clock]) is set to each of a list of bad values, both in the file and with
``--set``; every table gets an unknown key, loses each required key and is replaced by a
non-table.  The message each gives (or "ok" when the value is accepted) is compared with
tests/data/golden_errors.json, written on the hand-written loader, before the schema (e07275c),
and frozen since: a message that changes on purpose is changed in that file by hand, beside
the change that makes it.
"""

from __future__ import annotations

import copy
import json
import math
import tomllib

import pytest
import tomli_w

from tests.conftest import ROOT, TOPO
from zswarm.scenario import ScenarioError, loads, parse_override

GOLDEN = ROOT / "tests" / "data" / "golden_errors.json"
SCENARIOS = ("thesis-3.2-fixed8", "thesis-4.5-hybrid5", "decarli-8-formation")
# The tables and their fields (the absent optional ones too).
LINK = ("delay_ms", "jitter_ms", "jitter", "reorder", "drop", "ge_p_gb", "ge_p_bg", "ge_loss_good", "ge_loss_bad")
TABLES: dict[tuple[str | int, ...], tuple[str, ...]] = {
    ("scenario",): ("name", "description", "duration", "seed"),
    ("algorithm",): ("name", "gains", "params", "stale"),
    ("algorithm", "stale"): ("max_age", "policy"),
    ("world",): ("step", "sensor_rate", "plant", "sensors", "formation", "commands"),
    ("world", "commands"): ("max_age", "policy"),
    ("world", "formation"): ("axis", "rate"),
    ("noise",): ("gyro_var", "bearing_var", "velocity_var", "rel_att_var", "attitude_var", "rel_pos_var"),
    ("clock",): ("rate", "jitter", "drift_ppm", "offset"),
    ("links",): LINK,
    ("links", "sensors"): LINK,
    ("links", "commands"): LINK,
    ("links", "per_link", "world->1"): LINK,
    ("agents", 0, "clock"): ("rate", "jitter", "drift_ppm", "offset"),
}
BAD = ("x", True, -1, 0, 0.5, 2, 1e-9, 7e5, 1e300, math.inf, -math.inf, math.nan, 1.5e11, -2e5, [1, 2], [1, 2, 3], {"a": 1}, "zero", "hold", "exponential")


def _name(keys):
    out = ""
    for k in keys:
        out += f"[{k}]" if isinstance(k, int) else (f'."{k}"' if "-" in str(k) else f".{k}")
    return out.lstrip(".")


def _at(doc, keys, create=True):
    node = doc
    for k in keys:
        if isinstance(k, int):
            node = node[k]
        else:
            if k not in node and create:
                node[k] = {}
            node = node[k]
    return node


def _message(text, overrides=()):
    try:
        loads(text, "s.toml", overrides)
    except ScenarioError as exc:
        return str(exc)
    return "ok"


def _cases(stem):
    base = tomllib.loads((TOPO / f"{stem}.toml").read_text())
    out = {}
    for table, fields in TABLES.items():
        for fld in fields:
            for v in BAD:
                doc = copy.deepcopy(base)
                _at(doc, table)[fld] = v
                key = f"{stem} file {_name(table + (fld,))}={v!r}"
                out[key] = _message(tomli_w.dumps(doc))
            for v in ("x", -1, 1e300, "inf"):
                flag = f"{_name(table + (fld,))}={v}"
                key = f"{stem} --set {flag}"
                try:
                    o = parse_override(flag)
                except ScenarioError as exc:
                    out[key] = str(exc)
                    continue
                out[key] = _message((TOPO / f"{stem}.toml").read_text(), [o])
        doc = copy.deepcopy(base)
        _at(doc, table)["bogus"] = 1
        out[f"{stem} file {_name(table)} unknown key"] = _message(tomli_w.dumps(doc))
        if table != ("agents", 0, "clock"):
            doc = copy.deepcopy(base)
            _at(doc, table[:-1])[table[-1]] = 3
            out[f"{stem} file {_name(table)} not a table"] = _message(tomli_w.dumps(doc))
        for fld in fields:
            doc = copy.deepcopy(base)
            node = _at(doc, table)
            if fld in node:
                del node[fld]
                out[f"{stem} file {_name(table + (fld,))} removed"] = _message(tomli_w.dumps(doc))
    for top in ("scenario", "algorithm", "agents", "world", "bogus"):
        doc = copy.deepcopy(base)
        doc.pop(top, None) if top != "bogus" else doc.update(bogus=1)
        out[f"{stem} file top {top}"] = _message(tomli_w.dumps(doc))
    doc = copy.deepcopy(base)
    doc["algorithm"]["gains"]["bogus_gain"] = 1.0
    out[f"{stem} file gains unknown"] = _message(tomli_w.dumps(doc))
    for g in list(base["algorithm"].get("gains", {})):
        for v in ("x", -1, 0, math.inf, True):
            doc = copy.deepcopy(base)
            doc["algorithm"]["gains"][g] = v
            out[f"{stem} file gains.{g}={v!r}"] = _message(tomli_w.dumps(doc))
        doc = copy.deepcopy(base)
        del doc["algorithm"]["gains"][g]
        out[f"{stem} file gains.{g} removed"] = _message(tomli_w.dumps(doc))
    return out


@pytest.mark.parametrize("stem", SCENARIOS)
def test_messages_unchanged(stem):
    got = _cases(stem)
    ref = json.loads(GOLDEN.read_text())[stem]
    assert got.keys() == ref.keys()
    changed = {k: (ref[k], got[k]) for k in ref if ref[k] != got[k]}
    assert not changed, "\n".join(f"{k}:\n  was {a}\n  now {b}" for k, (a, b) in list(changed.items())[:20])
