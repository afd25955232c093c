"""Signed replies and publications: HMAC-SHA256 with a key the service and the cell share.

A reply's signature covers the key expression, a digest of the request it answers and the
reply's payload, so that a signed answer cannot be replayed to another request; a publication's
covers its key expression and payload. The signature travels as the Zenoh attachment, the
payload stays the plain JSON document. The key file holds at least 32 bytes (e.g.
`head -c 32 /dev/urandom > service.key`; keep it readable by the service and the controller only).
"""

from __future__ import annotations

import hashlib
import hmac
from pathlib import Path

from posedyn.errors import InputError

MIN_KEY_BYTES = 32


def read_key(path: Path) -> bytes:
    try:
        key = Path(path).read_bytes()
    except OSError as exc:
        raise InputError("a readable signing key file", got=str(exc), file=str(path)) from None
    if len(key.strip()) < MIN_KEY_BYTES:
        raise InputError(f"at least {MIN_KEY_BYTES} bytes of key", got=f"{len(key.strip())} bytes", file=str(path))
    return key.strip()


def reply_signature(key: bytes, key_expr: str, request: bytes | None, payload: bytes) -> bytes:
    digest = hashlib.sha256(request or b"").digest()
    return hmac.new(key, b"posedyn-reply-v1\0" + key_expr.encode() + b"\0" + digest + payload, hashlib.sha256).hexdigest().encode()


def sample_signature(key: bytes, key_expr: str, payload: bytes) -> bytes:
    return hmac.new(key, b"posedyn-sample-v1\0" + key_expr.encode() + b"\0" + payload, hashlib.sha256).hexdigest().encode()


def valid(signature: bytes | None, expected: bytes) -> bool:
    return signature is not None and hmac.compare_digest(signature, expected)
