"""Bearer tokens: known only by their sha256 hashes, compared in constant time."""

from __future__ import annotations

import hashlib
import hmac
import logging
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from diathermy.service.config import Settings
from diathermy.service.exceptions import AuthError

ANONYMOUS = "anonymous"
"""The owner of every session when auth is disabled."""

_HASH_PREFIX = "sha256:"
log = logging.getLogger("diathermy.service.auth")


def hash_token(token: str) -> str:
    """The hex sha256 of a token: what the server keeps and writes next to sessions."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def _entry_hash(entry: str) -> str:
    entry = entry.strip()
    if entry.startswith(_HASH_PREFIX):
        digest = entry[len(_HASH_PREFIX) :].lower()
        if len(digest) != 64 or any(c not in "0123456789abcdef" for c in digest):
            raise ValueError(f"token entry {entry[:16]}... is not sha256:<64 hex digits>")
        return digest
    if not entry:
        raise ValueError("empty token")
    return hash_token(entry)


def read_token_file(path: Path) -> list[str]:
    """Token entries of a file: one per line, blank lines and '#' comments skipped."""
    lines = path.read_text(encoding="utf-8").splitlines()
    return [ln.strip() for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]


@dataclass(frozen=True)
class TokenStore:
    """The hashes of the tokens the server accepts; ``disabled`` lets everyone in as anonymous."""

    hashes: frozenset[str]
    disabled: bool = False

    @classmethod
    def from_entries(cls, entries: Iterable[str], *, disabled: bool = False) -> TokenStore:
        return cls(hashes=frozenset(_entry_hash(e) for e in entries), disabled=disabled)

    @classmethod
    def from_settings(cls, settings: Settings) -> TokenStore:
        """Tokens from the settings and the token file; no tokens without ``auth_disabled`` fails."""
        entries = list(settings.tokens)
        if settings.token_file is not None:
            entries += read_token_file(settings.token_file)
        store = cls.from_entries(entries, disabled=settings.auth_disabled)
        if not store.disabled and not store.hashes:
            raise ValueError(
                "no bearer tokens configured: set DIATHERMY_TOKENS, --token or --token-file "
                "(or --no-auth to serve without authentication)"
            )
        return store

    def warn_if_disabled(self) -> None:
        if self.disabled:
            log.warning("authentication is DISABLED: every client is 'anonymous' and sees all")

    def owner(self, authorization: str | None) -> str:
        """The owner id (token hash) of an ``Authorization: Bearer <token>`` value."""
        if self.disabled:
            return ANONYMOUS
        if not authorization:
            raise AuthError("missing bearer token (Authorization: Bearer <token>)")
        scheme, _, token = authorization.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            raise AuthError("the Authorization header must be 'Bearer <token>'")
        digest = hash_token(token.strip())
        for known in self.hashes:
            if hmac.compare_digest(known, digest):
                return known
        raise AuthError("unknown bearer token")
