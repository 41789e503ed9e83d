"""SHA-256 and a constant-time compare for MAVLink 2 signing, without OpenSSL.

hashlib's sha256 and hmac's compare_digest are OpenSSL's: importing either loads and
initialises libcrypto, 3.6 MB of RSS in a process that needs nothing else of it.  A
follower signs and checks a few frames a tick and holds no other use for OpenSSL (its
TLS is Zenoh's own), and that was the tenth of its memory over the 40 MB a paper-case
follower may take (issue 50).  CPython's built-in SHA-256 hashes a signed frame in
0.5-0.7 us where OpenSSL's takes 0.4 (`python -m timeit`, key-primed copy or not): far
below a tick's cost.  An interpreter built without it falls back to hashlib.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

try:  # CPython 3.12+
    from _sha2 import sha256 as _sha256  # type: ignore[import-not-found,unused-ignore]
except ImportError:
    try:  # CPython 3.11
        from _sha256 import sha256 as _sha256  # type: ignore[import-not-found,no-redef,unused-ignore]
    except ImportError:  # an interpreter built without its own hashes
        from hashlib import sha256 as _sha256  # type: ignore[assignment,no-redef,unused-ignore]
# The constant-time compare that hmac.compare_digest falls back to without OpenSSL.
from _operator import _compare_digest  # type: ignore[attr-defined,unused-ignore]

sha256: Callable[..., Any] = _sha256
compare_digest: Callable[[bytes, bytes], bool] = _compare_digest
