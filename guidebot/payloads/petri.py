"""Payload models of the petri messages (registered by type name)."""

from __future__ import annotations

from guidebot.messages import PayloadModel, register_payload

__all__ = ["PayloadModel", "register_payload"]
