"""The SDK's job and model-registry calls against a real server and a real worker process."""

from __future__ import annotations

import asyncio
from collections import Counter
from pathlib import Path

import pytest

from diathermy_client import AsyncClient, Client, InvalidRequest, NotFound, Timeout
from tests.client.conftest import TOKEN_A, LiveServer
from tests.worker.conftest import WorkerProcess

TINY = {"grid": [5, 5, 9], "n_scenarios": 2, "n_steps": 2, "seed": 3}


def test_dataset_then_training_then_activation_with_the_blocking_client(
    live: LiveServer, client: Client, tmp_path: Path
) -> None:
    # no worker yet: a queued job cancels at once
    queued = client.submit_job({"kind": "dataset", "config": TINY})
    assert queued.state == "queued" and queued.kind == "dataset"
    assert client.cancel_job(queued.id).state == "cancelled"
    assert client.wait_job(queued.id, timeout_s=5).state == "cancelled"

    data = client.submit_job({"kind": "dataset", "config": TINY})
    spec = {
        "kind": "training",
        "dataset": data.id,
        "model_name": "tiny",
        "train": {"width": 4, "epochs": 1, "val_fraction": 0.5, "batch_size": 2},
    }
    train = client.submit_job(spec)
    assert train.depends_on == data.id and not train.done
    with pytest.raises(Timeout, match=train.id):
        client.wait_job(train.id, timeout_s=0.2, poll_s=0.05)

    worker = WorkerProcess(live.settings.data_dir, tmp_path / "worker.log")
    try:
        events = list(client.job_events(train.id, timeout_s=120))
    finally:
        worker.stop()
    kinds = Counter(e.event for e in events)
    assert kinds["end"] == 1 and events[-1].event == "end", kinds
    end = events[-1].job
    assert end is not None and end.state == "succeeded", end
    assert end.result is not None and end.result["model"] == "tiny:1"
    logs = [e.line.line for e in events if e.line is not None]
    assert "registered model tiny:1" in logs
    assert all(e.job is not None for e in events if e.event == "progress")

    done = client.wait_job(data.id, timeout_s=5)
    assert done.state == "succeeded" and done.progress.samples == 4
    log = client.job_log(train.id)
    assert [x.line for x in log] == logs  # the stream carried every line, in order
    assert client.job_log(train.id, after=log[-1].seq) == []
    assert client.get_job(train.id).progress.epoch == 1

    assert [j.id for j in client.list_jobs(kind="training")] == [train.id]
    assert [j.id for j in client.list_jobs(state="cancelled")] == [queued.id]
    assert {j.id for j in client.list_jobs()} == {queued.id, data.id, train.id}

    models = client.list_models()
    (model,) = models.models
    assert model.ref == "tiny:1" and model.grid == (5, 5, 9) and not model.active
    assert models.active == {}
    assert client.get_model("tiny", 1).dataset_sha256 == done.result["dataset_sha256"]  # type: ignore[index]
    assert client.activate_model("tiny", 1).active
    assert client.list_models().active == {"5x5x9": "tiny:1"}


def test_errors_name_the_field_or_the_missing_thing(client: Client) -> None:
    with pytest.raises(InvalidRequest) as err:
        client.submit_job({"kind": "dataset", "config": {"grid": [2, 5, 9]}})
    assert err.value.field is not None and "grid" in err.value.field
    with pytest.raises(InvalidRequest) as err:
        client.submit_job({"kind": "training", "dataset": "x", "train": {"width": 0}})
    assert err.value.field is not None and "width" in err.value.field
    with pytest.raises(NotFound):
        client.get_job("j-nope")
    with pytest.raises(NotFound):
        client.cancel_job("j-nope")
    with pytest.raises(NotFound):
        list(client.job_events("j-nope"))
    with pytest.raises(NotFound):
        client.get_model("nope", 1)
    with pytest.raises(NotFound):
        client.activate_model("nope", 1)
    with pytest.raises(TypeError):
        client.submit_job("dataset")  # type: ignore[arg-type]


def test_the_async_client_submits_cancels_lists_and_streams(live: LiveServer) -> None:
    async def main() -> None:
        async with AsyncClient(live.url, TOKEN_A) as client:
            job = await client.submit_job({"kind": "dataset", "config": TINY})
            assert (await client.get_job(job.id)).state == "queued"
            assert [j.id for j in await client.list_jobs(state="queued")] == [job.id]
            with pytest.raises(Timeout):
                await client.wait_job(job.id, timeout_s=0.1, poll_s=0.05)
            assert (await client.cancel_job(job.id)).state == "cancelled"
            final = await client.wait_job(job.id, timeout_s=5)
            assert final.done and final.state == "cancelled"
            events = [e async for e in client.job_events(job.id, timeout_s=10)]
            assert events[-1].event == "end" and events[-1].job is not None
            assert events[-1].job.state == "cancelled"
            lines = await client.job_log(job.id)
            assert [e.line for e in events if e.line is not None] == lines
            assert (await client.list_models()).models == []
            with pytest.raises(NotFound):
                await client.get_job("j-nope")
            with pytest.raises(InvalidRequest) as err:
                await client.submit_job({"kind": "sculpting"})
            assert err.value.field is not None and "kind" in err.value.field

    asyncio.run(main())
