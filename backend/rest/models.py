"""The base of every REST request body: a closed object of strict values.

A third-party client reads the OpenAPI document: ``"type": "integer"`` must not take ``true``
(``{"version": true}`` rolled the site back to version 1) nor ``"2"``, and an object must not
take keys it does not list (``additionalProperties: false``). JSON has no other way to say an
enum's member than its value, so strictness is per model and ``Literal`` is used for choices.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

__all__ = ["RequestBody"]


class RequestBody(BaseModel):
    """Unknown keys refused; no coercion (``true`` is not 1, ``"2"`` not 2, 1 is a number)."""

    model_config = ConfigDict(extra="forbid", strict=True)
