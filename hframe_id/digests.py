"""SHA-256 of files: the identity of recordings, truth and parameter files in manifests, fit
provenance, imported sources and the fleet's results store."""

from __future__ import annotations

import hashlib
import os

#: Bytes read at a time: a recording of any size is hashed in constant memory.
BLOCK_BYTES = 1 << 20


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 of the file at ``path`` as 64 hex digits."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(BLOCK_BYTES), b""):
            digest.update(block)
    return digest.hexdigest()
