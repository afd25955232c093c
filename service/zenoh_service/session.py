"""Zenoh session configuration shared by the server and the client."""

from __future__ import annotations

import json
from pathlib import Path

import zenoh


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
