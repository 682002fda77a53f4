"""Constant-time check of a key a client sent (a lease key, the API token).

hmac.compare_digest takes str only when both are ASCII and raises TypeError otherwise, so a
request carrying "\\x80" as its lease crashed the request's handler and got no answer. The
key is compared as UTF-8 bytes (lone surrogates, which JSON can carry, kept as they came)."""
from __future__ import annotations

import hmac


def key_matches(given: object, expected: str) -> bool:
    """True when `given` is a string equal to `expected`; anything else is simply no match."""
    if not isinstance(given, str):
        return False
    return hmac.compare_digest(given.encode("utf-8", "surrogatepass"), expected.encode("utf-8", "surrogatepass"))
