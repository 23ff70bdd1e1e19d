"""``Client`` and ``Session``: the blocking client (``AsyncClient`` is its asyncio twin)."""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import httpx
import numpy as np

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
from diathermy_client._sync_stream import Stream
from diathermy_client._transport import to_response, transport_error

T = TypeVar("T")


class Client:
    """A blocking client of a diathermy server.

    Example::

        with Client("http://127.0.0.1:8000", token="secret") as client:
            session = client.create_session("default", grid=(9, 9, 17))
            session.step(5)
    """

    def __init__(
        self,
        base_url: str | None = None,
        token: str | None = None,
        *,
        timeout_s: float = 30.0,
        retries: int = 3,
        backoff_s: float = 0.2,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        self._core = ClientCore(base_url, token, timeout_s, RetryPolicy(retries, backoff_s))
        self._http = httpx.Client(
            base_url=self._core.base_url or "",
            headers=self._core.headers(),
            timeout=timeout_s,
            transport=transport,
        )

    @property
    def base_url(self) -> str:
        return self._core.base_url or ""

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection pool. Example: ``client.close()``."""
        self._http.close()

    def _send(self, call: Call[T]) -> T:
        req = call.request
        delays = iter(self._core.retry.delays()) if req.idempotent else iter(())
        retried = False
        while True:
            error: DiathermyError | None = None
            resp: Response | None = None
            try:
                r = self._http.request(req.method, req.path, params=req.params, json=req.json)
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
            time.sleep(delay)
            retried = True

    # --- server
    def health(self) -> Health:
        """Liveness. Example: ``(client.health()).status == "ok"``."""
        return self._send(self._core.health())

    def ready(self) -> Health:
        """Readiness: 'ok' once the server scanned its data. Example: ``(client.ready()).status``."""
        return self._send(self._core.ready())

    def list_scenes(self) -> dict[str, Scene]:
        """The built-in scenes by name. Example: ``(client.list_scenes())["default"].grid``."""
        return self._send(self._core.list_scenes())

    # --- sessions
    def create_session(
        self,
        builtin: str | None = None,
        *,
        scene: dict[str, Any] | Scene | None = None,
        grid: tuple[int, int, int] | None = None,
    ) -> Session:
        """A new session from a built-in scene (default 'default') or an inline scene.

        Example: ``s = client.create_session("coagulation", grid=(9, 9, 17))``
        """
        info = self._send(self._core.create_session(builtin, scene=scene, grid=grid))
        return Session(self, info)

    def sessions(self) -> list[Session]:
        """Handles to this token's sessions. Example: ``[s.id for s in client.sessions()]``."""
        return [Session(self, i) for i in self.list_sessions()]

    def session(self, session_id: str) -> Session:
        """A handle to an existing session. Example: ``s = client.session(sid)``."""
        return Session(self, self.get_session(session_id))

    def list_sessions(self) -> list[SessionInfo]:
        """This token's sessions. Example: ``len(client.list_sessions())``."""
        return self._send(self._core.list_sessions())

    def get_session(self, session_id: str) -> SessionInfo:
        """One session's state. Example: ``(client.get_session(sid)).step``."""
        return self._send(self._core.get_session(session_id))

    def delete_session(self, session_id: str) -> None:
        """Stop and delete a session. Example: ``client.delete_session(sid)``."""
        self._send(self._core.delete_session(session_id))

    def step(self, session_id: str, n: int = 1) -> StepResult:
        """Take n steps. Example: ``(client.step(sid, 3)).reports[-1].max_temperature_k``."""
        return self._send(self._core.step(session_id, n))

    def update_electrode(
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

        Example: ``client.update_electrode(sid, position_m=(0.09, 0.05), power_w=30)``
        """
        return self._send(
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

    def list_electrodes(self, session_id: str) -> list[Electrode]:
        """Every electrode now (position, drive, on/off).

        Example: ``(client.list_electrodes(sid))[0].position_m``
        """
        return self._send(self._core.list_electrodes(session_id))

    def get_electrode(self, session_id: str, name: str = "active") -> Electrode:
        """One electrode now. Example: ``(client.get_electrode(sid)).power_w``."""
        return self._send(self._core.get_electrode(session_id, name))

    def read_fields(
        self,
        session_id: str,
        names: Sequence[str] | str,
        *,
        dtype: Dtype = "float32",
        format: str = "msgpack",
    ) -> Fields:
        """Fields as numpy arrays with the grid.

        Example: ``(client.read_fields(sid, ["temperature"]))["temperature"].shape``
        """
        return self._send(self._core.read_fields(session_id, names, dtype=dtype, format=format))

    def read_surface(self, session_id: str) -> Surface:
        """The cut surface. Example: ``(client.read_surface(sid)).vertices_m.shape``."""
        return self._send(self._core.read_surface(session_id))

    def read_vtu(self, session_id: str, path: str | Path | None = None) -> bytes:
        """The state as a ParaView .vtu file (also written to ``path`` if given).

        Example: ``client.read_vtu(sid, "state.vtu")``
        """
        data = self._send(self._core.read_vtu(session_id))
        if path is not None:
            Path(path).write_bytes(data)
        return data

    def take_snapshot(self, session_id: str) -> Snapshot:
        """Save the current state. Example: ``snap = client.take_snapshot(sid)``."""
        return self._send(self._core.take_snapshot(session_id))

    def list_snapshots(self, session_id: str) -> list[Snapshot]:
        """A session's snapshots. Example: ``[s.step for s in client.list_snapshots(sid)]``."""
        return self._send(self._core.list_snapshots(session_id))

    def restore_snapshot(self, session_id: str, snapshot: str | Snapshot) -> SessionInfo:
        """Back to a snapshot. Example: ``client.restore_snapshot(sid, snap)``."""
        return self._send(self._core.restore_snapshot(session_id, snapshot))

    # --- jobs
    def submit_job(self, spec: dict[str, Any]) -> Job:
        """Queue a dataset or training job (a dict with ``kind``; see docs/worker.md).

        Example: ``job = client.submit_job({"kind": "dataset", "config": {"grid": [5, 5, 9]}})``
        """
        return self._send(self._core.submit_job(spec))

    def list_jobs(self, *, state: JobState | None = None, kind: JobKind | None = None) -> list[Job]:
        """This token's jobs, newest first. Example: ``client.list_jobs(state="running")``."""
        return self._send(self._core.list_jobs(state=state, kind=kind))

    def get_job(self, job_id: str) -> Job:
        """One job. Example: ``(client.get_job(job_id)).progress.fraction``."""
        return self._send(self._core.get_job(job_id))

    def cancel_job(self, job_id: str) -> Job:
        """Cancel a queued job at once, a running one within seconds.

        Example: ``client.cancel_job(job_id).cancel_requested``
        """
        return self._send(self._core.cancel_job(job_id))

    def job_log(self, job_id: str, *, after: int = 0) -> list[JobLogLine]:
        """The job's log lines with ``seq > after``. Example: ``[x.line for x in client.job_log(jid)]``."""
        return self._send(self._core.job_log(job_id, after=after))

    def job_events(self, job_id: str, *, timeout_s: float = 600.0) -> Iterator[JobEvent]:
        """The job's server-sent events (``log``, ``progress``, then ``end``), until the server
        ends the stream (at a final state, or ``timeout`` after ``timeout_s``).

        Example::

            for event in client.job_events(job_id):
                if event.event == "progress":
                    print(event.job.progress.fraction)
        """
        req = self._core.job_events(job_id, timeout_s=timeout_s)
        timeout = httpx.Timeout(self._core.timeout_s, read=None)  # the server bounds the stream
        parser = SSEParser()
        try:
            with self._http.stream(req.method, req.path, params=req.params, timeout=timeout) as r:
                if r.status_code >= 400:
                    r.read()
                    check(to_response(r))
                for line in r.iter_lines():
                    event = parser.feed(line)
                    if event is not None:
                        yield event
        except httpx.HTTPError as err:
            raise transport_error(req, err) from err

    def wait_job(self, job_id: str, *, timeout_s: float = 600.0, poll_s: float = 0.5) -> Job:
        """Poll until the job is succeeded, failed or cancelled; raise ``Timeout`` after timeout_s.

        Example: ``assert client.wait_job(job_id, timeout_s=60).state == "succeeded"``
        """
        deadline = time.monotonic() + timeout_s
        while True:
            job = self.get_job(job_id)
            if job.done:
                return job
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(f"job {job_id} still {job.state} after {timeout_s} s")
            time.sleep(min(poll_s, left))

    # --- model registry
    def list_models(self) -> ModelList:
        """Registered models and the active one per grid.

        Example: ``client.list_models().active.get("5x5x9")``
        """
        return self._send(self._core.list_models())

    def get_model(self, name: str, version: int) -> ModelInfo:
        """One registered model. Example: ``client.get_model("tiny", 1).metrics``."""
        return self._send(self._core.get_model(name, version))

    def activate_model(self, name: str, version: int) -> ModelInfo:
        """Make a model the one new CNN sessions on its grid use (unless a scene names one).

        Example: ``client.activate_model("tiny", 1).active``
        """
        return self._send(self._core.activate_model(name, version))

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
    ) -> Stream:
        """The session's stream of frames; see ``Stream``.

        Example::

            with client.stream(sid, ["temperature"]) as stream:
                stream.run(20)
                for frame in stream:
                    print(frame.step, frame["temperature"].max())
        """
        sub = Subscription(tuple(fields), every, dtype, region)
        return Stream(
            self._core,
            session_id,
            sub,
            reconnect=reconnect,
            buffer=buffer,
            timeout_s=timeout_s if timeout_s is not None else self._core.timeout_s,
        )


class Session:
    """A handle to one session for the common flow (step, drive, read, stream).

    Example::

        session = client.create_session("moving-electrode", grid=(9, 9, 17))
        session.set_power(80.0)
        session.step(10)
        temperature = session.field("temperature")
    """

    def __init__(self, client: Client, info: SessionInfo) -> None:
        self.client = client
        self.info = info

    @property
    def id(self) -> str:
        return self.info.id

    def __repr__(self) -> str:
        return f"Session({self.id!r}, step={self.info.step})"

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        """Delete the session on leaving ``with``."""
        self.delete()

    def refresh(self) -> SessionInfo:
        """Re-read the session. Example: ``(session.refresh()).step``."""
        self.info = self.client.get_session(self.id)
        return self.info

    def step(self, n: int = 1) -> StepResult:
        """Take n steps. Example: ``session.step(3)``."""
        return self.client.step(self.id, n)

    def set_electrode(
        self,
        name: str = "active",
        *,
        position_m: tuple[float, float] | None = None,
        power_w: float | None = None,
        current_density_a_per_m2: float | None = None,
        active: bool | None = None,
        max_voltage_v: float | None = None,
    ) -> ElectrodeAck:
        """Change an electrode. Example: ``session.set_electrode(active=False)``."""
        return self.client.update_electrode(
            self.id,
            name,
            position_m=position_m,
            power_w=power_w,
            current_density_a_per_m2=current_density_a_per_m2,
            active=active,
            max_voltage_v=max_voltage_v,
        )

    def electrodes(self) -> list[Electrode]:
        """Every electrode now. Example: ``(session.electrodes())[0].active``."""
        return self.client.list_electrodes(self.id)

    def electrode(self, name: str = "active") -> Electrode:
        """One electrode now. Example: ``(session.electrode()).position_m``."""
        return self.client.get_electrode(self.id, name)

    def move_electrode(self, x_m: float, y_m: float, name: str = "active") -> ElectrodeAck:
        """Move an electrode on the top surface. Example: ``session.move_electrode(0.1, 0.05)``."""
        return self.set_electrode(name, position_m=(x_m, y_m))

    def set_power(self, power_w: float, name: str = "active") -> ElectrodeAck:
        """Re-power an electrode (W). Example: ``session.set_power(0)``."""
        return self.set_electrode(name, power_w=power_w)

    def fields(
        self, names: Sequence[str] | str, *, dtype: Dtype = "float32", format: str = "msgpack"
    ) -> Fields:
        """Several fields. Example: ``(session.fields(["temperature", "level_set"])).grid``."""
        return self.client.read_fields(self.id, names, dtype=dtype, format=format)

    def field(self, name: str, *, dtype: Dtype = "float32") -> np.ndarray:
        """One field. Example: ``(session.field("level_set")).min()``."""
        return (self.fields([name], dtype=dtype))[name]

    def surface(self) -> Surface:
        """The cut surface. Example: ``(session.surface()).is_empty``."""
        return self.client.read_surface(self.id)

    def vtu(self, path: str | Path | None = None) -> bytes:
        """A ParaView .vtu of the state. Example: ``session.vtu("state.vtu")``."""
        return self.client.read_vtu(self.id, path)

    def snapshot(self) -> Snapshot:
        """Save the state. Example: ``snap = session.snapshot()``."""
        return self.client.take_snapshot(self.id)

    def snapshots(self) -> list[Snapshot]:
        """This session's snapshots. Example: ``session.snapshots()``."""
        return self.client.list_snapshots(self.id)

    def restore(self, snapshot: str | Snapshot) -> SessionInfo:
        """Back to a snapshot. Example: ``session.restore(snap)``."""
        self.info = self.client.restore_snapshot(self.id, snapshot)
        return self.info

    def delete(self) -> None:
        """Delete the session. Example: ``session.delete()``."""
        self.client.delete_session(self.id)

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
    ) -> Stream:
        """Frames of this session. Example: ``for frame in session.stream(["temperature"])``."""
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
