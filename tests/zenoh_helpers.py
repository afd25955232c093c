"""What the service tests share: ports, a trained model, `posedyn serve` in a subprocess, test
certificates, late and live subscribers. Real Zenoh sessions on 127.0.0.1, explicit endpoints,
multicast scouting off."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import zenoh

from service.zenoh_service.server import ScheduleService, ServiceSettings
from service.zenoh_service.session import zenoh_config
from service.zenoh_service.workers import EngineSpec

ROOT = Path(__file__).resolve().parents[1]
CUT = ROOT / "datasets/seeds/hou2023_cut.toml"
TWIN = ROOT / "datasets/robots/kr_r2700_twin.toml"
P5 = {"pose_id": "P5", "x_mm": 1400.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}
CLI = [sys.executable, "-c", "from service.cli import main; main()"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def train_model(folder: Path) -> Path:
    from posedyn.io import read_modal_table
    from posedyn.io.model_dir import save_model
    from posedyn.posemodel import PoseModel

    save_model(PoseModel(method="stgp").fit(read_modal_table(ROOT / "datasets/seeds/hou2023_positions.csv")), folder)
    return folder


def start_service(model_dir: Path, state: Path, cell: str, signing_key: bytes | None = None, **limits) -> tuple[ScheduleService, str]:
    """A ScheduleService in this process (an embedded peer on a free loopback port), started."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    spec = EngineSpec(model_dir, CUT, twin=TWIN)
    return ScheduleService(spec, ServiceSettings(cell, **limits), zenoh_config(None, "peer", [endpoint]), state, signing_key=signing_key).start(), endpoint


def serve(model_dir: Path, state: Path, endpoint: str, extra=(), cell: str = "cell2") -> subprocess.Popen:
    """`posedyn serve` in its own process group; returns once it prints that it serves."""
    cmd = [*CLI, "serve", "--model", str(model_dir), "--cell", cell, "--cut", str(CUT), "--listen", endpoint, "--state-dir", str(state), *extra]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    line = proc.stdout.readline()
    assert line.startswith("serving"), (line, proc.stderr.read() if proc.poll() is not None else "")
    return proc


def session(endpoint: str, mode: str = "client", config: dict | None = None):
    conf = zenoh_config(None, mode, connect=[endpoint])
    for key, value in (config or {}).items():
        conf.insert_json5(key, json.dumps(value))
    return zenoh.open(conf)


def late_subscriber(endpoint: str, key: str, wait_s: float = 8.0) -> list[dict]:
    """What an AdvancedSubscriber with history, declared now, receives on `key`."""
    from zenoh.ext import HistoryConfig, declare_advanced_subscriber

    got = []
    with session(endpoint) as s:
        sub = declare_advanced_subscriber(s, key, lambda sample: got.append(json.loads(sample.payload.to_bytes())), history=HistoryConfig(detect_late_publishers=True))
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and not got:
            time.sleep(0.05)
        time.sleep(0.5)
        sub.undeclare()
    return got


def certificates(folder: Path, clients=("cell1-controller",)) -> dict:
    """A CA, a server certificate for localhost / 127.0.0.1 and one client certificate per common
    name, made with openssl."""

    def run(*args):
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=folder)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=posedyn test CA")
    (folder / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    for name, cn in [("server", "localhost"), *[(c, c) for c in clients]]:
        run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={cn}")
        run("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out", f"{name}.pem", "-days", "2", "-extfile", "ext.cnf")
    return {f.name: str(f) for f in folder.iterdir() if f.suffix in (".pem", ".key")}
