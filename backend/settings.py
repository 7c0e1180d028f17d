"""Server settings from the environment (prefix ``GUIDEBOT_``) and command-line flags.

Nothing is read at import time: ``Settings()`` reads the environment when it is built, so tests
pass their own instance to ``create_app(settings)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from backend.auth import Role

__all__ = ["DEFAULT_ADMIN_TOKEN", "Settings", "StaticToken"]

# Good enough on a developer's laptop, refused anywhere else (see Settings._refuse_default_secrets).
DEFAULT_ADMIN_TOKEN = "dev-admin-token"

WEB_DIR = Path(__file__).resolve().parent.parent / "web"


class StaticToken(BaseModel):
    """A bearer token known from configuration: who holds it and in which role."""

    token: str = Field(min_length=8)
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")
    role: Role


class Settings(BaseSettings):
    """Everything the server needs to start; ``GUIDEBOT_TOKENS`` is a JSON list of tokens."""

    model_config = SettingsConfigDict(env_prefix="GUIDEBOT_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    db_url: str = "sqlite+aiosqlite:///./guidebot.db"
    site: Path | None = None
    environment: Literal["development", "production"] = "development"
    admin_token: str = DEFAULT_ADMIN_TOKEN
    tokens: list[StaticToken] = Field(default_factory=list)
    metrics_token: str | None = Field(default=None, min_length=8)
    """Bearer token that may only read GET /metrics (docs/metrics.md)."""
    web_dir: Path = WEB_DIR
    # Hub (docs/protocol.md): per-client outbound queue, batching and limits.
    hub_queue_size: int = Field(default=4096, ge=8)
    hub_coalesce_after: int = Field(default=256, ge=0)
    hub_batch_max: int = Field(default=512, ge=1)
    hub_linger_ms: float = Field(default=5.0, ge=0, le=100)
    hub_max_message_bytes: int = Field(default=1 << 20, ge=1024)
    log_level: str = "info"
    # BuildingInterface (docs/building.md): poll the site's Modbus modules; input filter.
    building_enabled: bool = True
    building_filter_ms: float = Field(default=200.0, ge=0, le=5000)

    @model_validator(mode="after")
    def _refuse_default_secrets(self) -> Settings:
        if self.environment != "development" and self.admin_token == DEFAULT_ADMIN_TOKEN:
            raise ValueError(
                "GUIDEBOT_ADMIN_TOKEN must be set to a secret outside development "
                f"(environment={self.environment!r})"
            )
        if len(self.admin_token) < 8:
            raise ValueError("GUIDEBOT_ADMIN_TOKEN must be at least 8 characters")
        return self
