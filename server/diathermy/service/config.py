"""The service's settings: one pydantic-settings object, read from ``DIATHERMY_*`` variables."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from diathermy.service.cpus import check_engine_cpus, parse_cpus


class Settings(BaseSettings):
    """Everything the server can be told; the CLI overrides what it is given on top of these."""

    model_config = SettingsConfigDict(env_prefix="DIATHERMY_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    data_dir: Path = Path("diathermy-data")
    tokens: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="bearer tokens (comma-separated in DIATHERMY_TOKENS); 'sha256:<hex>' entries "
        "are already hashed",
    )
    token_file: Path | None = Field(
        default=None, description="one token (or sha256:<hex>) per line"
    )
    auth_disabled: bool = Field(
        default=False, description="serve without auth: everyone is 'anonymous'"
    )

    max_grid_nodes: int = Field(
        default=500_000,
        ge=27,
        description="most nodes a session's grid may have; the default admits every built-in "
        "scene (the largest, fixed-electrode, has 445,900)",
    )
    max_memory_bytes: int = Field(
        default=8 * 2**30,
        ge=1,
        description="most memory a session's engine is estimated to need before it allocates; "
        "the default admits every built-in scene (fixed-electrode: ~7.0 GiB)",
    )
    max_steps_per_request: int = Field(default=200, ge=1)
    max_sessions_per_token: int = Field(default=8, ge=1)
    max_active_jobs_per_token: int = Field(
        default=16, ge=1, description="queued plus running dataset/training jobs per token"
    )
    max_request_bytes: int = Field(default=1_000_000, ge=1024)
    max_message_bytes: int = Field(default=65_536, ge=256)
    max_stream_rate_hz: float = Field(default=60.0, gt=0)
    autosave_interval_s: float = Field(
        default=30.0, gt=0, description="checkpoint sessions this often"
    )
    journal_fsync: bool = Field(
        default=False,
        description="fsync the session journal after every command: survives power loss too, "
        "not only a killed process, at the cost of one disk sync per step",
    )
    engine_cpus: Annotated[list[int], NoDecode] = Field(
        default_factory=list,
        description="CPUs the engine processes run on, as taskset -c takes them ('1', '2-3,6'); "
        "the server process runs on the others it may use. Empty (the default): no placement",
    )
    log_level: str = "INFO"

    @field_validator("tokens", mode="before")
    @classmethod
    def _split(cls, value: object) -> object:
        if isinstance(value, str):
            return [t.strip() for t in value.split(",") if t.strip()]
        return value

    @field_validator("engine_cpus", mode="before")
    @classmethod
    def _cpu_list(cls, value: object) -> object:
        return parse_cpus(value) if isinstance(value, str) else value

    @field_validator("engine_cpus")
    @classmethod
    def _cpus_available(cls, value: list[int]) -> list[int]:
        return check_engine_cpus(value)
