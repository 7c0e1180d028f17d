"""The paper's anti-spurious rule: an input counts as active only after staying active for
``filter_s`` (200 ms by default). Releases count at once. Active is 1 (a press), or 0 for a
fire alarm's normally-closed contact (a cut wire alarms): the alarm is what must hold.

Because inputs are sampled, a press is seen for sure only when it lasts at least
``filter_s + period``; a pulse shorter than ``filter_s`` is never seen.
"""

from __future__ import annotations

__all__ = ["InputFilter"]

# Samples are taken on a period grid with a little jitter: two samples one filter apart may
# read as 199.9 ms. Up to this much short still counts.
TOLERANCE_S = 0.002


class InputFilter:
    """Debounce of one input from timestamped samples (seconds, monotonic)."""

    __slots__ = ("_since", "active", "filter_s", "value")

    def __init__(self, filter_s: float, value: int = 0, *, active: int = 1) -> None:
        if filter_s < 0:
            raise ValueError(f"filter must be >= 0 s, got {filter_s}")
        self.filter_s = filter_s
        self.value = value
        self.active = active
        """The value that must hold ``filter_s`` to count; a change away from it counts at once."""
        self._since: float | None = None

    @property
    def pending(self) -> bool:
        """A change is being timed (seen, not yet accepted)."""
        return self._since is not None

    def update(self, raw: int, t: float) -> int | None:
        """Feed one sample; returns the new accepted value when it changes, else None."""
        if raw == self.value:
            self._since = None
            return None
        if raw == self.active:
            if self._since is None:
                self._since = t
            if t - self._since + TOLERANCE_S < self.filter_s:
                return None
        self._since = None
        self.value = raw
        return raw
