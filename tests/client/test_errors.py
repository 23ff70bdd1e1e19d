"""Each SDK error type from a real server, timeouts, and retries of idempotent calls only."""

from __future__ import annotations

import json
import threading

import httpx
import pytest

from diathermy_client import (
    AuthError,
    Client,
    Conflict,
    DiathermyError,
    InvalidRequest,
    LimitExceeded,
    NotFound,
    ServerError,
    Timeout,
    TransportError,
)
from tests.client.conftest import QUICK_CUT_SCENE, SMALL_GRID, TOKEN_B, LiveServer
from tests.service.conftest import free_port


def test_error_types_from_a_live_server(live: LiveServer, client: Client) -> None:
    with Client(live.url, "wrong") as bad, pytest.raises(AuthError) as info:
        bad.list_sessions()
    assert info.value.status == 401 and info.value.code == "unauthorized"
    s = client.create_session("default", grid=SMALL_GRID)
    with Client(live.url, TOKEN_B) as other, pytest.raises(NotFound):
        other.get_session(s.id)  # another token's session looks missing
    with pytest.raises(NotFound) as nf:
        client.restore_snapshot(s.id, "nope")
    assert nf.value.field == "snapshot_id"
    with pytest.raises(InvalidRequest) as bad_value:
        s.set_power(-1.0)
    assert bad_value.value.field == "body.power_w" and bad_value.value.status == 422
    with pytest.raises(NotFound) as bad_name:  # a missing electrode is a missing resource
        s.set_electrode("ghost", power_w=1.0)
    assert bad_name.value.field == "name" and bad_name.value.status == 404
    with pytest.raises(InvalidRequest) as bad_field:
        s.fields(["temperature", "nope"])
    assert bad_field.value.status == 400 and bad_field.value.field == "fields"
    with pytest.raises(LimitExceeded) as big:
        client.create_session("default", grid=(33, 33, 65))
    assert big.value.field == "scene.grid" and "MiB" in big.value.message
    with pytest.raises(LimitExceeded):
        s.step(51)
    with pytest.raises(InvalidRequest) as bad_scene:
        client.create_session("no-such-scene")
    assert "builtin" in str(bad_scene.value)


def test_conflict_and_timeout_on_a_slow_step(live: LiveServer, client: Client) -> None:
    slow = client.create_session(scene=QUICK_CUT_SCENE)
    t = threading.Thread(target=lambda: client.step(slow.id, 15))
    t.start()
    rec = live.state.registry.sessions[slow.id]
    for _ in range(200):
        if rec.lock.locked():
            break
        threading.Event().wait(0.01)
    with pytest.raises(Conflict) as busy:
        client.step(slow.id)
    assert busy.value.status == 409 and busy.value.code == "busy"
    t.join()
    with Client(live.url, client._core.token, timeout_s=0.05) as hasty, pytest.raises(Timeout):
        hasty.step(slow.id, 15)  # a POST: not retried, the timeout is the answer


def test_transport_error_when_nobody_listens() -> None:
    with Client(f"http://127.0.0.1:{free_port()}", "t", retries=1, backoff_s=0.01) as c:
        with pytest.raises(TransportError):
            c.health()


def mock_client(handler: object, **kw: object) -> Client:
    return Client("http://test", "t", transport=httpx.MockTransport(handler), **kw)  # type: ignore[arg-type]


def test_idempotent_calls_are_retried_with_backoff_others_are_not() -> None:
    calls: list[str] = []

    def flaky(request: httpx.Request) -> httpx.Response:
        calls.append(request.method)
        if len(calls) < 3:
            return httpx.Response(503, json={"error": "starting", "message": "not ready"})
        return httpx.Response(200, json={"sessions": []})

    with mock_client(flaky, retries=3, backoff_s=0.001) as c:
        assert c.list_sessions() == []
    assert calls == ["GET", "GET", "GET"]

    calls.clear()
    with mock_client(flaky, retries=3, backoff_s=0.001) as c, pytest.raises(ServerError):
        c.step("abc")
    assert calls == ["POST"]

    def down(request: httpx.Request) -> httpx.Response:
        calls.append(request.method)
        raise httpx.ConnectError("refused", request=request)

    calls.clear()
    with mock_client(down, retries=2, backoff_s=0.001) as c, pytest.raises(TransportError):
        c.get_session("abc")
    assert calls == ["GET"] * 3

    def lost_answer(request: httpx.Request) -> httpx.Response:
        calls.append(request.method)
        if len(calls) == 1:  # deleted, but the answer was lost
            raise httpx.ReadTimeout("lost", request=request)
        return httpx.Response(404, json={"error": "not_found", "message": "no session"})

    calls.clear()
    with mock_client(lost_answer, retries=2, backoff_s=0.001) as c:
        c.delete_session("abc")  # the retry's 404 means the first DELETE did it
    assert calls == ["DELETE", "DELETE"]


def test_unreadable_answers_are_server_errors() -> None:
    with mock_client(lambda r: httpx.Response(500, text="boom"), retries=0) as c:
        with pytest.raises(ServerError) as info:
            c.health()
    assert info.value.status == 500 and "boom" in info.value.message
    body = json.dumps({"unexpected": True})
    with mock_client(lambda r: httpx.Response(200, text=body), retries=0) as c:
        with pytest.raises(ServerError):
            c.get_session("abc")
    with mock_client(lambda r: httpx.Response(418, text="teapot"), retries=0) as c:
        with pytest.raises(DiathermyError) as other:
            c.health()
    assert other.value.status == 418
