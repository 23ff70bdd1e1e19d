"""``diathermy serve`` and ``diathermy openapi``: the service's commands (FastAPI imported lazily)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any


def _cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn
    from pydantic import ValidationError

    from diathermy.service.config import Settings
    from diathermy.service.cpus import format_cpus, place_server
    from diathermy.service.jsonlog import configure_logging
    from diathermy.service.main import create_app

    overrides: dict[str, Any] = {
        k: v
        for k, v in {
            "host": args.host,
            "port": args.port,
            "data_dir": args.data_dir,
            "token_file": args.token_file,
            "engine_cpus": args.engine_cpus,
        }.items()
        if v is not None
    }
    if args.no_auth:
        overrides["auth_disabled"] = True
    try:
        settings = Settings(**overrides)
        if args.token:
            settings = settings.model_copy(update={"tokens": [*settings.tokens, *args.token]})
        configure_logging(settings.log_level)
        kept = place_server(settings.engine_cpus)
        if kept is not None:
            logging.getLogger("diathermy.service").info(
                "cpu placement",
                extra={
                    "engine_cpus": format_cpus(settings.engine_cpus),
                    "server_cpus": format_cpus(kept),
                },
            )
        app = create_app(settings)
    except ValidationError as err:
        print(f"diathermy: error: {one_line(err)}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as err:
        print(f"diathermy: error: {err}", file=sys.stderr)
        return 2
    uvicorn.run(
        app,
        host=settings.host,
        port=settings.port,
        ws="websockets-sansio",
        ws_per_message_deflate=False,  # frames are encoded once per subscription, sent as is
        ws_max_size=settings.max_message_bytes,
        log_config=None,
        access_log=False,
    )
    return 0


def one_line(err: Any) -> str:
    """A pydantic ValidationError as one line: ``field: message; ...``."""
    return "; ".join(
        f"{'.'.join(str(x) for x in e['loc']) or 'settings'}: {e['msg']}" for e in err.errors()
    )


def _cmd_openapi(args: argparse.Namespace) -> int:
    from diathermy.service.openapi import write_contracts

    for path in write_contracts(Path(args.out)):
        print(path)
    return 0


def add_serve_parser(subparsers: Any) -> None:
    """Add ``serve`` and ``openapi`` to the ``diathermy`` command line."""
    s = subparsers.add_parser(
        "serve", help="run the simulation service (REST + WebSocket); settings from DIATHERMY_*"
    )
    s.add_argument("--host", help="interface to bind (default 127.0.0.1, DIATHERMY_HOST)")
    s.add_argument("--port", type=int, help="port (default 8000, DIATHERMY_PORT)")
    s.add_argument("--data-dir", type=Path, help="session checkpoints (DIATHERMY_DATA_DIR)")
    s.add_argument("--token", action="append", help="accept this bearer token (repeatable)")
    s.add_argument("--token-file", type=Path, help="file of tokens or sha256:<hex>, one a line")
    s.add_argument(
        "--no-auth", action="store_true", help="serve without authentication (warns at start)"
    )
    s.add_argument(
        "--engine-cpus",
        metavar="LIST",
        help="run the engine processes on these CPUs ('1', '2-3,6') and the server on the "
        "others (DIATHERMY_ENGINE_CPUS; default: no placement)",
    )
    s.set_defaults(func=_cmd_serve)

    s = subparsers.add_parser("openapi", help="write openapi.json and stream-messages.json")
    s.add_argument("--out", default="openapi", help="folder to write into (default openapi/)")
    s.set_defaults(func=_cmd_openapi)
