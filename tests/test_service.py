"""The Zenoh schedule service (issue 8), with real Zenoh sessions on 127.0.0.1: explicit
endpoints, multicast scouting off. Limits and state: test_service_limits.py; security:
test_service_security.py."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

zenoh = pytest.importorskip("zenoh")

from service.zenoh_service.client import ScheduleClient, ServiceError  # noqa: E402
from service.zenoh_service.session import zenoh_config  # noqa: E402
from tests.zenoh_helpers import CUT, P5, ROOT, certificates, free_port, late_subscriber, serve, start_service  # noqa: E402


@pytest.fixture(scope="module")
def service(model_dir, tmp_path_factory):
    svc, endpoint = start_service(model_dir, tmp_path_factory.mktemp("state"), "cell1", max_payload_bytes=4096, queue_size=2)
    yield svc, endpoint
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
    for key in ("model_version", "service_id", "computed_at", "stale_after_s"):
        assert key in got
        got.pop(key)
    assert got == expected


def test_every_bad_input_gets_its_error_and_the_service_keeps_answering(client):
    cases = {
        b"{": "malformed_json",
        b"\xff\xfe": "malformed_json",
        b'{"pose": {"x_mm": 1400, "x_mm": 9000, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "malformed_json",  # a key twice: which counts?
        b"": "missing_payload",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800}}': "missing_field",
        b'{"pose": {"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0, "speed": 3}}': "unknown_field",
        b'{"pose": {"x_mm": NaN, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "not_finite",
        b'{"pose": {"x_mm": 1e999, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "not_finite",
        b'{"pose": {"x_mm": "far", "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "invalid_field",
        b'{"pose": {"x_mm": 9000, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "unreachable_pose",  # out of reach first
        b'{"pose": {"x_mm": 2100, "y_mm": 0, "z_mm": 800, "beta_deg": 0}}': "outside_workspace",
        b'{"pose": {"x_mm": 1400, "y_mm": 300, "z_mm": 800, "beta_deg": 0}}': "outside_workspace",  # y: all training poses at 0
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


def test_a_worker_that_dies_is_an_error_reply_and_the_service_goes_on(service, client):
    """Kill the worker process in the middle of a computation: the querier gets `internal` at
    once (not a timeout), the pool is started again and the next query is answered."""
    svc, _ = service

    def kill_when_computing():
        deadline = time.monotonic() + 10
        while svc.status()["computing"] == 0 and time.monotonic() < deadline:
            time.sleep(0.001)
        for pid in svc.pool.pids():
            os.kill(pid, signal.SIGKILL)

    killer = threading.Thread(target=kill_when_computing)
    killer.start()
    start = time.monotonic()
    with pytest.raises(ServiceError) as err:
        client.schedule({"x_mm": 1333.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0})
    killer.join()
    assert err.value.code == "internal" and "worker process died" in err.value.message
    assert time.monotonic() - start < 15
    assert client.schedule(P5)["critical_depth_mm"] > 0  # from the cache
    assert client.schedule({"x_mm": 1334.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0})["critical_depth_mm"] > 0  # a new worker computes it


def test_a_plan_is_published_live_entry_by_entry_and_whole_to_late_subscribers(service, client):
    poses = [dict(P5, pose_id="a"), {"pose_id": "b", "x_mm": 1500.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}]
    live = []
    with zenoh.open(zenoh_config(None, "client", connect=[service[1]])) as s:
        sub = s.declare_subscriber("cells/cell1/posedyn/schedules/job-7/*", lambda sample: live.append(json.loads(sample.payload.to_bytes())))
        time.sleep(0.3)
        plan = client.plan("job-7", poses, timeout_s=60)
        deadline = time.monotonic() + 10
        while len(live) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        sub.undeclare()
    assert [e["pose_id"] for e in plan["entries"]] == ["a", "b"]
    assert sorted(e["pose_id"] for e in live) == ["a", "b"]
    whole = late_subscriber(service[1], "cells/cell1/posedyn/schedules/job-7")
    assert whole and whole[-1]["plan_id"] == "job-7" and whole[-1]["entries"] == plan["entries"]
    assert client.stored_plan("job-7")["entries"] == plan["entries"]


def test_a_timed_plan_carries_the_coils_trajectory(service, client):
    """A plan with the poses' times (`times_s`) also carries the coil's planned voltage, current
    and field through the entries' targets (absorber.field_plan, in a worker); after the first
    node (the coil starts without field) the absorber is on each entry's target. Times that go
    back are refused."""
    poses = [dict(P5, pose_id="a"), {"pose_id": "b", "x_mm": 1600.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0},
             {"pose_id": "c", "x_mm": 1200.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}]
    plan = client.plan("timed-1", poses, timeout_s=60, times_s=[0.0, 1.0, 2.0])
    trajectory = plan["trajectory"]
    assert plan["times_s"] == [0.0, 1.0, 2.0] and trajectory["solver"]["status"] == "solved"
    assert len(trajectory["current_a"]) == 3 and len(trajectory["voltage_v"]) == 2
    for f, e in zip(trajectory["frequency_hz"][1:], plan["entries"][1:]):
        assert f == pytest.approx(e["absorber"]["target_hz"], rel=1e-3)
    assert client.stored_plan("timed-1")["trajectory"] == trajectory
    with pytest.raises(ServiceError) as bad:
        client.plan("timed-2", poses, timeout_s=10, times_s=[0.0, 2.0, 1.0])
    assert bad.value.code == "invalid_field" and "times_s" in bad.value.message


def test_a_killed_service_restarts_with_its_plans(model_dir, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    state = tmp_path / "state"
    proc = serve(model_dir, state, endpoint)
    try:
        with ScheduleClient("cell2", connect=[endpoint], timeout_s=30) as c:
            plan = c.plan("last", [P5])
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert list((state / "plans").glob("*.json")) == [state / "plans" / "last.json"]
    proc = serve(model_dir, state, endpoint)
    try:
        got = late_subscriber(endpoint, "cells/cell2/posedyn/schedules/last")
        assert got and got[-1]["entries"] == plan["entries"]
    finally:
        proc.send_signal(signal.SIGTERM)  # graceful: closes the session, exits 0
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "stopped" in out


def test_tls_works_and_a_client_without_the_certificate_is_refused(model_dir, tmp_path):
    if not __import__("shutil").which("openssl"):
        pytest.skip("openssl is needed to make the test certificates")
    certs = certificates(tmp_path, clients=())
    port = free_port()
    server_conf = tmp_path / "server.json5"
    server_conf.write_text(json.dumps({"transport": {"link": {"tls": {"listen_private_key": certs["server.key"], "listen_certificate": certs["server.pem"], "root_ca_certificate": certs["ca.pem"]}}}}))
    client_conf = tmp_path / "client.json5"
    client_conf.write_text(json.dumps({"transport": {"link": {"tls": {"root_ca_certificate": certs["ca.pem"]}}}}))
    endpoint = f"tls/localhost:{port}"
    proc = serve(model_dir, tmp_path / "state", endpoint, ["--config", str(server_conf)])
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


def test_query_reads_its_request_before_connecting_and_an_unreachable_service_is_no_reply(tmp_path):
    """A query to an endpoint where nothing listens exited 2 ('column --connect', as for bad
    input) although the README says no reply exits 3, and a malformed --pose-json was found only
    after connecting. The request is read first (exit 2 at once), and a session that reaches
    nothing is exit 3 'no_session'."""
    from tests.cli_helpers import run_cli

    nowhere = f"tcp/127.0.0.1:{free_port()}"
    bad = run_cli("query", "--cell", "c", "--connect", nowhere, "--pose-json", "{not json", "--timeout-s", "2")
    assert bad.returncode == 2 and "--pose-json" in bad.stderr
    # NaN / Infinity (not JSON: the request could not be sent) and an empty plan were tracebacks
    for option, text in (("--pose-json", json.dumps({**P5, "x_mm": float("nan")})), ("--pose-json", "[1, 2]")):
        bad = run_cli("query", "--cell", "c", "--connect", nowhere, option, text, "--timeout-s", "2")
        assert bad.returncode == 2 and bad.stderr.startswith(f"error: option '{option}': expected a JSON object"), bad.stderr
    bad = run_cli("query", "--cell", "c", "--connect", nowhere, "--pose-json", json.dumps(P5), "--cut-json", '{"rpm": Infinity}', "--timeout-s", "2")
    assert bad.returncode == 2 and "Infinity is not a JSON number" in bad.stderr
    # valid JSON the service would refuse (it was sent, and its refusal or no_session was exit 3)
    for option, text, said in (("--pose-json", json.dumps({**P5, "x_mm": "a"}), "pose.x_mm: expected a number"),
                               ("--cut-json", '{"teeth": 0}', "cut.teeth: expected an integer")):
        args = ["--pose-json", json.dumps(P5), option, text] if option == "--cut-json" else [option, text]
        bad = run_cli("query", "--cell", "c", "--connect", nowhere, *args, "--timeout-s", "2")
        assert bad.returncode == 2 and bad.stderr.startswith(f"error: option '{option}'") and said in bad.stderr, bad.stderr
    # flags judged before connecting (a wildcard cell, Zenoh's debug text for a bad endpoint, a plan id the service refuses after a 6 s wait)
    for flags, flag in ((["--cell", "c/**", "--connect", nowhere], "--cell"), (["--cell", "c", "--connect", "garbage"], "--connect"),
                        (["--cell", "c", "--connect", nowhere, "--timeout-s", "-1"], "--timeout-s")):
        bad = run_cli("query", *flags, "--pose-json", json.dumps(P5))
        assert bad.returncode == 2 and bad.stderr.startswith(f"error: option '{flag}'"), bad.stderr
    path = tmp_path / "p5.csv"
    path.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\n")
    bad = run_cli("query", "--cell", "c", "--connect", nowhere, "--plan", path, "--plan-id", "../etc", "--timeout-s", "2")
    assert bad.returncode == 2 and bad.stderr.startswith("error: option '--plan-id'")
    empty = tmp_path / "path.csv"
    empty.write_text("")
    bad = run_cli("query", "--cell", "c", "--connect", nowhere, "--plan", empty, "--timeout-s", "2")
    assert bad.returncode == 2 and bad.stderr.startswith(f"error: {empty}: expected a CSV")
    unreachable = run_cli("query", "--cell", "c", "--connect", nowhere, "--pose-json", json.dumps(P5), "--timeout-s", "2")
    assert unreachable.returncode == 3 and "no_session" in unreachable.stderr and nowhere in unreachable.stderr


def test_query_cli_reports_errors_and_zero_replies(service, tmp_path):
    base = [sys.executable, "-c", "from service.cli import main; main()", "query", "--cell", "cell1", "--connect", service[1], "--timeout-s", "20"]
    ok = subprocess.run(base + ["--pose-json", json.dumps(P5), "--json"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["pose_id"] == "P5"
    bad = subprocess.run(base + ["--pose-json", '{"x_mm": 1}'], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert bad.returncode == 2 and "missing_field" in bad.stderr  # the service's own check, before connecting
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
    got = late_subscriber(service[1], "cells/cell1/posedyn/schedules/put-1", wait_s=30)
    assert got and got[-1]["entries"][0]["pose_id"] == "p"
    with ScheduleClient("cell1", connect=[service[1]]) as c:
        assert c.status()["plans_published"] >= 1
