"""The authenticated profile (``zswarm run --secure``): mutual TLS and Zenoh access control.

Every process of a run gets a certificate of its own, signed by a CA made for the run
(:func:`make_certs`, with the ``cryptography`` package): the common name says who it is
(``agent-3``, ``world``, ``recorder``; the router is ``router``).  Links are TLS with
client certificates required (``enable_mtls``): a process without one signed by the
run's CA cannot connect.  The router's access control (:func:`acl`) lets each process
put only on its own keys and declare only its own liveliness token — agent i publishes
``edge/i/*``, ``est/i``, ``cmd/i``, ``stats/agent/i`` and ``alive/agent/i``, the world
the truth, the sensors, run control and its stats — so a process that claims to be
agent 3 with another certificate gets nothing delivered.  Everyone may subscribe to the
run's keys.  Zenoh's own features (TLS links, ACL by certificate common name), no
home-made authentication.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from zswarm.transport import keys

CA = "ca"
ROUTER = "router"
VALID_DAYS = 7  # the run's certificates: long enough for a soak, useless after


def name_of(role: str, ident: int) -> str:
    """A process's certificate name (its common name and file stem)."""
    return f"agent-{ident}" if role == "agent" else role


def make_certs(folder: Path, names: Iterable[str], hosts: Iterable[str] = ()) -> Path:
    """A CA (``ca.pem``; its key is not kept) and one certificate per name (plus the
    router's) in ``folder``: ``<name>.pem`` (certificate) and ``<name>.key`` (its key,
    mode 0600).  EC P-256; every certificate is valid for localhost and 127.0.0.1 and the
    names or addresses ``hosts`` (where a router started by hand is reached: TLS checks
    the endpoint's host against them), for server and client use."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    folder.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC)
    start, end = now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=VALID_DAYS)

    def write(stem: str, key: Any, cert: Any) -> None:
        # Created 0600 (never readable by others, not even for a moment); an old file too.
        fd = os.open(folder / f"{stem}.key", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.fchmod(fd, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
        (folder / f"{stem}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "zswarm run CA")])
    usage = {
        k: False
        for k in (
            "digital_signature",
            "content_commitment",
            "key_encipherment",
            "data_encipherment",
            "key_agreement",
            "key_cert_sign",
            "crl_sign",
            "encipher_only",
            "decipher_only",
        )
    }
    ca = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.KeyUsage(**(usage | {"digital_signature": True, "key_cert_sign": True, "crl_sign": True})), critical=True)
        .sign(ca_key, hashes.SHA256())
    )
    # The CA's key is not written: once these are made nothing more can be signed by the
    # run's CA, so a copied folder gives no way to mint another process's identity.
    (folder / f"{CA}.pem").write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    alt_names: list[Any] = []
    for h in ["localhost", "127.0.0.1", *hosts]:
        alt: Any
        try:
            alt = x509.IPAddress(ipaddress.ip_address(h))
        except ValueError:
            alt = x509.DNSName(h)
        if alt not in alt_names:
            alt_names.append(alt)
    for name in [ROUTER, *names]:
        key = ec.generate_private_key(ec.SECP256R1())
        cert = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(start)
            .not_valid_after(end)
            .add_extension(x509.SubjectAlternativeName(alt_names), critical=False)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .sign(ca_key, hashes.SHA256())
        )
        write(name, key, cert)
    return folder


def processes(sc_ids: Iterable[int]) -> list[tuple[str, int]]:
    """The (role, id) of every process of a run with agents ``sc_ids`` (the router aside)."""
    return [("agent", i) for i in sc_ids] + [("world", 0), ("recorder", 0)]


def certificate_names(sc_ids: Iterable[int]) -> list[str]:
    """The certificate names of every process of a run with agents ``sc_ids`` (the router's
    is made anyway): what :func:`make_certs` is given by ``zswarm run --secure`` and
    ``zswarm certs``."""
    return [name_of(r, i) for r, i in processes(sc_ids)]


def processes_in(folder: Path) -> list[tuple[str, int]]:
    """The (role, id) of the processes whose certificates are in ``folder`` (``agent-<i>.pem``,
    ``world.pem``, ``recorder.pem``): whom a router started by hand (``zswarm router
    --secure DIR``) gives the rights of :func:`acl`."""
    out: list[tuple[str, int]] = []
    for pem in sorted(folder.glob("*.pem")):
        stem = pem.stem
        if stem in ("world", "recorder"):
            out.append((stem, 0))
        elif stem.startswith("agent-") and stem[6:].isdigit():
            out.append(("agent", int(stem[6:])))
    return out


def tls(folder: Path, name: str, listen: bool) -> dict[str, Any]:
    """The ``transport/link/tls`` section of process ``name`` (``listen``: the router)."""
    d: dict[str, Any] = {"root_ca_certificate": str(folder / f"{CA}.pem"), "enable_mtls": True}
    side = "listen" if listen else "connect"
    d[f"{side}_private_key"] = str(folder / f"{name}.key")
    d[f"{side}_certificate"] = str(folder / f"{name}.pem")
    return d


def own_keys(run: str, role: str, ident: int) -> tuple[list[str], list[str]]:
    """(keys it may put on, liveliness tokens it may declare) for a process of ``run``."""
    if role == "agent":
        i = ident
        puts = [f"{keys.ROOT}/{run}/edge/{i}/*", keys.est(run, i), keys.cmd(run, i), keys.stats(run, "agent", i)]
    elif role == "world":
        puts = [keys.truth(run), f"{keys.ROOT}/{run}/sense/*", f"{keys.ROOT}/{run}/ctl/*", keys.stats(run, "world", 0)]
    else:
        puts = []
    return puts, [keys.alive(run, role, ident)]


def readable_keys(run: str, role: str, ident: int) -> list[str]:
    """The keys a process of ``run`` may subscribe to and receive: what its role reads and
    nothing else (least privilege: an agent that could read the truth or another agent's
    sensors could spoil an estimation experiment unseen).  An agent: its own sensor key, the
    edges into it, the run's control; the world: the commands and the control; the recorder
    (and the tools given its certificate: zswarm echo, hz): everything of the run."""
    ctl = f"{keys.ROOT}/{run}/ctl/*"
    if role == "agent":
        return [keys.sense(run, ident), keys.edges_into(run, ident), ctl]
    if role == "world":
        return [keys.cmds_all(run), ctl]
    return [f"{keys.ROOT}/{run}/**"]


def acl(run: str, procs: Iterable[tuple[str, int]]) -> dict[str, Any]:
    """The router's ``access_control`` for a run of the processes ``procs`` ((role, id)):
    deny by default; each may subscribe to and receive only what its role reads
    (:func:`readable_keys`), put only its own keys, declare only its own liveliness token,
    and ask only whether its own final stats are recorded, which the recorder answers.
    Everyone may watch the run's liveliness tokens (who is up)."""
    prefix = f"{keys.ROOT}/{run}/**"
    rules: list[dict[str, Any]] = [
        {
            "id": "liveliness",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ["declare_liveliness_subscriber", "liveliness_query"],
            "key_exprs": [prefix],
        },
        {"id": "tokens", "permission": "allow", "flows": ["egress"], "messages": ["liveliness_token", "declare_subscriber"], "key_exprs": [prefix]},
        # "Are my final stats recorded?" (keys.recorded): asked by each process of its own key
        # (below), served and answered by the recorder only.
        {"id": "recorded", "permission": "allow", "flows": ["egress"], "messages": ["query", "reply", "declare_queryable"], "key_exprs": [keys.recorded_all(run)]},
    ]
    subjects: list[dict[str, Any]] = [{"id": "anyone"}]
    policies: list[dict[str, Any]] = [{"rules": ["liveliness", "tokens", "recorded"], "subjects": ["anyone"]}]
    for role, ident in procs:
        name = name_of(role, ident)
        puts, tokens = own_keys(run, role, ident)
        reads = readable_keys(run, role, ident)
        own = [
            {"id": f"subscribe {name}", "permission": "allow", "flows": ["ingress"], "messages": ["declare_subscriber"], "key_exprs": reads},
            {"id": f"receive {name}", "permission": "allow", "flows": ["egress"], "messages": ["put"], "key_exprs": reads},
        ]
        if puts:
            own.append({"id": f"put {name}", "permission": "allow", "flows": ["ingress"], "messages": ["put"], "key_exprs": puts})
        own.append({"id": f"token {name}", "permission": "allow", "flows": ["ingress"], "messages": ["liveliness_token"], "key_exprs": tokens})
        if role == "recorder":
            own.append({"id": f"answer {name}", "permission": "allow", "flows": ["ingress"], "messages": ["declare_queryable", "reply"], "key_exprs": [keys.recorded_all(run)]})
        else:
            own.append({"id": f"ask {name}", "permission": "allow", "flows": ["ingress"], "messages": ["query"], "key_exprs": [keys.recorded(run, role, ident)]})
        rules += own
        subjects.append({"id": name, "cert_common_names": [name]})
        policies.append({"rules": [r["id"] for r in own], "subjects": [name]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def apply(conf: Any, folder: Path, name: str, router_acl: dict[str, Any] | None = None) -> None:
    """Put the TLS (and, for the router, access control) sections into a ``zenoh.Config``."""
    conf.insert_json5("transport/link/tls", json.dumps(tls(folder, name, listen=router_acl is not None)))
    if router_acl is not None:
        conf.insert_json5("access_control", json.dumps(router_acl))
