"""The SDK as a package: light imports, curated public names, types shipped, examples in docs."""

from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path

import diathermy_client

ROOT = Path(__file__).resolve().parents[2]

PUBLIC = {
    "Ack",
    "AsyncClient",
    "AsyncSession",
    "AsyncStream",
    "AuthError",
    "Client",
    "Conflict",
    "DiathermyError",
    "EffectReport",
    "Electrode",
    "ElectrodeAck",
    "Fields",
    "Frame",
    "Grid",
    "Health",
    "Hello",
    "InvalidRequest",
    "Job",
    "JobEvent",
    "JobLogLine",
    "JobProgress",
    "LimitExceeded",
    "ModelInfo",
    "ModelList",
    "NotFound",
    "ReconnectPolicy",
    "Scene",
    "ServerError",
    "Session",
    "SessionInfo",
    "Snapshot",
    "StepReport",
    "StepResult",
    "Stream",
    "StreamClosed",
    "Surface",
    "Timeout",
    "TransportError",
    "__version__",
}


def test_all_is_curated() -> None:
    assert set(diathermy_client.__all__) == PUBLIC
    assert len(diathermy_client.__all__) == len(PUBLIC)
    for name in PUBLIC:
        assert getattr(diathermy_client, name) is not None


def test_import_pulls_in_no_server_dependencies() -> None:
    code = (
        "import sys; import diathermy_client; "
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('fastapi', 'torch', 'scipy', 'diathermy', 'uvicorn', 'starlette', 'h5py', 'pyamg')); "
        "print(','.join(bad))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": str(ROOT / "client"), "PATH": "/usr/bin:/bin"},
        cwd=ROOT / "client",
    )
    assert out.stdout.strip() == "", out.stdout


def test_typed_package_and_exception_tree() -> None:
    assert (ROOT / "client" / "diathermy_client" / "py.typed").exists()
    d = diathermy_client
    for cls in (
        d.AuthError,
        d.NotFound,
        d.InvalidRequest,
        d.Conflict,
        d.ServerError,
        d.StreamClosed,
        d.Timeout,
        d.TransportError,
    ):
        assert issubclass(cls, d.DiathermyError)
    assert issubclass(d.LimitExceeded, d.InvalidRequest)
    assert issubclass(d.Timeout, TimeoutError)


def test_every_public_method_has_a_docstring_with_an_example() -> None:
    d = diathermy_client
    missing = []
    for cls in (d.Client, d.AsyncClient, d.Session, d.AsyncSession, d.Stream, d.AsyncStream):
        assert "Example" in (cls.__doc__ or ""), cls
        for name, member in inspect.getmembers(cls, inspect.isfunction):
            if name.startswith("_"):
                continue
            if "Example" not in (member.__doc__ or ""):
                missing.append(f"{cls.__name__}.{name}")
    assert not missing, missing


def test_sync_and_async_clients_offer_the_same_methods() -> None:
    d = diathermy_client
    for sync, asyn in [
        (d.Client, d.AsyncClient),
        (d.Session, d.AsyncSession),
        (d.Stream, d.AsyncStream),
    ]:
        public = {n for n in dir(sync) if not n.startswith("_")} - {"close"}
        apublic = {n for n in dir(asyn) if not n.startswith("_")} - {"aclose", "close"}
        assert public == apublic, public ^ apublic
