"""Prometheus metrics of one app instance (its own registry, so tests can run several apps)."""

from __future__ import annotations

from typing import Any

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest

_STEP_BUCKETS = (0.001, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)


class ServiceMetrics:
    """Step times per effect, sessions, stream frames sent and dropped, HTTP requests."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.step_seconds = Histogram(
            "diathermy_step_seconds", "Wall time of one step", buckets=_STEP_BUCKETS, registry=r
        )
        self.effect_seconds = Histogram(
            "diathermy_effect_seconds",
            "Wall time of one effect in one step",
            ["effect"],
            buckets=_STEP_BUCKETS,
            registry=r,
        )
        self.sessions = Gauge("diathermy_sessions", "Sessions known to the server", registry=r)
        self.sessions_loaded = Gauge(
            "diathermy_sessions_loaded", "Sessions held in memory", registry=r
        )
        self.stream_clients = Gauge(
            "diathermy_stream_clients", "Connected WebSocket stream clients", registry=r
        )
        self.frames_sent = Counter("diathermy_stream_frames_sent", "Stream frames sent", registry=r)
        self.frames_dropped = Counter(
            "diathermy_stream_frames_dropped",
            "Stream frames replaced by a newer one before a slow client took them",
            registry=r,
        )
        self.requests = Counter(
            "diathermy_http_requests", "HTTP requests", ["method", "route", "status"], registry=r
        )

    def observe_report(self, report: Any) -> None:
        """Record one step report's wall times."""
        self.step_seconds.observe(float(report.wall_s))
        for name, eff in report.effects.items():
            if eff.ran:
                self.effect_seconds.labels(effect=name).observe(float(eff.wall_s))

    def exposition(self) -> bytes:
        return generate_latest(self.registry)
