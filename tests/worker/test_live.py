"""A real server and real worker processes: datasets, training, the registry, cancel, SIGKILL."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from operator import attrgetter
from pathlib import Path

import httpx

from diathermy.datagen import DatasetReader
from diathermy.scene import builtin_scene
from diathermy.worker.registry import resolve_model
from tests.service.conftest import TOKEN_B, LiveServer
from tests.worker.conftest import ROOT, TINY, WorkerProcess, log_lines, wait_for

SLOW = {"grid": [7, 7, 13], "n_scenarios": 12, "n_steps": 3, "seed": 5}
"""Long enough (a few seconds per scenario batch on a busy machine) to interrupt mid-job."""
UNFINISHABLE = {**SLOW, "n_scenarios": 60, "n_steps": 150}  # <= the 72 start tets of a 7x7 top
"""For the cancel test: about a minute of work on an idle machine (~1 s a scenario), so the
cancel always lands first; SLOW (0.1 s a scenario idle) finished before it in CI."""


def sse_events(api: httpx.Client, job_id: str) -> Iterator[tuple[str, dict]]:
    """(event, data) pairs of GET /v1/jobs/{id}/events until the server closes it."""
    with api.stream("GET", f"/v1/jobs/{job_id}/events", params={"timeout_s": 120}) as resp:
        assert resp.status_code == 200
        assert resp.headers["content-type"].startswith("text/event-stream")
        event = None
        for line in resp.iter_lines():
            if line.startswith("event: "):
                event = line.removeprefix("event: ")
            elif line.startswith("data: ") and event is not None:
                yield event, json.loads(line.removeprefix("data: "))


def test_dataset_then_training_to_an_active_model(
    live: LiveServer, api: httpx.Client, start_worker: Callable[..., WorkerProcess]
) -> None:
    start_worker()
    data = api.post("/v1/jobs", json={"kind": "dataset", "config": TINY})
    assert data.status_code == 201, data.text
    data_id = data.json()["id"]
    spec = {
        "kind": "training",
        "dataset": data_id,  # submitted before the dataset exists: it waits for it
        "model_name": "tiny",
        "train": {"width": 4, "epochs": 2, "val_fraction": 0.34, "batch_size": 2},
        "activate": True,
    }
    train = api.post("/v1/jobs", json=spec)
    assert train.status_code == 201, train.text
    train_id = train.json()["id"]
    assert train.json()["depends_on"] == data_id

    events = list(sse_events(api, train_id))
    kinds = Counter(e for e, _ in events)
    assert kinds["end"] == 1 and events[-1][0] == "end"
    assert events[-1][1]["state"] == "succeeded", events[-1]
    epochs = [d["progress"].get("epoch") for e, d in events if e == "progress"]
    assert epochs[-1] == 2 and set(epochs) <= {None, 1, 2}
    logs = [d["line"] for e, d in events if e == "log"]
    assert any(line.startswith("epoch 2/2") for line in logs)
    assert "registered model tiny:1" in logs

    done = api.get(f"/v1/jobs/{data_id}").json()
    assert done["state"] == "succeeded" and done["attempts"] == 1
    assert done["progress"]["fraction"] == 1.0 and done["progress"]["samples"] == 6
    trained = api.get(f"/v1/jobs/{train_id}").json()
    assert trained["progress"]["epoch"] == 2 and trained["result"]["model"] == "tiny:1"

    models = api.get("/v1/models").json()
    assert models["active"] == {"5x5x9": "tiny:1"}
    (model,) = models["models"]
    assert model["ref"] == "tiny:1" and model["grid"] == [5, 5, 9] and model["active"]
    assert model["dataset_sha256"] == done["result"]["dataset_sha256"]
    assert model["architecture"]["width"] == 4
    assert 0 <= model["metrics"]["val_mean_strain_energy_error"] < float("inf")
    assert api.get("/v1/models/tiny/1").json()["ref"] == "tiny:1"
    assert api.get("/v1/models/tiny/2").status_code == 404

    data_dir = live.settings.data_dir
    listing = subprocess.run(
        [sys.executable, "-m", "diathermy", "models", "--data-dir", str(data_dir)],
        capture_output=True, text=True, check=True, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT / "server")},
    ).stdout  # fmt: skip
    assert "* tiny:1" in listing and "5x5x9" in listing
    path = resolve_model(data_dir, (5, 5, 9))
    assert path == Path(model["dataset"]["path"]).parents[1] / "models/tiny/1/model.pt"
    assert path.is_file()

    # a session on that grid runs its mechanics with the model through the hybrid-CNN backend
    scene = builtin_scene("default").on_uniform_grid((5, 5, 9)).model_dump(mode="json")
    scene["mechanics"] = {**scene["mechanics"], "backend": "cnn", "model": str(path)}
    session = api.post("/v1/sessions", json={"scene": scene})
    assert session.status_code == 201, session.text
    stepped = api.post(f"/v1/sessions/{session.json()['id']}/step", json={"n": 2})
    assert stepped.status_code == 200, stepped.text
    sim = live.state.registry.sessions[session.json()["id"]].sim  # the engine process's
    backend = sim.call(attrgetter("mechanics.name", "mechanics.model_path"))
    assert backend == ("cnn", path)

    # another token sees none of these jobs
    with live.client(TOKEN_B) as other:
        assert other.get(f"/v1/jobs/{train_id}").status_code == 404
        assert other.get("/v1/jobs").json()["jobs"] == []
        assert other.post(f"/v1/jobs/{train_id}/cancel").status_code == 404


def test_cancel_a_running_job_stops_it_within_seconds(
    live: LiveServer, api: httpx.Client, start_worker: Callable[..., WorkerProcess]
) -> None:
    start_worker()
    job_id = api.post("/v1/jobs", json={"kind": "dataset", "config": UNFINISHABLE}).json()["id"]
    wait_for(api, job_id, lambda j: (j["progress"].get("scenarios") or 0) >= 1)
    t0 = time.monotonic()
    assert api.post(f"/v1/jobs/{job_id}/cancel").json()["cancel_requested"]
    job = wait_for(api, job_id, lambda j: j["state"] != "running", timeout_s=15)
    assert job["state"] == "cancelled"
    assert time.monotonic() - t0 < 8
    lines = log_lines(api, job_id)
    assert "cancellation requested" in lines and lines[-1] == "cancelled"
    with DatasetReader(Path(live.settings.data_dir) / "datasets" / f"{job_id}.h5") as reader:
        assert len(reader) < UNFINISHABLE["n_scenarios"] * UNFINISHABLE["n_steps"]  # stopped early
    # the worker carries on with the next job
    nxt = api.post("/v1/jobs", json={"kind": "dataset", "config": TINY}).json()["id"]
    assert (
        wait_for(api, nxt, lambda j: j["state"] != "queued" and j["state"] != "running")["state"]
        == "succeeded"
    )


def test_sigkilled_worker_job_resumes_on_restart(
    live: LiveServer, api: httpx.Client, start_worker: Callable[..., WorkerProcess]
) -> None:
    first = start_worker(lease_s=2.0)
    job_id = api.post("/v1/jobs", json={"kind": "dataset", "config": SLOW}).json()["id"]
    wait_for(api, job_id, lambda j: (j["progress"].get("scenarios") or 0) >= 2)
    first.kill()
    stale = api.get(f"/v1/jobs/{job_id}").json()
    assert stale["state"] == "running"  # nobody knows yet; the lease will tell
    time.sleep(1.0)  # the orphaned job process notices its worker is gone and exits
    start_worker(lease_s=2.0)
    job = wait_for(api, job_id, lambda j: j["state"] not in ("queued", "running"), timeout_s=90)
    assert job["state"] == "succeeded", job
    assert job["attempts"] == 2
    lines = log_lines(api, job_id)
    assert any(line.startswith("requeued to resume") for line in lines)
    assert any(line.startswith("resuming") for line in lines)
    committed = Counter(line.split()[1] for line in lines if line.startswith("scenario "))
    # no scenario committed twice (no orphan ran on beside the resumed attempt); one killed
    # between its commit and its log line is in the file but not the log
    assert max(committed.values()) == 1
    assert int(max(committed, key=int)) == SLOW["n_scenarios"] - 1
    with DatasetReader(job["result"]["dataset_path"]) as reader:
        assert len(reader) == SLOW["n_scenarios"] * SLOW["n_steps"]
        assert sorted(set(reader.scenario_ids().tolist())) == list(range(SLOW["n_scenarios"]))


def test_two_workers_never_run_the_same_job(
    api: httpx.Client, start_worker: Callable[..., WorkerProcess]
) -> None:
    small = {**TINY, "n_scenarios": 2}
    ids = [
        api.post("/v1/jobs", json={"kind": "dataset", "config": {**small, "seed": s}}).json()["id"]
        for s in range(5)
    ]
    start_worker()
    start_worker()
    workers = set()
    for job_id in ids:
        job = wait_for(api, job_id, lambda j: j["state"] == "succeeded", timeout_s=90)
        assert job["attempts"] == 1
        lines = log_lines(api, job_id)
        assert sum("started by worker" in line for line in lines) == 1
        assert sum(line.startswith("scenario 0 committed") for line in lines) == 1
        workers.add(job["worker"])
    assert len(workers) >= 1


def test_bad_job_specs_get_4xx_naming_the_field(api: httpx.Client) -> None:
    cases = [
        ({"kind": "dataset", "config": {"grid": [2, 5, 9]}}, 422, "grid"),
        ({"kind": "dataset", "config": {"grid": [65, 65, 129]}}, 422, "grid"),
        ({"kind": "dataset", "config": {**TINY, "bogus": 1}}, 422, "bogus"),
        ({"kind": "training", "dataset": "j-000000000000"}, 400, "dataset"),
        ({"kind": "training", "dataset": "x", "train": {"width": 0}}, 422, "width"),
        ({"kind": "training", "dataset": "x", "train": {"lr": -1}}, 422, "lr"),
        ({"kind": "sculpting"}, 422, "kind"),
    ]
    for body, status, field in cases:
        resp = api.post("/v1/jobs", json=body)
        assert resp.status_code == status, (body, resp.text)
        assert field in (resp.json()["field"] or ""), (body, resp.json())
    assert api.get("/v1/jobs/j-nope").status_code == 404
    assert api.post("/v1/models/nope/1/activate").status_code == 404
    assert httpx.get(str(api.base_url) + "/v1/jobs").status_code == 401
