"""Key expressions of the final stats' confirmation, and who may use them under --secure."""

from __future__ import annotations

import pytest

from zswarm.transport import keys, run_control, secure, wire
from zswarm.transport.bus import key_matches


def test_recorded_keys_round_trip_and_refuse_anything_else():
    for role, i in (("agent", 1), ("agent", 4096), ("world", 0)):
        k = keys.recorded("r1", role, i)
        assert key_matches(keys.recorded_all("r1"), k) and keys.parse_recorded("r1", k) == (role, i)
    for k in (
        keys.recorded("r2", "agent", 1),  # another run's
        "zswarm/r1/recorded/recorder/0",  # the recorder sends no final stats to confirm
        "zswarm/r1/recorded/agent/x",
        "zswarm/r1/recorded/agent/1/more",
        keys.stats("r1", "agent", 1),
    ):
        assert keys.parse_recorded("r1", k) is None, k


def test_access_control_lets_each_process_ask_only_its_own_key_and_only_the_recorder_answer():
    acl = secure.acl("r1", secure.processes([1, 2]))
    rules = {r["id"]: r for r in acl["rules"]}
    by_subject = {p["subjects"][0]: p["rules"] for p in acl["policies"]}

    def allowed(name: str, message: str, flow: str) -> list[str]:
        return [k for rid in by_subject["anyone"] + by_subject[name] for k in rules[rid]["key_exprs"] if message in rules[rid]["messages"] and flow in rules[rid]["flows"]]

    assert allowed("agent-1", "query", "ingress") == [keys.recorded("r1", "agent", 1)]
    assert allowed("world", "query", "ingress") == [keys.recorded("r1", "world", 0)]
    assert allowed("recorder", "query", "ingress") == []
    for name in ("agent-1", "agent-2", "world"):
        assert allowed(name, "declare_queryable", "ingress") == [] and allowed(name, "reply", "ingress") == []
    assert allowed("recorder", "declare_queryable", "ingress") == allowed("recorder", "reply", "ingress") == [keys.recorded_all("r1")]
    assert allowed("agent-1", "reply", "egress") == [keys.recorded_all("r1")]  # the answer reaches the asker


def test_run_control_and_tokens_with_a_run_secret(monkeypatch):
    """With the run's secret (keys.SECRET_ENV) a ctl message must carry its HMAC and a token
    its tag; without it anything decodes as before (processes started by hand, old files)."""
    plain = wire.encode("stop", 0, 0, 2.0, reason="forged")
    monkeypatch.setenv(keys.SECRET_ENV, "s3cret")
    signed = run_control.encode_ctl("start", 0, 0, 0.0, epoch=1, time_scale=1, duration=5, seed=1, run="r")  # ints for floats: signed as decoded
    assert run_control.decode_ctl(signed, "start")["mac"]
    with pytest.raises(wire.MessageError, match="not signed with this run's secret"):
        run_control.decode_ctl(plain, "stop")
    tagged = keys.alive("r", "agent", 3)
    assert tagged.startswith("zswarm/r/alive/agent/3/") and keys.parse_alive(tagged) == ("agent", 3)
    assert keys.parse_alive("zswarm/r/alive/agent/3") is None  # a token without the tag: not the run's
    assert keys.parse_alive(tagged.replace("/agent/3/", "/agent/4/")) is None  # another's tag
    monkeypatch.setenv(keys.SECRET_ENV, "other")
    with pytest.raises(wire.MessageError, match="not signed"):
        run_control.decode_ctl(signed, "start")
    monkeypatch.delenv(keys.SECRET_ENV)
    assert run_control.decode_ctl(plain, "stop")["reason"] == "forged" and keys.parse_alive(tagged) == ("agent", 3)


def test_one_parser_takes_every_key_apart_and_back():
    """keys.parse is the one parser (the agent's edge links, the world's command keys, the
    replay's liveliness keys and wire.check_stream use it): every key zswarm builds parses to
    its kind and ids and back to the same stream; keys of another shape, or ids written
    another way than zswarm writes them ("03", "+3", "٣"), are not zswarm's."""
    built = {
        keys.edge("r", 1, 3): ("edge", 1, 3),
        keys.sense("r", 2): ("sense", 0, 2),
        keys.cmd("r", 4): ("cmd", 4, None),
        keys.est("r", 5): ("est", 5, None),
        keys.stats("r", "agent", 6): ("stats", 6, None),
        keys.truth("r"): ("truth", 0, None),
        keys.ctl("r", "start"): ("ctl", 0, None),
        keys.recorded("r", "world", 0): ("recorded", 0, None),
        "zswarm/r/alive/agent/3/abc": ("alive", 3, None),
    }
    for key, (kind, src, dst) in built.items():
        k = keys.parse(key)
        assert k is not None and (k.run, k.kind, k.src, k.dst) == ("r", kind, src, dst), key
        assert keys.stream_key("r", k.stream) == key
    for bad in ("zswarm/r/edge/03/4", "zswarm/r/cmd/+3", "zswarm/r/est/\u0663", "zswarm/r/edge/1", "zswarm/r/stats/ghost/1", "other/r/est/1", "zswarm//est/1", "zswarm/r"):
        assert keys.parse(bad) is None, bad
    assert keys.parse_recorded("r", keys.recorded("r", "agent", 2)) == ("agent", 2) and keys.parse_recorded("s", keys.recorded("r", "agent", 2)) is None
