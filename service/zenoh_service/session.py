"""Zenoh session configuration shared by the server and the client, and the service's default
access control."""

from __future__ import annotations

import json
from pathlib import Path

import zenoh

#: Where `posedyn serve` listens when it is given no endpoint and no config: this machine only.
DEFAULT_LISTEN = "tcp/127.0.0.1:7447"


def zenoh_config(config_file: Path | None = None, mode: str | None = None, listen=(), connect=()):
    """A zenoh.Config from an optional JSON5 file plus the command line's mode and endpoints.
    Explicit endpoints turn multicast scouting off (the peers are named, nothing to discover)."""
    conf = zenoh.Config.from_file(str(config_file)) if config_file else zenoh.Config()
    if mode:
        conf.insert_json5("mode", json.dumps(mode))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen or connect:
        conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def service_acl(prefix: str) -> dict:
    """Access control that keeps the service's own keys its own, whoever connects: no remote put
    or delete on its results (`schedules/**`), no remote queryable, liveliness token or reply on
    its endpoints (`schedule`, `plan/*`, `status`, `alive`: a rogue queryable or token is not
    routed); everything else allowed. Zenoh filters what arrives from other sessions (ingress), so the
    service's own publications and replies pass."""
    return {
        "enabled": True,
        "default_permission": "allow",
        "rules": [
            {"id": "results are the service's", "permission": "deny", "flows": ["ingress"], "messages": ["put", "delete"],
             "key_exprs": [f"{prefix}/schedules/**"]},
            {"id": "endpoints are the service's", "permission": "deny", "flows": ["ingress"], "messages": ["declare_queryable", "liveliness_token", "reply"],
             "key_exprs": [f"{prefix}/schedule", f"{prefix}/plan/**", f"{prefix}/status", f"{prefix}/alive"]},
        ],
        "subjects": [{"id": "everyone"}],
        "policies": [{"id": "service", "rules": ["results are the service's", "endpoints are the service's"], "subjects": ["everyone"]}],
    }


def secure_defaults(conf, prefix: str):
    """`conf` with the service's access control added when the configuration has none (a
    configuration that enables its own access control is taken as it is)."""
    current = json.loads(conf.get_json("access_control"))
    if not current.get("enabled"):
        conf.insert_json5("access_control", json.dumps(service_acl(prefix)))
    conf.insert_json5("timestamping/enabled", "true")  # AdvancedPublisher's cache needs timestamps
    return conf
