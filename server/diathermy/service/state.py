"""What one app instance holds: settings, tokens, sessions, metrics, start-up progress."""

from __future__ import annotations

from dataclasses import dataclass

from diathermy.service.auth import TokenStore
from diathermy.service.config import Settings
from diathermy.service.metrics import ServiceMetrics
from diathermy.service.registry import SessionRegistry


@dataclass
class AppState:
    settings: Settings
    tokens: TokenStore
    registry: SessionRegistry
    metrics: ServiceMetrics
    ready: bool = False
