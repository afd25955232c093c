"""Service benchmark on loopback: a raw Zenoh echo queryable (Python callback, the baseline) and
`posedyn serve`, each in its own process; clients in this process.

Prints p50/p99 latency of one client's sequential queries (echo, cached schedule, fresh
computation), the throughput of 4 concurrent clients sending 10,000 queries in all (echo and
cached schedule), the error count, and the ratios. Targets (issue 8): cached p50 <= 1 ms,
p99 <= 10 ms, throughput >= half of the echo's, zero errors.

    .venv/bin/python bench/zenoh_service.py [--queries 10000] [--clients 4]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

from posedyn.io.shipped import DATASETS

ECHO = """
import signal, sys, threading, zenoh
conf = zenoh.Config()
conf.insert_json5("listen/endpoints", '["%s"]')
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
def echo(query):
    query.reply(query.key_expr, query.payload.to_bytes() if query.payload is not None else b"")
    query.drop()
q = session.declare_queryable("bench/echo", echo, complete=True)
print("ready", flush=True)
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
stop.wait()
session.close()
"""
POSE = {"pose_id": "P5", "x_mm": 1400.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def session(endpoint: str):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def ask(s, key: str, payload: bytes) -> bool:
    for reply in s.get(key, payload=payload, target=zenoh.QueryTarget.ALL_COMPLETE, timeout=10.0):
        return reply.ok is not None
    return False


def latencies(s, key: str, payloads) -> np.ndarray:
    out = []
    for p in payloads:
        start = time.perf_counter()
        if not ask(s, key, p):
            raise RuntimeError(f"error reply on {key}")
        out.append(time.perf_counter() - start)
    return np.array(out)


def throughput(endpoint: str, key: str, payload: bytes, total: int, clients: int) -> tuple[float, int]:
    sessions = [session(endpoint) for _ in range(clients)]
    errors = [0] * clients
    per = total // clients

    def run(k):
        for _ in range(per):
            try:
                if not ask(sessions[k], key, payload):
                    errors[k] += 1
            except Exception:  # noqa: BLE001 - counted
                errors[k] += 1

    threads = [threading.Thread(target=run, args=(k,)) for k in range(clients)]
    start = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    elapsed = time.perf_counter() - start
    for s in sessions:
        s.close()
    return per * clients / elapsed, sum(errors)


def start(cmd, **kw):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, start_new_session=True, **kw)
    line = proc.stdout.readline()
    if not (line.startswith("ready") or line.startswith("serving")):
        raise RuntimeError(f"did not start: {line!r}")
    return proc


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--queries", type=int, default=10_000)
    parser.add_argument("--clients", type=int, default=4)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "model"
        subprocess.run([sys.executable, "-c", "from service.cli import main; main()", "train", str(DATASETS / "seeds/hou2023_positions.csv"), "--cv", "0", "--out", str(model)], check=True, capture_output=True)
        echo_ep, ours_ep = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
        echo = start([sys.executable, "-c", ECHO % echo_ep])
        ours = start([sys.executable, "-c", "from service.cli import main; main()", "serve", "--model", str(model), "--cell", "bench", "--cut", str(DATASETS / "seeds/hou2023_cut.toml"), "--listen", ours_ep, "--queue-size", "64"])
        try:
            request = json.dumps({"pose": POSE}).encode()
            s_echo, s_ours = session(echo_ep), session(ours_ep)
            ask(s_ours, "cells/bench/posedyn/schedule", request)  # compute once: the rest are cache hits
            for _ in range(200):
                ask(s_echo, "bench/echo", request)
                ask(s_ours, "cells/bench/posedyn/schedule", request)
            e = latencies(s_echo, "bench/echo", [request] * 2000)
            c = latencies(s_ours, "cells/bench/posedyn/schedule", [request] * 2000)
            fresh_payloads = [json.dumps({"pose": dict(POSE, x_mm=1200.0 + 4.0 * i)}).encode() for i in range(40)]
            f = latencies(s_ours, "cells/bench/posedyn/schedule", fresh_payloads)
            s_echo.close()
            s_ours.close()
            print("latency, one client, sequential (ms):")
            for name, x in (("raw echo queryable", e), ("cached schedule", c), ("fresh computation", f)):
                print(f"  {name:20s} p50 {np.percentile(x, 50) * 1e3:8.3f}  p99 {np.percentile(x, 99) * 1e3:8.3f}  (n = {len(x)})")
            print(f"  cached / echo: p50 {np.percentile(c, 50) / np.percentile(e, 50):.2f}x, p99 {np.percentile(c, 99) / np.percentile(e, 99):.2f}x  (targets: cached p50 <= 1 ms, p99 <= 10 ms)")
            te, err_e = throughput(echo_ep, "bench/echo", request, args.queries, args.clients)
            tc, err_c = throughput(ours_ep, "cells/bench/posedyn/schedule", request, args.queries, args.clients)
            print(f"throughput, {args.clients} clients, {args.queries} queries each run:")
            print(f"  raw echo queryable   {te:8.0f} queries/s, errors {err_e}")
            print(f"  cached schedule      {tc:8.0f} queries/s, errors {err_c}")
            print(f"  ratio {tc / te:.2f} (target >= 0.5), errors {err_c} (target 0)")
        finally:
            for proc in (echo, ours):
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(30)


if __name__ == "__main__":
    main()
