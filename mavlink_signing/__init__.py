"""MAVLink 2 message signing shared by the vehicle and the companion computer: key files and frame checks.

A package of its own at the bottom of the house, because both sides need it: ``sitl_bridge`` (the simulated vehicle)
and ``autonomy`` (the companion computer, which must not import the simulator). It uses the standard library only;
it works on raw frames and on pymavlink's parser by duck typing. ``hrlsac keygen`` is :mod:`.keygen_cli`.

The signing spec (https://mavlink.io/en/guide/message_signing.html) in one paragraph: a signed MAVLink 2 frame sets
bit 0 of ``incompat_flags`` and ends with 13 bytes: link id (1), timestamp (6, little-endian, units of 10
microseconds since the MAVLink epoch, 1 January 2015 00:00 UTC) and the first 6 bytes of SHA-256(secret key + the
frame up to and including the timestamp). A receiver keeps the last timestamp of each (link id, system, component)
stream and rejects a frame whose timestamp is not newer; a new stream is accepted only if its timestamp is at most
one minute behind the receiver's clock.

Key files hold the 32-byte secret as 64 hexadecimal characters on one line and must be private to their owner
(like ssh keys): :func:`write_key_file` writes them so, :func:`load_key_file` refuses anything else.
"""
from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import time
from collections import Counter
from pathlib import Path
from typing import Callable

KEY_BYTES = 32
MAVLINK_EPOCH_UNIX_S = 1_420_070_400  # 1 January 2015, 00:00:00 UTC
TIMESTAMP_UNITS_PER_S = 100_000  # the signing timestamp counts 10-microsecond units
NEW_STREAM_MAX_AGE = 60 * TIMESTAMP_UNITS_PER_S  # the spec's one minute
SIGNATURE_LEN = 13  # link id + 6-byte timestamp + 6-byte signature
SIGNED_FLAG = 0x01  # MAVLINK_IFLAG_SIGNED in incompat_flags
MAVLINK1_MARKER = 0xFE
_MAX_KEY_FILE_BYTES = 256  # a key file is 65 bytes; anything much larger is not one (and is not read whole)

# Verdicts of SignatureVerifier.check (also the keys of the rejection counters).
SIGNED = "signed"
UNSIGNED = "unsigned"  # a MAVLink 2 frame without a signature
MAVLINK1 = "mavlink1"  # MAVLink 1 cannot carry a signature: accepting it would be a downgrade
BAD_SIGNATURE = "bad_signature"  # wrong key, or the frame was altered
REPLAY = "replay"  # timestamp not newer than the last one seen on its stream
STALE = "stale"  # a new stream whose timestamp is more than a minute behind our clock


class KeyFileError(ValueError):
    """A key file cannot be written or used; the message is one line naming the file and the fix."""


# ---------------------------------------------------------------------------------------------- key files
def generate_key() -> bytes:
    """A fresh random 32-byte secret from the operating system's CSPRNG."""
    return secrets.token_bytes(KEY_BYTES)


def write_key_file(path: str | Path, key: bytes, force: bool = False) -> None:
    """Write ``key`` as 64 hex characters and a newline, mode 0600, atomically; refuse to replace an existing
    file unless ``force``. The secret is never on disk with wider permissions, nor half-written."""
    path = Path(path)
    if len(key) != KEY_BYTES:
        raise KeyFileError(f"a signing key is {KEY_BYTES} bytes, got {len(key)}")
    if path.exists() and not force:
        raise KeyFileError(f"key file {path} exists; pass --force to replace it (clients using it must be updated)")
    temporary = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    try:
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise KeyFileError(f"cannot write key file {path}: {exc.strerror}") from None
    try:
        with os.fdopen(descriptor, "w") as handle:
            handle.write(key.hex() + "\n")
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(temporary, 0o600)  # O_CREAT's mode is reduced by the umask, never widened; make it exact
        if force:
            os.replace(temporary, path)
        else:
            os.link(temporary, path)  # fails if the file appeared meanwhile: never overwrite silently
    except FileExistsError:
        raise KeyFileError(f"key file {path} exists; pass --force to replace it") from None
    except OSError as exc:
        raise KeyFileError(f"cannot write key file {path}: {exc.strerror}") from None
    finally:
        temporary.unlink(missing_ok=True)


def load_key_file(path: str | Path) -> bytes:
    """The 32-byte secret in ``path``; :class:`KeyFileError` if it is missing, shared or malformed."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            mode = stat.S_IMODE(os.fstat(handle.fileno()).st_mode)
            data = handle.read(_MAX_KEY_FILE_BYTES + 1)
    except FileNotFoundError:
        raise KeyFileError(f"key file {path} does not exist; write one with 'hrlsac keygen {path}'") from None
    except IsADirectoryError:
        raise KeyFileError(f"key file {path} is a directory, not a key file") from None
    except OSError as exc:
        raise KeyFileError(f"cannot read key file {path}: {exc.strerror}") from None
    if mode & 0o077:
        what = "readable" if mode & 0o044 else "writable" if mode & 0o022 else "executable"
        raise KeyFileError(f"key file {path} is {what} by others (mode {mode:04o}); run chmod 600 {path}")
    text = data.removesuffix(b"\n").removesuffix(b"\r")
    if len(text) != 2 * KEY_BYTES or not all(chr(c) in "0123456789abcdefABCDEF" for c in text):
        raise KeyFileError(f"key file {path} is malformed: expected {2 * KEY_BYTES} hexadecimal characters on one "
                           f"line; write a new one with 'hrlsac keygen {path}'")
    return bytes.fromhex(text.decode("ascii"))


# ---------------------------------------------------------------------------------------------- timestamps
def timestamp_from_unix(unix_s: float) -> int:
    """The signing timestamp of a UNIX time."""
    return max(0, int((unix_s - MAVLINK_EPOCH_UNIX_S) * TIMESTAMP_UNITS_PER_S))


def wall_timestamp() -> int:
    """The signing timestamp of now (flights in real time: what pymavlink and PX4 use)."""
    return timestamp_from_unix(time.time())


def simulated_timestamp(clock: Callable[[], float]) -> Callable[[], int]:
    """Signing timestamps from a simulated clock (seconds): simulated time 0 is the MAVLink epoch, so a lockstep
    replay signs with the same timestamps every time and its tlog stays byte-identical."""
    return lambda: int(round(clock() * TIMESTAMP_UNITS_PER_S))


# ---------------------------------------------------------------------------------------------- checking
def frame_signature(key: bytes, signed_part: bytes) -> bytes:
    """The 6-byte signature of a frame whose bytes up to and including the timestamp are ``signed_part``."""
    return hashlib.sha256(key + signed_part).digest()[:6]


class SignatureVerifier:
    """Checks raw frames against one key and keeps the per-stream timestamps (replay protection)."""

    def __init__(self, key: bytes, now: Callable[[], int]):
        self.key = key
        self.now = now
        self.stream_timestamps: dict[tuple[int, int, int], int] = {}

    def check(self, frame: bytes) -> str:
        """One of the verdicts above. The signature is checked before any state changes, so a forged frame
        cannot push a stream's timestamp into the future and lock its genuine sender out."""
        if not frame or frame[0] == MAVLINK1_MARKER:
            return MAVLINK1
        if len(frame) < 3 or not frame[2] & SIGNED_FLAG:
            return UNSIGNED
        if len(frame) < 12 + SIGNATURE_LEN:
            return BAD_SIGNATURE
        if not hmac.compare_digest(frame_signature(self.key, frame[:-6]), frame[-6:]):
            return BAD_SIGNATURE
        stream = (frame[-SIGNATURE_LEN], frame[5], frame[6])  # link id, source system, source component
        timestamp = int.from_bytes(frame[-12:-6], "little")
        last = self.stream_timestamps.get(stream)
        if last is not None and timestamp <= last:
            return REPLAY
        if last is None and timestamp + NEW_STREAM_MAX_AGE < self.now():
            return STALE
        self.stream_timestamps[stream] = timestamp
        return SIGNED


class _ForgetfulDict(dict):
    """A mapping that keeps nothing: pymavlink records a stream's timestamp before checking the signature, so
    forged frames with made-up (link, system, component) would add one entry each, 16 million possible; its
    verdict is not used (SignatureVerifier keeps the streams, after the signature verified)."""

    def __setitem__(self, key, value) -> None:
        pass


class _ClockedSigning:
    """Stands in for pymavlink's ``MAVLinkSigning``: the outgoing timestamp follows a clock.

    pymavlink reads ``signing.timestamp`` for each frame it signs and then adds one; here a read returns the
    larger of the last value and the clock, so timestamps follow the run's time and still strictly increase.
    """

    def __init__(self, key: bytes, link_id: int, now: Callable[[], int]):
        self.secret_key = key
        self.link_id = link_id
        self.sign_outgoing = True
        self._now = now
        self._timestamp = 0
        # Incoming frames are judged by LinkSigning (with counters by reason), not by pymavlink's parser, which
        # moves a stream's timestamp before checking the signature: let its parser pass every frame through.
        self.allow_unsigned_callback = lambda mav, msg_id: True
        self.stream_timestamps: dict = _ForgetfulDict()
        self.sig_count = self.badsig_count = self.goodsig_count = self.unsigned_count = self.reject_count = 0

    @property
    def timestamp(self) -> int:
        return max(self._timestamp, self._now())

    @timestamp.setter
    def timestamp(self, value: int) -> None:
        self._timestamp = value


class LinkSigning:
    """One side's signing: signs what a pymavlink encoder sends, judges what arrives, counts by verdict.

    ``allow_unsigned(msg_id)`` decides which unsigned frames are still accepted (the vehicle: PX4's allow-list;
    the companion computer: everything, with a warning). Wrongly signed and replayed frames are never accepted.
    """

    def __init__(self, key: bytes, now: Callable[[], int], allow_unsigned: Callable[[int], bool]):
        self.now = now
        self.allow_unsigned = allow_unsigned
        self.verifier = SignatureVerifier(key, now)
        self.rejected: Counter[str] = Counter()
        self.accepted_unsigned: Counter[str] = Counter()
        self.accepted_signed = 0
        self._encoders: list = []

    @property
    def key(self) -> bytes:
        return self.verifier.key

    def install(self, mav, link_id: int = 0) -> None:
        """Make the pymavlink ``MAVLink`` object ``mav`` sign everything it sends with our key and clock
        (again if it was installed before: a no-op then)."""
        known = any(encoder is mav for encoder in self._encoders)
        if known and isinstance(mav.signing, _ClockedSigning):
            return
        mav.signing = _ClockedSigning(self.key, link_id, self.now)
        if not known:
            self._encoders.append(mav)

    def replace_key(self, key: bytes, initial_timestamp: int = 0) -> None:
        """Switch to a new key (SETUP_SIGNING): new frames are signed and checked with it, streams start over."""
        self.verifier = SignatureVerifier(key, self.now)
        for mav in self._encoders:
            mav.signing.secret_key = key
            mav.signing.timestamp = max(mav.signing.timestamp, initial_timestamp)

    def admit(self, frame: bytes, msg_id: int, msg_name: str) -> tuple[bool, str]:
        """(accepted, verdict) for one decoded frame; counts it."""
        verdict = self.verifier.check(bytes(frame))
        if verdict == SIGNED:
            self.accepted_signed += 1
            return True, verdict
        if verdict in (UNSIGNED, MAVLINK1) and self.allow_unsigned(msg_id):
            self.accepted_unsigned[msg_name if msg_id >= 0 else "UNKNOWN"] += 1  # bounded: not one per unknown id
            return True, verdict
        self.rejected[verdict] += 1
        return False, verdict

    def summary(self) -> dict:
        """Counts for reports: signed frames accepted, unsigned accepted by type, rejected by reason."""
        return {"accepted_signed": self.accepted_signed,
                "accepted_unsigned": dict(sorted(self.accepted_unsigned.items())),
                "rejected": dict(sorted(self.rejected.items())), "rejected_total": sum(self.rejected.values())}

    def describe_rejections(self) -> str:
        """One line for logs: 'rejected 3 messages (bad_signature 1, unsigned 2)'."""
        total = sum(self.rejected.values())
        detail = ", ".join(f"{reason} {count}" for reason, count in sorted(self.rejected.items()))
        return f"rejected {total} message{'s' if total != 1 else ''}" + (f" ({detail})" if detail else "")
