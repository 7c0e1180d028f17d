"""The paper's anti-spurious rule: an input counts as active only after staying active for
``filter_s`` (200 ms by default). Releases count at once.

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

    __slots__ = ("_since", "filter_s", "value")

    def __init__(self, filter_s: float, value: int = 0) -> None:
        if filter_s < 0:
            raise ValueError(f"filter must be >= 0 s, got {filter_s}")
        self.filter_s = filter_s
        self.value = value
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
        if raw and not self.value:
            if self._since is None:
                self._since = t
            if t - self._since + TOLERANCE_S < self.filter_s:
                return None
        self._since = None
        self.value = raw
        return raw
