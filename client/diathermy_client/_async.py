"""``AsyncClient`` and ``AsyncSession``: the asyncio twins of ``Client`` and ``Session``."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import httpx
import numpy as np

from diathermy_client._async_stream import AsyncStream
from diathermy_client._core import Call, ClientCore, Response, RetryPolicy, SSEParser, check
from diathermy_client._errors import DiathermyError, Timeout
from diathermy_client._models import (
    Dtype,
    Electrode,
    ElectrodeAck,
    Fields,
    Health,
    Job,
    JobEvent,
    JobKind,
    JobLogLine,
    JobState,
    ModelInfo,
    ModelList,
    Region,
    Scene,
    SessionInfo,
    Snapshot,
    StepResult,
    Surface,
    WireDtype,
)
from diathermy_client._stream_core import DEFAULT_RECONNECT, ReconnectPolicy, Subscription
from diathermy_client._transport import to_response, transport_error

T = TypeVar("T")


class AsyncClient:
    """An asyncio client of a diathermy server.

    Example::

        async with AsyncClient("http://127.0.0.1:8000", token="secret") as client:
            session = await client.create_session("default", grid=(9, 9, 17))
            await session.step(5)
    """

    def __init__(
        self,
        base_url: str | None = None,
        token: str | None = None,
        *,
        timeout_s: float = 30.0,
        retries: int = 3,
        backoff_s: float = 0.2,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        self._core = ClientCore(base_url, token, timeout_s, RetryPolicy(retries, backoff_s))
        self._http = httpx.AsyncClient(
            base_url=self._core.base_url or "",
            headers=self._core.headers(),
            timeout=timeout_s,
            transport=transport,
        )

    @property
    def base_url(self) -> str:
        return self._core.base_url or ""

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connection pool. Example: ``await client.aclose()``."""
        await self._http.aclose()

    async def _send(self, call: Call[T]) -> T:
        req = call.request
        delays = iter(self._core.retry.delays()) if req.idempotent else iter(())
        retried = False
        while True:
            error: DiathermyError | None = None
            resp: Response | None = None
            try:
                r = await self._http.request(req.method, req.path, params=req.params, json=req.json)
                resp = to_response(r)
            except httpx.HTTPError as err:
                error = transport_error(req, err)
            status = resp.status if resp is not None else None
            if resp is not None and not self._core.should_retry(call, status):
                return self._core.result(call, resp, retried=retried)
            delay = next(delays, None)
            if delay is None:
                if error is not None:
                    raise error
                assert resp is not None
                return self._core.result(call, resp, retried=retried)
            await asyncio.sleep(delay)
            retried = True

    # --- server
    async def health(self) -> Health:
        """Liveness. Example: ``(await client.health()).status == "ok"``."""
        return await self._send(self._core.health())

    async def ready(self) -> Health:
        """Readiness: 'ok' once the server scanned its data. Example: ``(await client.ready()).status``."""
        return await self._send(self._core.ready())

    async def list_scenes(self) -> dict[str, Scene]:
        """The built-in scenes by name. Example: ``(await client.list_scenes())["default"].grid``."""
        return await self._send(self._core.list_scenes())

    # --- sessions
    async def create_session(
        self,
        builtin: str | None = None,
        *,
        scene: dict[str, Any] | Scene | None = None,
        grid: tuple[int, int, int] | None = None,
    ) -> AsyncSession:
        """A new session from a built-in scene (default 'default') or an inline scene.

        Example: ``s = await client.create_session("coagulation", grid=(9, 9, 17))``
        """
        info = await self._send(self._core.create_session(builtin, scene=scene, grid=grid))
        return AsyncSession(self, info)

    async def sessions(self) -> list[AsyncSession]:
        """Handles to this token's sessions. Example: ``[s.id for s in await client.sessions()]``."""
        return [AsyncSession(self, i) for i in await self.list_sessions()]

    async def session(self, session_id: str) -> AsyncSession:
        """A handle to an existing session. Example: ``s = await client.session(sid)``."""
        return AsyncSession(self, await self.get_session(session_id))

    async def list_sessions(self) -> list[SessionInfo]:
        """This token's sessions. Example: ``len(await client.list_sessions())``."""
        return await self._send(self._core.list_sessions())

    async def get_session(self, session_id: str) -> SessionInfo:
        """One session's state. Example: ``(await client.get_session(sid)).step``."""
        return await self._send(self._core.get_session(session_id))

    async def delete_session(self, session_id: str) -> None:
        """Stop and delete a session. Example: ``await client.delete_session(sid)``."""
        await self._send(self._core.delete_session(session_id))

    async def step(self, session_id: str, n: int = 1) -> StepResult:
        """Take n steps. Example: ``(await client.step(sid, 3)).reports[-1].max_temperature_k``."""
        return await self._send(self._core.step(session_id, n))

    async def update_electrode(
        self,
        session_id: str,
        name: str = "active",
        *,
        position_m: tuple[float, float] | None = None,
        power_w: float | None = None,
        current_density_a_per_m2: float | None = None,
        active: bool | None = None,
        max_voltage_v: float | None = None,
    ) -> ElectrodeAck:
        """Move, re-power or switch an electrode from the next step.

        Example: ``await client.update_electrode(sid, position_m=(0.09, 0.05), power_w=30)``
        """
        return await self._send(
            self._core.update_electrode(
                session_id,
                name,
                position_m=position_m,
                power_w=power_w,
                current_density_a_per_m2=current_density_a_per_m2,
                active=active,
                max_voltage_v=max_voltage_v,
            )
        )

    async def list_electrodes(self, session_id: str) -> list[Electrode]:
        """Every electrode now (position, drive, on/off).

        Example: ``(await client.list_electrodes(sid))[0].position_m``
        """
        return await self._send(self._core.list_electrodes(session_id))

    async def get_electrode(self, session_id: str, name: str = "active") -> Electrode:
        """One electrode now. Example: ``(await client.get_electrode(sid)).power_w``."""
        return await self._send(self._core.get_electrode(session_id, name))

    async def read_fields(
        self,
        session_id: str,
        names: Sequence[str] | str,
        *,
        dtype: Dtype = "float32",
        format: str = "msgpack",
    ) -> Fields:
        """Fields as numpy arrays with the grid.

        Example: ``(await client.read_fields(sid, ["temperature"]))["temperature"].shape``
        """
        return await self._send(
            self._core.read_fields(session_id, names, dtype=dtype, format=format)
        )

    async def read_surface(self, session_id: str) -> Surface:
        """The cut surface. Example: ``(await client.read_surface(sid)).vertices_m.shape``."""
        return await self._send(self._core.read_surface(session_id))

    async def read_vtu(self, session_id: str, path: str | Path | None = None) -> bytes:
        """The state as a ParaView .vtu file (also written to ``path`` if given).

        Example: ``await client.read_vtu(sid, "state.vtu")``
        """
        data = await self._send(self._core.read_vtu(session_id))
        if path is not None:
            Path(path).write_bytes(data)
        return data

    async def take_snapshot(self, session_id: str) -> Snapshot:
        """Save the current state. Example: ``snap = await client.take_snapshot(sid)``."""
        return await self._send(self._core.take_snapshot(session_id))

    async def list_snapshots(self, session_id: str) -> list[Snapshot]:
        """A session's snapshots. Example: ``[s.step for s in await client.list_snapshots(sid)]``."""
        return await self._send(self._core.list_snapshots(session_id))

    async def restore_snapshot(self, session_id: str, snapshot: str | Snapshot) -> SessionInfo:
        """Back to a snapshot. Example: ``await client.restore_snapshot(sid, snap)``."""
        return await self._send(self._core.restore_snapshot(session_id, snapshot))

    # --- jobs
    async def submit_job(self, spec: dict[str, Any]) -> Job:
        """Queue a dataset or training job (a dict with ``kind``; see docs/worker.md).

        Example: ``job = await client.submit_job({"kind": "dataset", "config": {"grid": [5, 5, 9]}})``
        """
        return await self._send(self._core.submit_job(spec))

    async def list_jobs(
        self, *, state: JobState | None = None, kind: JobKind | None = None
    ) -> list[Job]:
        """This token's jobs, newest first. Example: ``await client.list_jobs(state="running")``."""
        return await self._send(self._core.list_jobs(state=state, kind=kind))

    async def get_job(self, job_id: str) -> Job:
        """One job. Example: ``(await client.get_job(job_id)).progress.fraction``."""
        return await self._send(self._core.get_job(job_id))

    async def cancel_job(self, job_id: str) -> Job:
        """Cancel a queued job at once, a running one within seconds.

        Example: ``(await client.cancel_job(job_id)).cancel_requested``
        """
        return await self._send(self._core.cancel_job(job_id))

    async def job_log(self, job_id: str, *, after: int = 0) -> list[JobLogLine]:
        """The job's log lines with ``seq > after``. Example: ``[x.line for x in await client.job_log(jid)]``."""
        return await self._send(self._core.job_log(job_id, after=after))

    async def job_events(self, job_id: str, *, timeout_s: float = 600.0) -> AsyncIterator[JobEvent]:
        """The job's server-sent events (``log``, ``progress``, then ``end``), until the server
        ends the stream (at a final state, or ``timeout`` after ``timeout_s``).

        Example::

            async for event in client.job_events(job_id):
                if event.event == "progress":
                    print(event.job.progress.fraction)
        """
        req = self._core.job_events(job_id, timeout_s=timeout_s)
        timeout = httpx.Timeout(self._core.timeout_s, read=None)  # the server bounds the stream
        parser = SSEParser()
        try:
            async with self._http.stream(
                req.method, req.path, params=req.params, timeout=timeout
            ) as r:
                if r.status_code >= 400:
                    await r.aread()
                    check(to_response(r))
                async for line in r.aiter_lines():
                    event = parser.feed(line)
                    if event is not None:
                        yield event
        except httpx.HTTPError as err:
            raise transport_error(req, err) from err

    async def wait_job(self, job_id: str, *, timeout_s: float = 600.0, poll_s: float = 0.5) -> Job:
        """Poll until the job is succeeded, failed or cancelled; raise ``Timeout`` after timeout_s.

        Example: ``assert (await client.wait_job(job_id, timeout_s=60)).state == "succeeded"``
        """
        deadline = time.monotonic() + timeout_s
        while True:
            job = await self.get_job(job_id)
            if job.done:
                return job
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(f"job {job_id} still {job.state} after {timeout_s} s")
            await asyncio.sleep(min(poll_s, left))

    # --- model registry
    async def list_models(self) -> ModelList:
        """Registered models and the active one per grid.

        Example: ``(await client.list_models()).active.get("5x5x9")``
        """
        return await self._send(self._core.list_models())

    async def get_model(self, name: str, version: int) -> ModelInfo:
        """One registered model. Example: ``(await client.get_model("tiny", 1)).metrics``."""
        return await self._send(self._core.get_model(name, version))

    async def activate_model(self, name: str, version: int) -> ModelInfo:
        """Make a model the one new CNN sessions on its grid use (unless a scene names one).

        Example: ``(await client.activate_model("tiny", 1)).active``
        """
        return await self._send(self._core.activate_model(name, version))

    def stream(
        self,
        session_id: str,
        fields: Sequence[str] = (),
        *,
        every: int = 1,
        dtype: WireDtype = "float32",
        region: Region = "volume",
        reconnect: ReconnectPolicy | None = DEFAULT_RECONNECT,
        buffer: int = 16,
        timeout_s: float | None = None,
    ) -> AsyncStream:
        """The session's stream of frames; see ``AsyncStream``.

        Example::

            async with client.stream(sid, ["temperature"]) as stream:
                await stream.run(20)
                async for frame in stream:
                    print(frame.step, frame["temperature"].max())
        """
        sub = Subscription(tuple(fields), every, dtype, region)
        return AsyncStream(
            self._core,
            session_id,
            sub,
            reconnect=reconnect,
            buffer=buffer,
            timeout_s=timeout_s if timeout_s is not None else self._core.timeout_s,
        )


class AsyncSession:
    """A handle to one session for the common flow (step, drive, read, stream).

    Example::

        session = await client.create_session("moving-electrode", grid=(9, 9, 17))
        await session.set_power(80.0)
        await session.step(10)
        temperature = await session.field("temperature")
    """

    def __init__(self, client: AsyncClient, info: SessionInfo) -> None:
        self.client = client
        self.info = info

    @property
    def id(self) -> str:
        return self.info.id

    def __repr__(self) -> str:
        return f"AsyncSession({self.id!r}, step={self.info.step})"

    async def __aenter__(self) -> AsyncSession:
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Delete the session on leaving ``async with``."""
        await self.delete()

    async def refresh(self) -> SessionInfo:
        """Re-read the session. Example: ``(await session.refresh()).step``."""
        self.info = await self.client.get_session(self.id)
        return self.info

    async def step(self, n: int = 1) -> StepResult:
        """Take n steps. Example: ``await session.step(3)``."""
        return await self.client.step(self.id, n)

    async def set_electrode(
        self,
        name: str = "active",
        *,
        position_m: tuple[float, float] | None = None,
        power_w: float | None = None,
        current_density_a_per_m2: float | None = None,
        active: bool | None = None,
        max_voltage_v: float | None = None,
    ) -> ElectrodeAck:
        """Change an electrode. Example: ``await session.set_electrode(active=False)``."""
        return await self.client.update_electrode(
            self.id,
            name,
            position_m=position_m,
            power_w=power_w,
            current_density_a_per_m2=current_density_a_per_m2,
            active=active,
            max_voltage_v=max_voltage_v,
        )

    async def electrodes(self) -> list[Electrode]:
        """Every electrode now. Example: ``(await session.electrodes())[0].active``."""
        return await self.client.list_electrodes(self.id)

    async def electrode(self, name: str = "active") -> Electrode:
        """One electrode now. Example: ``(await session.electrode()).position_m``."""
        return await self.client.get_electrode(self.id, name)

    async def move_electrode(self, x_m: float, y_m: float, name: str = "active") -> ElectrodeAck:
        """Move an electrode on the top surface. Example: ``await session.move_electrode(0.1, 0.05)``."""
        return await self.set_electrode(name, position_m=(x_m, y_m))

    async def set_power(self, power_w: float, name: str = "active") -> ElectrodeAck:
        """Re-power an electrode (W). Example: ``await session.set_power(0)``."""
        return await self.set_electrode(name, power_w=power_w)

    async def fields(
        self, names: Sequence[str] | str, *, dtype: Dtype = "float32", format: str = "msgpack"
    ) -> Fields:
        """Several fields. Example: ``(await session.fields(["temperature", "level_set"])).grid``."""
        return await self.client.read_fields(self.id, names, dtype=dtype, format=format)

    async def field(self, name: str, *, dtype: Dtype = "float32") -> np.ndarray:
        """One field. Example: ``(await session.field("level_set")).min()``."""
        return (await self.fields([name], dtype=dtype))[name]

    async def surface(self) -> Surface:
        """The cut surface. Example: ``(await session.surface()).is_empty``."""
        return await self.client.read_surface(self.id)

    async def vtu(self, path: str | Path | None = None) -> bytes:
        """A ParaView .vtu of the state. Example: ``await session.vtu("state.vtu")``."""
        return await self.client.read_vtu(self.id, path)

    async def snapshot(self) -> Snapshot:
        """Save the state. Example: ``snap = await session.snapshot()``."""
        return await self.client.take_snapshot(self.id)

    async def snapshots(self) -> list[Snapshot]:
        """This session's snapshots. Example: ``await session.snapshots()``."""
        return await self.client.list_snapshots(self.id)

    async def restore(self, snapshot: str | Snapshot) -> SessionInfo:
        """Back to a snapshot. Example: ``await session.restore(snap)``."""
        self.info = await self.client.restore_snapshot(self.id, snapshot)
        return self.info

    async def delete(self) -> None:
        """Delete the session. Example: ``await session.delete()``."""
        await self.client.delete_session(self.id)

    def stream(
        self,
        fields: Sequence[str] = (),
        *,
        every: int = 1,
        dtype: WireDtype = "float32",
        region: Region = "volume",
        reconnect: ReconnectPolicy | None = DEFAULT_RECONNECT,
        buffer: int = 16,
        timeout_s: float | None = None,
    ) -> AsyncStream:
        """Frames of this session. Example: ``async for frame in session.stream(["temperature"])``."""
        return self.client.stream(
            self.id,
            fields,
            every=every,
            dtype=dtype,
            region=region,
            reconnect=reconnect,
            buffer=buffer,
            timeout_s=timeout_s,
        )
