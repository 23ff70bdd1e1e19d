"""Builds the app: settings, state, middleware, error handlers, routers, start-up and shutdown."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator

import anyio.to_thread
from fastapi import FastAPI

from diathermy.service.auth import TokenStore
from diathermy.service.config import Settings
from diathermy.service.engine import DefaultEngine, EngineAdapter
from diathermy.service.errors import install_error_handlers
from diathermy.service.metrics import ServiceMetrics
from diathermy.service.middleware import LimitAndLogMiddleware
from diathermy.service.registry import SessionRegistry
from diathermy.service.routes import (
    electrodes,
    fields,
    health,
    jobs,
    models,
    reports,
    scenes,
    sessions,
    stream,
)
from diathermy.service.routes.viewer import mount_viewer
from diathermy.service.sessions import save_dirty
from diathermy.service.state import AppState
from diathermy.version import __version__
from diathermy.worker.queue import JobQueue

log = logging.getLogger("diathermy.service")


async def _autosave(state: AppState) -> None:
    while True:
        await asyncio.sleep(state.settings.autosave_interval_s)
        try:
            await save_dirty(registry=state.registry)
        except Exception:
            log.exception("autosave failed")


def create_app(settings: Settings | None = None, *, engine: EngineAdapter | None = None) -> FastAPI:
    """The FastAPI app; ``engine`` replaces the default engine (tests, other backends)."""
    settings = settings or Settings()
    state = AppState(
        settings=settings,
        tokens=TokenStore.from_settings(settings),
        registry=SessionRegistry(
            settings.data_dir,
            engine or DefaultEngine(settings.data_dir),
            fsync=settings.journal_fsync,
            engine_cpus=settings.engine_cpus,
        ),
        metrics=ServiceMetrics(),
    )
    sessions_ = state.registry.sessions
    state.metrics.sessions.set_function(lambda: len(sessions_))
    state.metrics.sessions_loaded.set_function(
        lambda: sum(r.sim is not None and not r.sim.failed for r in list(sessions_.values()))
    )

    @contextlib.asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        state.tokens.warn_if_disabled()
        n = await anyio.to_thread.run_sync(state.registry.scan)
        state.ready = True
        log.info("ready", extra={"sessions": n, "data_dir": str(settings.data_dir)})
        saver = asyncio.create_task(_autosave(state))
        try:
            yield
        finally:
            state.ready = False
            saver.cancel()
            for rec in list(state.registry.sessions.values()):
                if rec.driver is not None:
                    await rec.driver.stop()
            try:
                saved = await save_dirty(registry=state.registry)
            finally:
                await anyio.to_thread.run_sync(state.registry.close_all)
            log.info("stopped", extra={"saved_sessions": saved})

    app = FastAPI(
        title="diathermy",
        version=__version__,
        description="Electrosurgery simulation sessions over REST and WebSocket. "
        "Stream wire format: docs/service.md and openapi/stream-messages.json.",
        lifespan=lifespan,
    )
    app.state.diathermy = state
    app.state.diathermy_jobs = JobQueue(settings.data_dir)
    app.add_middleware(
        LimitAndLogMiddleware, max_bytes=settings.max_request_bytes, metrics=state.metrics
    )
    install_error_handlers(app)
    for module in (health, scenes, sessions, electrodes, fields, stream, jobs, models, reports):
        app.include_router(module.router)
    mount_viewer(app)
    return app
