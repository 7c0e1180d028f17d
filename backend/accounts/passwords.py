"""Password rules and hashing: argon2id (argon2-cffi's defaults), a minimum length, and a
refusal of common passwords and of ones made of the account's name."""

from __future__ import annotations

import asyncio
import functools

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError

from backend.accounts.common_passwords import COMMON

__all__ = ["DEFAULT_MIN_LENGTH", "hash_password", "password_problem", "verify_password"]

DEFAULT_MIN_LENGTH = 12
MAX_LENGTH = 256
"""Longer is refused: argon2 hashes any length, but nobody types more, and a huge body
would only cost the server time."""

_HASHER = PasswordHasher()


_MADE_EARLIER = (
    "$argon2id$v=19$m=65536,t=3,p=4$PTLfU1V++bSwNGHzW97zWQ"
    "$wlvrK3saa2tX5noxpseJpTWXR3CdOVaD7OUXzlocYbU"
)


@functools.cache
def _dummy() -> str:
    """A hash to check against when an account has none, so it spends the time of a real check.
    Made earlier with today's parameters (hashing at import cost every server process and test
    worker about 0.2 CPU-seconds); made here once if the parameters have changed since."""
    if _HASHER.check_needs_rehash(_MADE_EARLIER):
        return _HASHER.hash("not a password: spends the time of a real check")
    return _MADE_EARLIER


def password_problem(password: str, name: str, min_length: int = DEFAULT_MIN_LENGTH) -> str | None:
    """Why ``password`` may not be used for account ``name`` (None: it may)."""
    if len(password) < min_length:
        return f"a password needs at least {min_length} characters"
    if len(password) > MAX_LENGTH:
        return f"a password may have at most {MAX_LENGTH} characters"
    folded = password.lower()
    if folded in COMMON or folded.rstrip("0123456789!.") in COMMON:
        return "this password is on the list of common passwords: choose another"
    if len(set(folded)) < 4:
        return "this password repeats too few characters: choose another"
    if name and name.lower() in folded:
        return "a password may not contain the account's name"
    return None


async def hash_password(password: str) -> str:
    """The argon2id hash to store (computed off the event loop: it takes tens of ms)."""
    return await asyncio.to_thread(_HASHER.hash, password)


async def verify_password(stored: str, password: str) -> bool:
    """Whether ``password`` matches ``stored``; an account without a password (``stored``
    empty) spends the same time and never matches."""

    def check() -> bool:
        try:
            return _HASHER.verify(stored or _dummy(), password) and bool(stored)
        except (VerificationError, InvalidHashError):
            return False

    return await asyncio.to_thread(check)


def needs_rehash(stored: str) -> bool:
    """True when ``stored`` was made with weaker parameters than today's."""
    return bool(stored) and _HASHER.check_needs_rehash(stored)
