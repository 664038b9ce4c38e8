"""The ASGI application and the ``serve`` entry point used by ``alloc serve`` / ``make run``."""

from __future__ import annotations

import gc
import logging
import os
import sys
import threading
import time
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from pydantic import ValidationError
from starlette.types import ASGIApp, Message, Receive, Scope, Send

import alloc

from . import timing
from .config import MAX_AXES, MAX_BATCH, MAX_EFFECTORS, Settings
from .db import make_engine, make_sessionmaker
from .docs import install_docs
from .bodies import GC_THRESHOLDS, BodyBudget, BodySizeLimit
from .errors import PROBLEM_JSON, install_handlers
from .keys import NO_KEY_WARNING, KeyAtHead
from .routes import allocation, ams, methods, system, telemetry, vehicles
from .priority import GATE_STATE_KEY, PriorityGate, PriorityMiddleware
from .server import GuardedHttpToolsProtocol
from .streams import GuardedWebSocketProtocol, StreamLimits
from .pool import AllocatorPool
from .store import VehicleStore
from .warm import start_background_warm_up, warm_up

__all__ = ["create_app", "serve", "warm_up", "BodySizeLimit", "ServerTiming", "uvicorn_options"]

_log = logging.getLogger("service")

DESCRIPTION = f"""
Control allocation over HTTP: allocate for an inline problem or for a stored vehicle at its
current health, record failures and repairs, read the history.

* Sizes: m <= {MAX_EFFECTORS} effectors, k <= {MAX_AXES} axes, batches <= {MAX_BATCH:,} demands;
  request bodies are limited (``ALLOC_MAX_BODY_BYTES``, 413 beyond).
* Numbers must be finite; an unlimited rate is ``null``.
* Errors are RFC 9457 ``{PROBLEM_JSON}`` with an ``errors`` list (``loc``, ``pointer``, ``reason``).
* Numbers at most 1e9 in magnitude, non-zero weights at least 1e-9; types are strict.
* Write endpoints need ``X-API-Key`` when ``ALLOC_API_KEY`` is set.
* Any number of worker processes and replicas may share one database: every request reads
  the vehicle's committed health version.
"""


class ServerTiming:
    """ASGI middleware: a ``Server-Timing: app;dur=<ms>`` header on every response.

    The time from the request reaching the application to its response headers, so a
    client can tell the service's share of a latency from the network's and its own;
    followed by the phases the request's path recorded (:mod:`service.timing`).
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()
        timeline = timing.start()
        received = scope.get("alloc.received")
        if received is not None:
            timeline.phases.append(("dispatch", t0 - received))

        async def timed_send(message: Message) -> None:
            if message["type"] == "http.response.start":
                ms = (time.perf_counter() - t0) * 1e3
                value = f"app;dur={ms:.3f}" + (", " + timeline.header() if timeline.phases else "")
                message = {**message, "headers": [*message.get("headers", ()), (b"server-timing", value.encode())]}
            await send(message)

        await self.app(scope, receive, timed_send)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the application: database (migrated), store, allocator pool, routers, error handlers, body limit."""
    settings = settings or Settings()
    if settings.api_key is None:
        _log.warning(NO_KEY_WARNING)
    engine = make_engine(settings.resolved_database_url)
    gate = PriorityGate(settings.api_key)
    store = VehicleStore(engine, make_sessionmaker(engine), idempotency_ttl_s=settings.idempotency_ttl_s)
    pool = AllocatorPool(store, cache_size=settings.cache_size, cache_bytes=settings.cache_bytes,
                         inline_cache_bytes=settings.inline_cache_bytes, build_budget=settings.build_budget_s,
                         build_workers=settings.build_workers, build_queue=settings.build_queue,
                         batch_budget=settings.batch_budget_s, max_answer_bytes=settings.max_answer_bytes,
                         answer_bytes_in_flight=settings.answer_bytes_in_flight)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        t0 = time.perf_counter()
        # A thread waiting for the GIL (an event's writer thread, a build finishing) gets it
        # within 1 ms instead of 5 ms: an event does a dozen GIL hand-offs, and under a
        # request flood each one would otherwise wait the full interval.
        sys.setswitchinterval(0.001)
        # Move everything allocated at start-up (numpy, scipy, pydantic models, ...) out of
        # the collector's reach: full collections then scan only per-request garbage,
        # which keeps GC pauses out of the latency tail.
        gc.collect()
        gc.freeze()
        gc.set_threshold(*GC_THRESHOLDS)  # parsed bodies' garbage: shorter pauses (service.bodies)
        stop = threading.Event()
        warming = None
        if settings.warmup:
            # The kernels load on a thread once the service answers (service.warm); the build
            # processes for costly builds and batches start after that, so that their own
            # imports and warm-up do not compete with this process's for the CPU.
            warming = start_background_warm_up(stop, then=pool.builder.start_processes)
        app.state.startup_seconds, app.state.ready = time.perf_counter() - t0, True
        yield {GATE_STATE_KEY: gate}  # lifespan state: where the HTTP protocol finds the gate
        app.state.ready = False  # shutting down: /v1/ready answers 503 from here on
        stop.set()
        if warming is not None:
            warming.join(timeout=10)  # at most the method it is warming: no build process started after the close
        pool.close()
        store.close()
        engine.dispose()

    app = FastAPI(title="alloc service", version=alloc.__version__, description=DESCRIPTION, lifespan=lifespan,
                  docs_url=None, redoc_url=None)
    app.state.settings = settings
    app.state.store = store
    app.state.pool = pool
    app.state.gate = gate
    for module in (allocation, methods, ams, vehicles, system):
        app.include_router(module.router)
    install_docs(app)
    install_handlers(app)
    app.add_middleware(BodySizeLimit, limit=settings.max_body_bytes, gate=gate,
                       budget=BodyBudget(settings.body_bytes_in_flight, settings.writer_body_bytes))
    app.add_middleware(PriorityMiddleware, gate=gate)  # before anything reads a body
    # outside the gate: a WebSocket message over its limits is refused without entering it, and
    # a keyless write without waiting at it (service.streams, service.keys)
    app.add_middleware(StreamLimits, api_key=settings.api_key, messages_per_s=settings.ws_key_messages_per_s,
                       bytes_per_s=settings.ws_key_bytes_per_s)
    app.add_middleware(KeyAtHead, api_key=settings.api_key, routes_of=lambda: app)
    app.add_middleware(ServerTiming)  # outermost: includes the body limit's buffering
    return app


def uvicorn_options(settings: Settings) -> dict[str, Any]:
    """uvicorn's connection settings, from the service's (service/README.md, "Connection hygiene");
    the rest of the connection policy is :class:`service.server.GuardedHttpToolsProtocol`'s."""
    return {
        "access_log": False,  # a log line per request costs about as much as a pseudo-inverse allocation
        "timeout_keep_alive": settings.keep_alive_s,
        # HTTP connections + tasks per process, 503 beyond; the WebSockets are counted apart
        # (ALLOC_MAX_WEBSOCKETS) and events and probes have ALLOC_RESERVED_REQUESTS more (service.server)
        "limit_concurrency": settings.max_connections,
        "backlog": 2 * settings.max_connections,
        "timeout_graceful_shutdown": 10,
        # A WebSocket message is assembled whole before the route sees it: without this bound a
        # client could make the process hold 16 MiB (uvicorn's default) per message, where the
        # stream accepts at most 64 KiB.  The margin keeps the stream's own named error (413,
        # service.streams) for messages just over its limit; a larger frame is refused from its
        # header, before its payload is read, and the socket closed with 1009 (message too big).
        "ws_max_size": telemetry.WS_MAX_MESSAGE_BYTES + (64 << 10),
    }


def serve(host: str = "127.0.0.1", port: int = 8000, data_dir: str | Path | None = None,
          database_url: str | None = None, api_key: str | None = None, workers: int = 1,
          api_key_file: str | Path | None = None, **uvicorn_settings: Any) -> None:
    """Run the service with uvicorn: ``workers`` processes on one port and one database.

    Any number of workers (and of replicas on the same database) is safe: every request
    reads the vehicle's health version from the database (:mod:`service.store`).  The
    settings are passed to the workers through the ``ALLOC_*`` environment.
    """
    import uvicorn
    from uvicorn.config import STARTUP_FAILURE

    from .supervisor import ReadinessSupervisor

    if data_dir is not None:
        os.environ["ALLOC_DATA_DIR"] = str(Path(data_dir).resolve())
    if database_url is not None:
        os.environ["ALLOC_DATABASE_URL"] = database_url
    if api_key is not None:
        os.environ["ALLOC_API_KEY"] = api_key
    if api_key_file is not None:
        os.environ["ALLOC_API_KEY_FILE"] = str(Path(api_key_file).resolve())
    try:  # validated here once: a refused setting stops the start, before any worker
        settings = Settings()
    except ValidationError as exc:  # say which setting and why, without a traceback (nor the value)
        reasons = "; ".join(str(err["msg"]).removeprefix("Value error, ") for err in exc.errors())
        raise SystemExit(f"alloc service: refusing to start: {reasons}") from None
    make_engine(settings.resolved_database_url).dispose()  # migrate once, before the workers start
    options = {**uvicorn_options(settings), **uvicorn_settings}
    config = uvicorn.Config("service.main:create_app", factory=True, host=host, port=port, workers=workers,
                            http=GuardedHttpToolsProtocol, ws=GuardedWebSocketProtocol, **options)
    if workers > 1:
        # workers are health-checked once ready, restarted only when not ready in time (service.supervisor)
        ReadinessSupervisor(config, [config.bind_socket()], settings.startup_timeout_s).run()
        return
    server = uvicorn.Server(config)
    server.run()
    if not server.started:
        sys.exit(STARTUP_FAILURE)


def _main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description="Run the alloc HTTP service.")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--workers", type=int, default=1, help="worker processes (one database, one truth)")
    parser.add_argument("--data-dir", default=None)
    parser.add_argument("--database-url", default=None)
    parser.add_argument("--api-key-file", default=None,
                        help="file holding the write key (or ALLOC_API_KEY); never the key itself on argv")
    parser.add_argument("--log-level", default="info")
    parser.add_argument("--access-log", action="store_true", help="log every request")
    args = parser.parse_args()
    serve(args.host, args.port, args.data_dir, args.database_url, workers=args.workers,
          api_key_file=args.api_key_file, log_level=args.log_level, access_log=args.access_log)


if __name__ == "__main__":
    _main()
