"""The SDK agrees with the server's published contracts (openapi/*.json): a server change that
breaks the SDK fails here."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from diathermy.engine.report import EffectReport as EngineEffectReport
from diathermy.engine.report import StepReport as EngineStepReport
from diathermy_client import _models as m
from diathermy_client._core import ClientCore, SSEParser
from diathermy_client._stream_core import (
    Subscription,
    electrode_message,
    run_message,
    step_message,
)

ROOT = Path(__file__).resolve().parents[2]
OPENAPI = json.loads((ROOT / "openapi" / "openapi.json").read_text())
STREAM = json.loads((ROOT / "openapi" / "stream-messages.json").read_text())
SCHEMAS = OPENAPI["components"]["schemas"]

REQUESTS = {
    "SessionCreate": m.SessionCreate,
    "StepRequest": m.StepRequest,
    "ElectrodeUpdate": m.ElectrodeUpdate,
}
RESULTS = {
    "GridPublic": m.Grid,
    "SnapshotPublic": m.Snapshot,
    "SessionPublic": m.SessionInfo,
    "StepResult": m.StepResult,
    "ElectrodeAck": m.ElectrodeAck,
    "ElectrodeState": m.Electrode,
    "Health": m.Health,
    "JobPublic": m.Job,
    "JobProgressPublic": m.JobProgress,
    "JobLogLine": m.JobLogLine,
    "ModelPublic": m.ModelInfo,
    "ModelList": m.ModelList,
}


def required(model: type[BaseModel]) -> set[str]:
    return {n for n, f in model.model_fields.items() if f.is_required()}


@pytest.mark.parametrize("name", sorted(REQUESTS))
def test_request_models_match_the_schema(name: str) -> None:
    schema, model = SCHEMAS[name], REQUESTS[name]
    assert set(model.model_fields) == set(schema["properties"]), name
    assert required(model) <= set(schema.get("required", [])), name


@pytest.mark.parametrize("name", sorted(RESULTS))
def test_result_models_match_the_schema(name: str) -> None:
    schema, model = SCHEMAS[name], RESULTS[name]
    assert set(model.model_fields) == set(schema["properties"]), name
    # the SDK may only insist on what the server always sends
    assert required(model) <= set(schema.get("required", [])), name


def test_scene_fields_exist_in_the_server_scene() -> None:
    props = SCHEMAS["Scene"]["properties"]
    assert set(m.Scene.model_fields) <= set(props)


def test_step_report_matches_the_engine_report() -> None:
    engine = {f.name for f in dataclasses.fields(EngineStepReport)}
    assert set(m.StepReport.model_fields) == engine
    assert set(m.EffectReport.model_fields) == {
        f.name for f in dataclasses.fields(EngineEffectReport)
    }


def test_stream_messages_match_the_schema() -> None:
    server = STREAM["server_to_client"]["$defs"]
    for name, model in [("Hello", m.Hello), ("Ack", m.Ack)]:
        assert set(model.model_fields) == set(server[name]["properties"]), name
        assert required(model) <= set(server[name].get("required", [])), name
    frame = set(server["FrameMessage"]["properties"]) - {"type"}
    assert {f.name for f in dataclasses.fields(m.Frame)} == frame
    assert set(server["SurfaceArrays"]["properties"]) == {"vertices", "faces"}
    assert set(server["WireArray"]["properties"]) == {"shape", "dtype", "data"}
    assert set(server["ErrorMessage"]["properties"]) == {"type", "error", "message", "field"}

    client = STREAM["client_to_server"]["$defs"]
    sent = {
        "Subscribe": Subscription(("temperature",)).message(),
        "ElectrodeControl": electrode_message(
            "active",
            1,
            position_m=(0.1, 0.05),
            power_w=1.0,
            current_density_a_per_m2=1.0,
            active=True,
        ),
        "Run": run_message(10),
        "Pause": {"type": "pause"},
        "Step": step_message(1),
    }
    for name, msg in sent.items():
        props = client[name]["properties"]
        assert set(msg) <= set(props), name
        assert set(client[name].get("required", [])) <= set(msg), name
        assert msg["type"] == props["type"]["const"], name


def path_regex(template: str) -> re.Pattern[str]:
    return re.compile("^" + re.sub(r"\{[^}]+\}", "[^/]+", template) + "$")


def test_every_endpoint_the_sdk_calls_exists_with_that_method() -> None:
    core = ClientCore("http://x", "t")
    calls = [
        core.health(),
        core.ready(),
        core.list_scenes(),
        core.create_session("default"),
        core.list_sessions(),
        core.get_session("s1"),
        core.delete_session("s1"),
        core.step("s1", 2),
        core.update_electrode("s1", "active", power_w=1.0),
        core.read_fields("s1", ["temperature"]),
        core.read_surface("s1"),
        core.read_vtu("s1"),
        core.take_snapshot("s1"),
        core.list_snapshots("s1"),
        core.restore_snapshot("s1", "snap"),
        core.submit_job({"kind": "dataset", "config": {"grid": [5, 5, 9]}}),
        core.list_jobs(state="queued", kind="dataset"),
        core.get_job("j1"),
        core.cancel_job("j1"),
        core.job_log("j1", after=3),
        core.list_models(),
        core.get_model("tiny", 1),
        core.activate_model("tiny", 1),
    ]
    requests = [call.request for call in calls] + [core.job_events("j1", timeout_s=5)]
    routes = [
        (method.upper(), path_regex(p), op)
        for p, ops in OPENAPI["paths"].items()
        for method, op in ops.items()
    ]
    for req in requests:
        found = [op for method, rx, op in routes if method == req.method and rx.match(req.path)]
        assert found, f"{req.method} {req.path} is not in openapi.json"
        params: dict[str, Any] = {
            p["name"]: p for p in found[0].get("parameters", []) if p["in"] == "query"
        }
        assert set(req.params or {}) <= set(params), (req.path, req.params)
        assert {n for n, p in params.items() if p.get("required")} <= set(req.params or {}), (
            req.path
        )
        if req.json is not None:
            ref = found[0]["requestBody"]["content"]["application/json"]["schema"]
            if "oneOf" in ref:  # a discriminated union: the member the body's tag names
                ref = ref["discriminator"]["mapping"][
                    req.json[ref["discriminator"]["propertyName"]]
                ]
            else:
                ref = ref.get("$ref") or next(
                    a["$ref"] for a in ref.get("anyOf", []) if "$ref" in a
                )
            props = SCHEMAS[ref.rsplit("/", 1)[-1]]["properties"]
            assert set(req.json) <= set(props), (req.path, req.json)


def test_job_states_and_kinds_match_the_schema() -> None:
    from typing import get_args

    assert set(get_args(m.JobState)) == set(SCHEMAS["JobState"]["enum"])
    assert set(get_args(m.JobKind)) == set(SCHEMAS["JobKind"]["enum"])
    assert set(SCHEMAS["JobState"]["enum"]) - m.FINAL_STATES == {"queued", "running"}
    lines = ["id: 3", "event: log", 'data: {"seq": 3, "ts": 1.0, "line": "hi"}', ""]
    parser = SSEParser()
    events = [e for e in map(parser.feed, [": comment", *lines]) if e is not None]
    assert len(events) == 1 and events[0].id == 3 and events[0].line is not None
    assert events[0].line.line == "hi" and events[0].job is None
