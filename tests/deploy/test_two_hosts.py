"""Two hosts for real: network namespaces joined by veth pairs act as the rig PC, the remote
host and the router host; haptic-master and haptic-slave run a short session through
haptic-router over mutual TLS with the shipped configurations (deploy/zenoh/, router-tls.toml).
Then: a client whose certificate is of another CA cannot connect, and one with a certificate
of the deployment's CA whose CN the access control does not name gets no handle or tool
message through (the receiving side sees none, while the master's certificate does).

A second session runs the direct-peer topology (deploy/zenoh/peer-*.json5, two-hosts-tls.toml)
between the rig and the remote host.

The namespaces ``hap-{rig,remote,router}-<pid>`` and their veth pairs (10.200.1.0/30 rig to
router, 10.200.2.0/30 remote to router, 10.200.3.0/30 rig to remote: private addresses that
exist only inside them) are
made and removed here; every process is ended by its own PID and reaped. Skips, with the
reason, where network namespaces cannot be made (no CAP_NET_ADMIN, no iproute2)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers.programs import Program, Programs

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
ZENOH = DEPLOY / "zenoh"
PID = os.getpid()
NS = {name: f"hap-{name}-{PID}" for name in ("rig", "remote", "router")}
# veth pairs: (namespace, veth, address) at each end
PAIRS = (
    (("rig", f"hapr{PID}a", "10.200.1.1/30"), ("router", f"hapr{PID}b", "10.200.1.2/30")),
    (("remote", f"hapm{PID}a", "10.200.2.1/30"), ("router", f"hapm{PID}b", "10.200.2.2/30")),
    (("rig", f"hapd{PID}a", "10.200.3.1/30"), ("remote", f"hapd{PID}b", "10.200.3.2/30")),
)
ROUTER_FOR = {"rig": "tls/10.200.1.2:7447", "remote": "tls/10.200.2.2:7447"}
MASTER_DIRECT = "tls/10.200.3.1:7447"  # the rig PC as the direct peers' listener
SESSION_S = 2.0

pytestmark = pytest.mark.slow

PROBE = r'''
"""listen|send SIDE ENDPOINT SECONDS CERT-OVERRIDES-JSON ZENOH-FILE: a Link of SIDE; listen
counts the peer's messages, send publishes this side's; prints one JSON line."""
import json, sys, time
from haptic.common.config import load_config
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import link_config_from
role, side, endpoint, seconds, overrides, zfile = sys.argv[1:7]
# Without the shipped file the probe is TLS without a certificate of its own: the protected
# mode would refuse it before Zenoh does; insecure lets the test see the router refuse it.
config = link_config_from(load_config(), side, mode="client", connect=(endpoint,), listen=(),
                          key_prefix="haptic/rig-1", zenoh_config_file=zfile or None,
                          zenoh_overrides=tuple(map(tuple, json.loads(overrides))),
                          insecure=not zfile)
try:
    link = Link(config).open()
except Exception as error:
    print(json.dumps({"opened": False, "error": " ".join(str(error).split())[:200]}), flush=True)
    sys.exit(0)
with link:
    print(json.dumps({"opened": True}), flush=True)
    count, sent, end = 0, 0, time.monotonic() + float(seconds)
    while time.monotonic() < end:
        if role == "send":
            if side == "master":
                link.send_handle((1.0, 1.0), (0.0, 0.0))
            else:
                link.send_tool((1.0, 1.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
            sent += 1
        elif link.poll() is not None:
            count += 1
        time.sleep(0.005)
    print(json.dumps({"opened": True, "received": count, "sent": sent}), flush=True)
'''


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check,
                          timeout=20)


def remove_network() -> None:
    for ns in NS.values():
        ip("netns", "delete", ns, check=False)  # takes its veth ends (and their peers) along
    for ends in PAIRS:
        ip("link", "delete", ends[0][1], check=False)  # only if it never left the root ns


@pytest.fixture(scope="module")
def network() -> Iterator[None]:
    if shutil.which("ip") is None:
        pytest.skip("iproute2 ('ip') is not installed: cannot make network namespaces")
    probe = ip("netns", "add", NS["rig"], check=False)
    if probe.returncode != 0:
        pytest.skip(f"cannot make network namespaces ({probe.stderr.strip()}): the two-host "
                    "test needs CAP_NET_ADMIN")
    try:
        for name in ("remote", "router"):
            ip("netns", "add", NS[name])
        for ns in NS.values():
            ip("-n", ns, "link", "set", "lo", "up")
        for ends in PAIRS:
            ip("link", "add", ends[0][1], "type", "veth", "peer", "name", ends[1][1])
            for host, veth, address in ends:
                ip("link", "set", veth, "netns", NS[host])
                ip("-n", NS[host], "addr", "add", address, "dev", veth)
                ip("-n", NS[host], "link", "set", veth, "up")
        yield
    finally:
        remove_network()


def start_on(programs: Programs, host: str, args: list[str]) -> Program:
    """Start ``python args`` in ``host``'s namespace; ``ip netns exec`` execs the command, so
    the PID the launcher ends is the program's own."""
    return programs.start(["ip", "netns", "exec", NS[host], sys.executable, *args],
                          stop_signal=signal.SIGTERM)


def zenoh_set(overrides) -> list[str]:
    return [arg for key, value in overrides for arg in ("--zenoh-set", f"{key}={value}")]


def probe(programs: Programs, tmp_path: Path, role: str, host: str, side: str,
          overrides, seconds: float, shipped_file: bool = True) -> Program:
    script = tmp_path / "probe.py"
    script.write_text(PROBE)
    zenoh_file = ZENOH / f"client-{side}.json5" if shipped_file else ""
    return start_on(
        programs, host, [str(script), role, side, ROUTER_FOR[host], repr(seconds),
                         json.dumps([list(pair) for pair in overrides]), str(zenoh_file)])


def result(probed: Program, timeout_s: float = 30.0) -> dict:
    probed.wait(timeout_s=timeout_s)
    lines = [line for line in probed.output().splitlines() if line.startswith("{")]
    assert lines, f"probe printed nothing: {probed.output()[-2000:]}"
    return json.loads(lines[-1])


def exchange(programs, tmp_path, sender_host, sender_side, sender_certs, receiver_certs):
    """Messages a receiver (the other side, the deployment's own certificate) in the other
    namespace gets while ``sender_side`` publishes for 2 s with ``sender_certs``."""
    receiver_side = "slave" if sender_side == "master" else "master"
    receiver_host = "remote" if sender_host == "rig" else "rig"
    receiver = probe(programs, tmp_path, "listen", receiver_host, receiver_side,
                     receiver_certs, 5.0)
    assert json.loads(receiver.wait_for(r"^\{.*\}$", timeout_s=30.0).group(0))["opened"]
    time.sleep(0.5)  # the receiver's subscription reaches the router
    sender = probe(programs, tmp_path, "send", sender_host, sender_side, sender_certs, 2.0)
    sent, received = result(sender), result(receiver)
    assert sent["opened"], sent
    assert sent["sent"] > 100
    return received["received"]


def run_session(programs: Programs, certs, out: Path, topology: str) -> float:
    """Slave on the remote host, master (``--rig model``) on the rig for SESSION_S, over
    ``topology`` (``router``: clients of the router that must already run; ``peers``: direct);
    checks both summaries and returns the session's wall time (start of the slave to the
    end of both programs), s."""
    summaries = {side: out / f"{side}.json" for side in ("master", "slave")}
    toml = "router-tls.toml" if topology == "router" else "two-hosts-tls.toml"
    common = ["--config", str(DEPLOY / toml), "--no-status", "--peer-wait", "30"]
    if topology == "router":
        ends = {"master": ["--connect", ROUTER_FOR["rig"]],
                "slave": ["--connect", ROUTER_FOR["remote"]]}
        files = {side: ZENOH / f"client-{side}.json5" for side in summaries}
    else:
        ends = {"master": ["--listen", MASTER_DIRECT], "slave": ["--connect", MASTER_DIRECT]}
        files = {side: ZENOH / f"peer-{side}.json5" for side in summaries}
    started = time.monotonic()
    slave = start_on(programs, "remote", [
        "-m", "haptic.slave_sim.cli", *common, *ends["slave"],
        "--zenoh-config", str(files["slave"]), *zenoh_set(certs.tls_overrides("slave")),
        "--duration", repr(SESSION_S + 20), "--scenario", "constant-rate", "--out", str(out),
        "--json-summary", str(summaries["slave"])])
    master = start_on(programs, "rig", [
        "-m", "haptic.master.cli", *common, *ends["master"],
        "--zenoh-config", str(files["master"]), *zenoh_set(certs.tls_overrides("master")),
        "--rig", "model", "--duration", repr(SESSION_S),
        "--json-summary", str(summaries["master"])])
    assert master.wait(timeout_s=60) == 0, master.output()
    # the session is over: stop the slave
    assert slave.stop(signal.SIGTERM, grace_s=20) == 0, slave.output()
    elapsed = time.monotonic() - started
    for side, path in summaries.items():
        summary = json.loads(path.read_text())
        assert summary["steps"] > 0, side
        # the other side's messages arrived: a measured one-way delay, forces
        assert summary["link_one_way_delay_p50_s"] is not None, side
        assert summary["max_abs_force_N"] > 0.0, side
        # the protected mode admitted the session for its mutual TLS, not an --insecure
        assert summary["link_protection"] == "mutual TLS", side
        print(f"{topology}: {side} received p50 {summary['link_one_way_delay_p50_s'] * 1e6:.0f}"
              f" us p99 {summary['link_one_way_delay_p99_s'] * 1e6:.0f} us, "
              f"max |force| {summary['max_abs_force_N']:.2f} N")
    print(f"{topology}: session of {SESSION_S:g} s over mutual TLS: {elapsed:.1f} s wall")
    return elapsed


def test_session_and_access_control_through_the_router(network, certs, tmp_path):
    with Programs() as programs:
        router = start_on(
            programs, "router",
            ["-m", "haptic.common.wire.router.cli", "--zenoh-config", str(ZENOH / "router.json5"),
             *[arg for host in ("rig", "remote") for arg in ("--listen", ROUTER_FOR[host])],
             *zenoh_set(certs.tls_overrides("router"))])
        router.wait_for("listening", timeout_s=60.0)
        run_session(programs, certs, tmp_path / "out", "router")

        good = certs.tls_overrides
        # control: the master's own certificate gets handle messages through
        assert exchange(programs, tmp_path, "rig", "master", good("master"), good("slave")) > 0
        # a valid certificate whose CN the access control does not name: nothing arrives
        assert exchange(programs, tmp_path, "rig", "master", good("intruder"),
                        good("slave")) == 0
        assert exchange(programs, tmp_path, "remote", "slave", good("intruder"),
                        good("master")) == 0
        # a certificate of another CA: no session at all
        rogue = result(probe(programs, tmp_path, "send", "rig", "master",
                             good("master", rogue=True), 1.0))
        assert not rogue["opened"] and "connect" in rogue["error"].lower(), rogue
        # TLS that trusts the CA but presents no certificate of its own: no session either
        ca_only = (("transport/link/tls/root_ca_certificate", f'"{certs.good / "ca.pem"}"'),)
        anonymous = result(probe(programs, tmp_path, "send", "rig", "master", ca_only, 1.0,
                                 shipped_file=False))
        assert not anonymous["opened"] and "connect" in anonymous["error"].lower(), anonymous


def test_session_between_direct_peers(network, certs, tmp_path):
    with Programs() as programs:
        run_session(programs, certs, tmp_path / "out", "peers")
