"""The hash an account without a password is checked against: made earlier, so no process spends
an argon2 hash at import, and with today's parameters, so the check takes a real check's time."""

from __future__ import annotations

from backend.accounts import passwords


def test_the_dummy_hash_has_today_s_parameters_and_matches_nothing() -> None:
    assert passwords._dummy() == passwords._MADE_EARLIER
    assert not passwords._HASHER.check_needs_rehash(passwords._dummy())


async def test_an_account_without_a_password_never_signs_in() -> None:
    assert not await passwords.verify_password(
        "", "not a password: spends the time of a real check"
    )
    assert not await passwords.verify_password("", "")
