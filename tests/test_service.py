"""The Zenoh schedule service (issue 8), with real Zenoh sessions on 127.0.0.1: explicit
endpoints, multicast scouting off."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")

from service.zenoh_service.client import ScheduleClient, ServiceError  # noqa: E402
from service.zenoh_service.engine import ScheduleEngine  # noqa: E402
from service.zenoh_service.server import ScheduleService, ServiceSettings  # noqa: E402
from service.zenoh_service.session import zenoh_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CUT = ROOT / "datasets/seeds/hou2023_cut.toml"
TWIN = ROOT / "datasets/robots/kr_r2700_twin.toml"
P5 = {"pose_id": "P5", "x_mm": 1400.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory) -> Path:
    from posedyn.posemodel import PoseModel
    from posedyn.io import read_modal_table
    from posedyn.io.model_dir import save_model

    folder = tmp_path_factory.mktemp("model") / "hou2023"
    save_model(PoseModel(method="stgp").fit(read_modal_table(ROOT / "datasets/seeds/hou2023_positions.csv")), folder)
    return folder


@pytest.fixture(scope="module")
def service(model_dir, tmp_path_factory):
    port = free_port()
    state = tmp_path_factory.mktemp("state")
    settings = ServiceSettings("cell1", max_payload_bytes=4096, queue_size=2, workers=1)
    svc = ScheduleService(ScheduleEngine(model_dir, CUT, twin=TWIN), settings, zenoh_config(None, "peer", [f"tcp/127.0.0.1:{port}"]), state).start()
    yield svc, f"tcp/127.0.0.1:{port}"
    svc.close()


@pytest.fixture()
def client(service):
    with ScheduleClient("cell1", connect=[service[1]], timeout_s=20) as c:
        yield c


def test_query_returns_what_posedyn_schedule_writes(client, model_dir, tmp_path):
    poses = tmp_path / "poses.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\n")
    cli = subprocess.run(
        [sys.executable, "-c", "from service.cli import main; main()", "schedule", str(model_dir), "--poses", str(poses), "--cut", str(CUT), "--json"],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
    )
    assert cli.returncode == 0, cli.stderr
    expected = json.loads(cli.stdout)[0]
    got = client.schedule(P5)
    for key in ("model_version", "computed_at", "stale_after_s"):
        assert key in got
        got.pop(key)
    assert got == expected


def test_every_bad_input_gets_its_error_and_the_service_keeps_answering(client):
    cases = {
        b"{": "malformed_json",
        b"\xff\xfe": "malformed_json",
        b"": "missing_payload",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800}}': "missing_field",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0, "speed": 3}}': "unknown_field",
        b'{"pose": {"x_mm": NaN, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "not_finite",
        b'{"pose": {"x_mm": 1e999, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "not_finite",
        b'{"pose": {"x_mm": "far", "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "invalid_field",
        b'{"pose": {"x_mm": 9000, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "outside_workspace",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 6000, "beta_deg": 0}}': "unreachable_pose",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0}, "cut": {"teeth": 0}}': "invalid_field",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0}, "cut": {"rpm": -5}}': "invalid_field",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0}, "pad": "' + b"x" * 5000 + b'"}': "payload_too_large",
    }
    for payload, code in cases.items():
        start = time.monotonic()
        with pytest.raises(ServiceError) as err:
            client.get("schedule", None, raw=payload)
        assert err.value.code == code, (payload[:60], err.value)
        assert time.monotonic() - start < 15  # answered, not timed out
    with pytest.raises(ServiceError) as err:
        client.stored_plan("no-such-plan")
    assert err.value.code == "unknown_plan"
    with pytest.raises(ServiceError) as err:
        client.get("plan/bad id!", None)
    assert err.value.code in ("invalid_plan_id", "no_reply")  # a space is not a valid key expression either
    assert client.schedule(P5)["pose_id"] == "P5"
    assert client.schedule(P5)["pose_id"] == "P5"  # the second from the cache
    status = client.status()
    assert status["errors"] >= len(cases) and status["cache_hits"] >= 1


def test_a_failing_computation_is_an_error_reply_not_a_timeout(service, client, monkeypatch):
    svc, _ = service

    def broken(pose, cut):
        raise RuntimeError("boom")

    monkeypatch.setattr(svc.scheduler, "entry", broken)
    start = time.monotonic()
    with pytest.raises(ServiceError) as err:
        client.schedule({"x_mm": 1333.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0})
    assert err.value.code == "internal" and "boom" in err.value.message
    assert time.monotonic() - start < 5
    monkeypatch.undo()
    assert client.schedule(P5)["critical_depth_mm"] > 0


def test_overload_is_answered_busy(service, client):
    """Queue of 2, one worker: a burst of new poses gets 'busy' at once for some, schedules for
    the rest, and nobody waits for a timeout."""
    results = []

    def ask(x):
        try:
            results.append(client.schedule({"x_mm": x, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0})["pose_id"])
        except ServiceError as exc:
            results.append(exc.code)

    threads = [threading.Thread(target=ask, args=(1250.0 + 7 * i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert len(results) == 8 and "busy" in results and "pose" in results
    assert set(results) <= {"busy", "pose"}


def _late_subscriber(endpoint: str, key: str, wait_s: float = 8.0) -> list[dict]:
    from zenoh.ext import HistoryConfig, declare_advanced_subscriber

    got = []
    conf = zenoh_config(None, "client", connect=[endpoint])
    with zenoh.open(conf) as session:
        sub = declare_advanced_subscriber(session, key, lambda s: got.append(json.loads(s.payload.to_bytes())), history=HistoryConfig(detect_late_publishers=True))
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and not got:
            time.sleep(0.05)
        time.sleep(0.5)
        sub.undeclare()
    return got


def test_a_late_subscriber_gets_a_plan_published_before_it_joined(service, client):
    poses = [dict(P5, pose_id="a"), {"pose_id": "b", "x_mm": 1500.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}]
    plan = client.plan("job-7", poses)
    assert [e["pose_id"] for e in plan["entries"]] == ["a", "b"]
    got = _late_subscriber(service[1], "cells/cell1/posedyn/schedules/job-7/*")
    assert sorted(e["pose_id"] for e in got) == ["a", "b"]
    whole = _late_subscriber(service[1], "cells/cell1/posedyn/schedules/job-7")
    assert whole and whole[-1]["plan_id"] == "job-7"
    assert client.stored_plan("job-7")["entries"] == plan["entries"]


def _serve(model_dir, state, endpoint, extra=()):
    cmd = [sys.executable, "-c", "from service.cli import main; main()", "serve", "--model", str(model_dir), "--cell", "cell2", "--cut", str(CUT),
           "--listen", endpoint, "--state-dir", str(state), *extra]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    line = proc.stdout.readline()
    assert line.startswith("serving"), (line, proc.stderr.read() if proc.poll() is not None else "")
    return proc


def test_a_killed_service_restarts_with_its_plans(model_dir, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    state = tmp_path / "state"
    proc = _serve(model_dir, state, endpoint)
    try:
        with ScheduleClient("cell2", connect=[endpoint], timeout_s=30) as c:
            plan = c.plan("last", [P5])
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert list((state / "plans").glob("*.json")) == [state / "plans" / "last.json"]
    proc = _serve(model_dir, state, endpoint)
    try:
        got = _late_subscriber(endpoint, "cells/cell2/posedyn/schedules/last")
        assert got and got[-1]["entries"] == plan["entries"]
    finally:
        proc.send_signal(signal.SIGTERM)  # graceful: closes the session, exits 0
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "stopped" in out


def _certificates(folder: Path) -> dict:
    """A CA and a server certificate for localhost / 127.0.0.1, made with openssl."""
    def run(*args):
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=folder)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=posedyn test CA")
    run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=localhost")
    (folder / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    run("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out", "server.pem", "-days", "2", "-extfile", "ext.cnf")
    return {name: str(folder / name) for name in ("ca.pem", "server.key", "server.pem")}


def test_tls_works_and_a_client_without_the_certificate_is_refused(model_dir, tmp_path):
    if not __import__("shutil").which("openssl"):
        pytest.skip("openssl is needed to make the test certificates")
    certs = _certificates(tmp_path)
    port = free_port()
    server_conf = tmp_path / "server.json5"
    server_conf.write_text(json.dumps({"transport": {"link": {"tls": {"listen_private_key": certs["server.key"], "listen_certificate": certs["server.pem"], "root_ca_certificate": certs["ca.pem"]}}}}))
    client_conf = tmp_path / "client.json5"
    client_conf.write_text(json.dumps({"transport": {"link": {"tls": {"root_ca_certificate": certs["ca.pem"]}}}}))
    endpoint = f"tls/localhost:{port}"
    proc = _serve(model_dir, tmp_path / "state", endpoint, ["--config", str(server_conf)])
    try:
        with ScheduleClient("cell2", connect=[endpoint], config=client_conf, timeout_s=30) as c:
            assert c.schedule(P5)["pose_id"] == "P5"
        refused = True
        try:
            with ScheduleClient("cell2", connect=[endpoint], timeout_s=3) as c:  # no CA: the handshake fails
                c.schedule(P5)
            refused = False
        except (zenoh.ZError, ServiceError):
            pass
        assert refused
        with pytest.raises((zenoh.ZError, ServiceError)):  # and plain TCP on the TLS port gets nothing
            with ScheduleClient("cell2", connect=[f"tcp/127.0.0.1:{port}"], timeout_s=3) as c:
                c.schedule(P5)
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)


def test_query_cli_reports_errors_and_zero_replies(service, tmp_path):
    base = [sys.executable, "-c", "from service.cli import main; main()", "query", "--cell", "cell1", "--connect", service[1], "--timeout-s", "20"]
    ok = subprocess.run(base + ["--pose-json", json.dumps(P5), "--json"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["pose_id"] == "P5"
    bad = subprocess.run(base + ["--pose-json", '{"x_mm": 1}'], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert bad.returncode == 3 and "missing_field" in bad.stderr
    nobody = subprocess.run(
        [sys.executable, "-c", "from service.cli import main; main()", "query", "--cell", "nobody", "--connect", service[1], "--timeout-s", "2", "--pose-json", json.dumps(P5)],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )
    assert nobody.returncode == 3 and "no_reply" in nobody.stderr
    plan = tmp_path / "path.csv"
    plan.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nq1,1400,0,800,0\nq2,1450,0,800,0\n")
    sent = subprocess.run(base + ["--plan", str(plan), "--json"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert sent.returncode == 0, sent.stderr
    assert json.loads(sent.stdout)["plan_id"] == "path"


def test_the_shipped_security_examples_are_valid_zenoh_configs():
    for path in sorted((ROOT / "service/zenoh_service/config").glob("*.json5")):
        zenoh.Config.from_file(str(path))  # raises on an unknown key or a syntax error


def test_a_plan_put_is_published_and_the_service_is_alive(service):
    conf = zenoh_config(None, "client", connect=[service[1]])
    with zenoh.open(conf) as session:
        alive = list(session.liveliness().get("cells/cell1/posedyn/alive", timeout=5))
        assert alive and alive[0].ok is not None
        session.put("cells/cell1/posedyn/plan/put-1", json.dumps({"poses": [dict(P5, pose_id="p")]}))
        session.put("cells/cell1/posedyn/plan/put-2", b"not json")  # refused and counted, nothing dies
    got = _late_subscriber(service[1], "cells/cell1/posedyn/schedules/put-1", wait_s=30)
    assert got and got[-1]["entries"][0]["pose_id"] == "p"
    with ScheduleClient("cell1", connect=[service[1]]) as c:
        assert c.status()["plans_published"] >= 1
