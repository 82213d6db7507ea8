"""API keys: loading, hashing, constant-time checks, and the rule for running without keys.

Keys come from ``CURVATURE_API_KEYS`` (comma-separated) and ``CURVATURE_API_KEYS_FILE`` (one a
line). Only their HMAC-SHA256 digests are kept: in memory to check requests, and in the job
store as the owner of each job, so neither a memory dump of the key ring nor the database
gives a key back. Without keys every caller is the same anonymous owner, which is only safe on
a loopback address (:func:`check_exposure`).
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import re
from dataclasses import dataclass
from pathlib import Path

from .settings import Settings

ANONYMOUS = "anonymous"
# Domain separation: the digest of a key here is useless as the digest of anything else.
_HMAC_KEY = b"curvature-service/api-key/v1"
# RFC 6750 token characters; 16 characters at least, so a key cannot be guessed by trying.
KEY_PATTERN = re.compile(r"[A-Za-z0-9._~+/=-]{16,512}")
MAX_TOKEN_LENGTH = 512


class KeyConfigError(ValueError):
    """The configured keys are unusable (bad characters, too short, unreadable file)."""


def key_digest(key: str) -> str:
    """The owner id of ``key``: hex HMAC-SHA256 under a fixed service key."""
    return hmac.new(_HMAC_KEY, key.encode("utf-8"), hashlib.sha256).hexdigest()


@dataclass(frozen=True)
class KeyRing:
    """Digests of the accepted keys; empty means the service is open (anonymous owner)."""

    digests: tuple[str, ...] = ()

    @property
    def enabled(self) -> bool:
        return bool(self.digests)

    def owner_of(self, token: str) -> str | None:
        """The owner id of a presented token, or ``None`` when no configured key matches.

        Every configured digest is compared, with :func:`hmac.compare_digest`, whatever
        matched first: the time taken says nothing about which key, or how much of one, was
        right.
        """
        if not token or len(token) > MAX_TOKEN_LENGTH:
            return None
        digest = key_digest(token)
        found = False
        for known in self.digests:
            found |= hmac.compare_digest(digest, known)
        return digest if found else None


def _check_key(key: str, where: str) -> str:
    if not KEY_PATTERN.fullmatch(key):
        # Never echo the key itself: it may be a real secret with a typo.
        raise KeyConfigError(
            f"{where}: an API key must be 16 to 512 characters from A-Z a-z 0-9 . _ ~ + / = -"
            f" (this one has {len(key)} characters)")
    return key


def load_keyring(settings: Settings) -> KeyRing:
    """Read and hash the keys of ``settings``.

    Raises
    ------
    KeyConfigError
        A key is malformed, or the key file cannot be read or holds no key.
    """
    keys: list[str] = []
    if settings.api_keys is not None:
        raw = settings.api_keys.get_secret_value()
        for i, key in enumerate(k.strip() for k in raw.split(",")):
            if key:
                keys.append(_check_key(key, f"CURVATURE_API_KEYS entry {i + 1}"))
    if settings.api_keys_file is not None:
        path = Path(settings.api_keys_file)
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise KeyConfigError(f"CURVATURE_API_KEYS_FILE {path}: cannot read it "
                                 f"({type(exc).__name__}: {exc})") from None
        found = 0
        for number, line in enumerate(lines, 1):
            key = line.strip()
            if key and not key.startswith("#"):
                keys.append(_check_key(key, f"{path} line {number}"))
                found += 1
        if not found:
            raise KeyConfigError(f"CURVATURE_API_KEYS_FILE {path}: no key in the file")
    return KeyRing(tuple(sorted({key_digest(k) for k in keys})))


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip().strip("[]")).is_loopback
    except ValueError:
        return False  # any other host name may resolve to a public interface


def check_exposure(settings: Settings, keyring: KeyRing) -> str | None:
    """Why the service must not start as configured, or ``None`` when it may.

    Without keys anyone who reaches the port can read every job, so the service binds a
    loopback address only, unless ``allow_open`` says the operator wants it open.
    """
    if keyring.enabled or is_loopback(settings.host) or settings.allow_open:
        return None
    return (f"refusing to listen on {settings.host} without API keys: anyone reaching the port "
            "could read and delete every job. Set CURVATURE_API_KEYS or "
            "CURVATURE_API_KEYS_FILE, listen on 127.0.0.1, or set CURVATURE_ALLOW_OPEN=true "
            "to run open on purpose.")
