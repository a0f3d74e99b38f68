"""A whole-file SHA-256 seal in the zip comment of a policy artifact.

The CRC-32s of a zip archive cover each member's data, not the bytes around it: local headers (time, extra
field, padding), data descriptors and the gaps between members. A flipped byte there leaves every CRC intact,
and a damaged artifact would load. So ``hrlsac export`` seals what torch writes: the zip end record gets a
comment ``hrlsac-sha256:<64 hex digits>``, the digest of the archive exactly as torch wrote it (no comment).
Zip readers ignore comments, so a sealed artifact is still a valid zip; torch is handed the unsealed bytes.

Checking the seal finds a change of any byte of the file: in the archive (the digest differs), in the comment
(it is no longer a seal) or in the comment length (the end record is no longer where the seal puts it).
"""
from __future__ import annotations

import hashlib
import struct

ZIP_END = b"PK\x05\x06"
ZIP_END_SIZE = 22  # the end record without its comment; its last field is the comment's length (uint16)
SEAL_PREFIX = b"hrlsac-sha256:"
SEAL_SIZE = len(SEAL_PREFIX) + 64


class SealError(ValueError):
    """The bytes are not a sealed archive, or not the archive that was sealed."""


def ends_with_zip_end(data: bytes) -> bool:
    """Whether the last bytes of ``data`` are a zip end record without a comment, as torch writes it."""
    return data[-ZIP_END_SIZE:-ZIP_END_SIZE + 4] == ZIP_END and data[-2:] == b"\0\0"


def seal(archive: bytes) -> bytes:
    """``archive`` (a zip whose end record is last, without a comment, as torch writes it) with its seal."""
    if not ends_with_zip_end(archive):
        raise ValueError("can only seal a zip archive that ends with its end record and has no comment")
    digest = hashlib.sha256(archive).hexdigest().encode()
    return archive[:-2] + struct.pack("<H", SEAL_SIZE) + SEAL_PREFIX + digest


def is_sealed(data: bytes) -> bool:
    """Whether ``data`` ends like a sealed archive (an end record with a seal-sized comment); not yet checked."""
    end = data[-SEAL_SIZE - ZIP_END_SIZE:-SEAL_SIZE]
    return (len(end) == ZIP_END_SIZE and end.startswith(ZIP_END) and end[-2:] == struct.pack("<H", SEAL_SIZE)
            and data[-SEAL_SIZE:].startswith(SEAL_PREFIX))


def unseal(data: bytes) -> bytes:
    """The archive as torch wrote it, after checking the seal of ``data``; raises :class:`SealError`."""
    if not is_sealed(data):
        raise SealError("no seal at the end of the file")
    archive = data[:-SEAL_SIZE - 2] + b"\0\0"
    if hashlib.sha256(archive).hexdigest().encode() != data[-64:]:
        raise SealError("SHA-256 of the archive does not match its seal")
    return archive
