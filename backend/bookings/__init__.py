"""Booked and recurring tours (docs/server.md, "Bookings"): staff book a tour or a single
point's visit for a date and time in the venue's time zone, once or recurring; the leader's
scheduler starts each occurrence exactly once and tells staff in time when one cannot be served.
"""

from backend.bookings.model import Booking, BookingError, BookingRequest

__all__ = ["Booking", "BookingError", "BookingRequest"]
