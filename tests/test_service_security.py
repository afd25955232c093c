"""Issue 20, item 3: who may write to the service's keys and whose answers the cell believes,
with real Zenoh sessions on 127.0.0.1: the default access control, the client's checks against
a rogue queryable (second source, pinned service id, HMAC signatures), and the shipped locked-
down example (mutual TLS + ACL) as it is shipped."""

from __future__ import annotations

import json
import re
import shutil
import signal
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")

from service.zenoh_service.client import ScheduleClient, ServiceError  # noqa: E402
from service.zenoh_service.session import zenoh_config  # noqa: E402
from tests.zenoh_helpers import P5, ROOT, certificates, free_port, serve, session, start_service  # noqa: E402

KEY = b"k" * 16 + b"0123456789abcdef"
FORGED = {"pose_id": "P5", "critical_depth_mm": 99.0, "service_id": "0" * 32}


@pytest.fixture(scope="module")
def service(model_dir, tmp_path_factory):
    svc, endpoint = start_service(model_dir, tmp_path_factory.mktemp("state"), "cell4", signing_key=KEY)
    with ScheduleClient("cell4", connect=[endpoint], timeout_s=60) as c:
        c.schedule(P5)
    yield svc, endpoint
    svc.close()


def _rogue_queryable(s, key: str):
    def answer(query):
        query.reply(query.key_expr, json.dumps(FORGED).encode())
        query.drop()

    return s.declare_queryable(key, answer, complete=True)


def test_by_default_nobody_else_writes_the_services_keys(service):
    """An anonymous session connected to the service: its put on `schedules/**` does not reach
    the cell's subscriber (the service's own publication does), its `schedule` queryable is not
    routed (the cell gets the service's one answer), its `alive` token is not either."""
    svc, endpoint = service
    received = []
    with session(endpoint) as cell, session(endpoint) as rogue:
        sub = cell.declare_subscriber("cells/cell4/posedyn/schedules/**", lambda s: received.append(json.loads(s.payload.to_bytes())))
        queryable = _rogue_queryable(rogue, "cells/cell4/posedyn/schedule")
        token = rogue.liveliness().declare_token("cells/cell4/posedyn/alive")
        time.sleep(0.5)
        rogue.put("cells/cell4/posedyn/schedules/job/0", json.dumps(FORGED))
        with ScheduleClient("cell4", connect=[endpoint], timeout_s=60) as c:
            entry = c.schedule(P5)  # one source: no conflicting_replies, the service's document
            c.plan("signed-job", [P5])
            alive = list(c.session.liveliness().get("cells/cell4/posedyn/alive", timeout=3))
        time.sleep(0.5)
        queryable.undeclare()
        token.undeclare()
        sub.undeclare()
    assert entry["service_id"] == svc.service_id and entry["critical_depth_mm"] != FORGED["critical_depth_mm"]
    assert received and all(r.get("service_id") != FORGED["service_id"] and r.get("critical_depth_mm") != 99.0 for r in received)
    assert len(alive) == 1 and str(alive[0].ok.key_expr) == "cells/cell4/posedyn/alive"


def test_the_client_refuses_a_rogue_queryable_it_can_reach(service):
    """A rogue peer the cell's session reaches directly (not through the service, so no access
    control of the service's applies): two sources answer. By default the client refuses the
    answer (`conflicting_replies`); pinned to the service's id, or with the signing key, it takes
    the service's answer and ignores the rogue's."""
    svc, endpoint = service
    rogue_endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(zenoh_config(None, "peer", listen=[rogue_endpoint])) as rogue:
        queryable = _rogue_queryable(rogue, "cells/cell4/posedyn/schedule")
        both = [endpoint, rogue_endpoint]
        with ScheduleClient("cell4", connect=both, mode="peer", timeout_s=20) as c:
            time.sleep(0.5)
            with pytest.raises(ServiceError) as err:
                c.schedule(P5)
            assert err.value.code == "conflicting_replies"
        with ScheduleClient("cell4", connect=both, mode="peer", timeout_s=20, service_id=svc.service_id) as c:
            time.sleep(0.5)
            assert c.schedule(P5)["service_id"] == svc.service_id
        with ScheduleClient("cell4", connect=both, mode="peer", timeout_s=20, signing_key=KEY) as c:
            time.sleep(0.5)
            assert c.schedule(P5)["critical_depth_mm"] != FORGED["critical_depth_mm"]
        queryable.undeclare()
    alone = f"tcp/127.0.0.1:{free_port()}"
    conf = zenoh_config(None, "peer", listen=[alone])
    conf.insert_json5("scouting/gossip/enabled", "false")  # a rogue that knows nothing of the service
    with zenoh.open(conf) as rogue:
        queryable = _rogue_queryable(rogue, "cells/cell4/posedyn/schedule")
        with ScheduleClient("cell4", connect=[alone], timeout_s=5, signing_key=KEY) as c:
            with pytest.raises(ServiceError) as err:  # only the rogue answers: its unsigned answer is refused
                c.schedule(P5)
            assert err.value.code == "refused_replies"
        queryable.undeclare()


def test_signed_replies_cannot_be_replayed_to_another_request(service):
    from service.zenoh_service.signing import reply_signature, sample_signature

    svc, endpoint = service
    key = "cells/cell4/posedyn/schedule"
    request = json.dumps({"pose": P5}).encode()
    with session(endpoint) as s:
        reply = next(iter(s.get(key, payload=request, timeout=20)))
    body, signature = reply.ok.payload.to_bytes(), reply.ok.attachment.to_bytes()
    assert signature == reply_signature(KEY, key, request, body)
    assert signature != reply_signature(KEY, key, json.dumps({"pose": dict(P5, x_mm=1500.0)}).encode(), body)
    got = []
    with ScheduleClient("cell4", connect=[endpoint], signing_key=KEY, timeout_s=60) as c:
        sub = c.session.declare_subscriber("cells/cell4/posedyn/schedules/signed-2/*", lambda sample: got.append(c.verify_sample(sample)))
        time.sleep(0.3)
        c.plan("signed-2", [P5])
        time.sleep(0.5)
        sub.undeclare()
    assert got == [True]
    assert sample_signature(KEY, "a", b"x") != sample_signature(KEY, "b", b"x")


@pytest.mark.skipif(not shutil.which("openssl"), reason="openssl makes the test certificates")
def test_the_locked_down_example_lets_only_the_controller_in(model_dir, tmp_path):
    """The shipped mTLS + ACL example, certificate paths substituted: the controller queries and
    sends plans; a session with a certificate from the same CA but another name gets nothing
    (access control is silent: `no_reply`); the controller cannot publish on the service's keys;
    a session without a certificate cannot connect."""
    certs = tmp_path / "certs"
    certs.mkdir()
    certificates(certs, clients=("cell1-controller", "intruder"))
    (certs / "credentials.txt").write_text("cell1:change-me-cell1\nintruder:change-me-intruder\n")

    def shipped(name: str, replace: dict) -> Path:
        text = (ROOT / "service/zenoh_service/config" / name).read_text().replace('"certs/', f'"{certs}/')
        for old, new in replace.items():
            text = text.replace(old, new)
        out = tmp_path / (name if not replace else "intruder-" + name)
        out.write_text(text)
        return out

    server_conf = shipped("server-mtls-acl.json5", {})
    controller = shipped("client-mtls.json5", {})
    intruder = shipped("client-mtls.json5", {"cell1-controller.": "intruder.", "change-me-cell1": "change-me-intruder", 'user: "cell1"': 'user: "intruder"'})
    port = free_port()
    endpoint = f"tls/localhost:{port}"
    proc = serve(model_dir, tmp_path / "state", endpoint, ["--config", str(server_conf)], cell="cell1")
    try:
        with ScheduleClient("cell1", connect=[endpoint], config=controller, timeout_s=60) as c:
            assert c.schedule(P5)["pose_id"] == "P5"
            received = []
            sub = c.session.declare_subscriber("cells/cell1/posedyn/schedules/**", lambda s: received.append(json.loads(s.payload.to_bytes())))
            time.sleep(0.5)
            with ScheduleClient("cell1", connect=[endpoint], config=controller) as other:  # another session: no local delivery
                other.session.put("cells/cell1/posedyn/schedules/forged/0", json.dumps(FORGED))
                other.session.put("cells/cell1/posedyn/plan/by-put", json.dumps({"poses": [dict(P5, pose_id="put")]}))
                time.sleep(0.5)
            deadline = time.monotonic() + 30
            while not any(r.get("plan_id") == "by-put" or r.get("pose_id") == "put" for r in received) and time.monotonic() < deadline:
                time.sleep(0.1)
            sub.undeclare()
        assert any(r.get("pose_id") == "put" for r in received)  # the service's publication of the controller's plan
        assert all(r.get("critical_depth_mm") != 99.0 for r in received)  # the controller's forged put was dropped
        with ScheduleClient("cell1", connect=[endpoint], config=intruder, timeout_s=3) as c:
            with pytest.raises(ServiceError) as err:
                c.schedule(P5)
            assert err.value.code == "no_reply" and "access control" in err.value.message
        refused = True
        try:
            with ScheduleClient("cell1", connect=[endpoint], timeout_s=3) as c:
                c.schedule(P5)
            refused = False
        except (zenoh.ZError, ServiceError):
            pass
        assert refused
    finally:
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0


def test_readme_security_section_names_the_default_and_the_locked_down_example():
    readme = (ROOT / "README.md").read_text()
    section = re.search(r"### Security(.*?)\n## ", readme, re.S)
    assert section, "README: a Security section under the service"
    for words in ("127.0.0.1:7447", "server-mtls-acl.json5", "--signing-key", "--service-id", "no_reply"):
        assert words in section.group(1), words
