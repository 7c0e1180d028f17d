"""GuideBot: fleet software for tour-guide robots (shared envelope, bus, hub client and CLI)."""

__version__ = "0.1.0"
