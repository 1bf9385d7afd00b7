"""deploy/secure/ as written: TLS + mutual TLS + ACL on loopback, with throwaway certificates.

The recipe's files are used verbatim except for the certificate folder and the router's address
(the paths an operator substitutes too). The router is a Zenoh session in "router" mode.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest
import zenoh

from helpers.zenoh_loopback import collect, free_port
from vpp_service.service.app import run_service
from vpp_service.service.config import read_toml, validate_config
from vpp_service.sources.base import SourceContext, build_source
from vpp_service.transport import wire

SECURE = Path(__file__).resolve().parents[1] / "deploy" / "secure"

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl (make-certs.sh)")


class Site:
    """Throwaway certificates and the recipe's configs rewritten for a loopback port."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.port = free_port()
        self.certs = tmp / "certs"
        self.other = tmp / "other-ca"
        make = ["bash", str(SECURE / "make-certs.sh")]
        subprocess.run([*make, str(self.certs), "127.0.0.1"], check=True, capture_output=True)
        subprocess.run([*make, str(self.other), "127.0.0.1", "rig0"], check=True, capture_output=True)

    def config_file(self, name: str, certs: Path | None = None, replace: dict[str, str] | None = None) -> Path:
        """``deploy/secure/<name>.json5`` with the certificate folder and the router address substituted."""
        text = (SECURE / f"{name}.json5").read_text()
        text = text.replace("/etc/vpp-service/tls/", f"{certs or self.certs}/")
        text = text.replace("tls/0.0.0.0:7447", f"tls/127.0.0.1:{self.port}")
        text = text.replace("tls/router.example:7447", f"tls/127.0.0.1:{self.port}")
        for old, new in (replace or {}).items():
            assert old in text, old
            text = text.replace(old, new)
        path = self.tmp / f"{name}-{len(list(self.tmp.glob('*.json5')))}.json5"
        path.write_text(text)
        return path

    def client(self, name: str, **kw: object) -> zenoh.Session:
        return zenoh.open(zenoh.Config.from_file(str(self.config_file(name, **kw))))

    def rig(self, cert: str, certs: Path | None = None) -> zenoh.Session:
        """A rig publisher's session (rig0.json5) presenting certificate ``cert``."""
        return self.client("rig0", certs=certs, replace={"rig0-key.pem": f"{cert}-key.pem", "rig0.pem": f"{cert}.pem"})

    def service_config(self) -> dict:
        data = read_toml(SECURE / "vpp-service.toml")
        data["service"].update(out=str(self.tmp / "out"), summary=False)
        data["zenoh"]["connect"] = [f"tls/127.0.0.1:{self.port}"]
        data["zenoh"]["config_file"] = str(self.config_file("service"))
        data["matcher"]["max_disparity"] = 16  # the small frames below
        return data


def frames(rig: str, n: int) -> list[bytes]:
    src = build_source(
        "sim",
        {"scene": "synthetic", "scene_options": {"height": 48, "width": 96, "max_disparity": 16}, "count": n},
        SourceContext(rig=rig),
    )
    src.open()
    return [wire.encode_frame(src.frame(i).with_(rig=rig, seq=i)) for i in range(n)]


def status(session: zenoh.Session, rig: str = "rig0") -> dict | None:
    for reply in session.get(f"vpp/{rig}/@status", timeout=3.0):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_string())
    return None


@pytest.fixture
def site(tmp_path):
    site = Site(tmp_path)
    router = zenoh.open(zenoh.Config.from_file(str(site.config_file("router"))))
    stop = threading.Event()
    result: dict = {}
    svc = threading.Thread(
        target=lambda: result.update(run_service(validate_config(site.service_config()), stop, None))
    )
    svc.start()
    try:
        yield site
    finally:
        stop.set()
        svc.join(20)
        router.close()
    assert not svc.is_alive() and result["source_error"] is None


def wait_status(viewer: zenoh.Session, timeout: float = 10.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        st = status(viewer)
        if st is not None:
            return st
        time.sleep(0.2)
    raise AssertionError("no @status reply through the router")


def test_authorized_rig_gets_results_viewer_reads_outputs_and_status(site):
    with site.client("viewer") as viewer, site.rig("rig0") as rig:
        wait_status(viewer)
        rig_sub = rig.declare_subscriber("vpp/rig0/out/disparity", zenoh.handlers.FifoChannel(64))
        view_sub = viewer.declare_subscriber("vpp/rig0/out/disparity", zenoh.handlers.FifoChannel(64))
        pub = rig.declare_publisher("vpp/rig0/in/frame", congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.5)  # declarations reach the router
        for payload in frames("rig0", 5):
            pub.put(payload)
            time.sleep(0.05)
        assert len(collect(rig_sub, 5, timeout=10.0)) == 5, "the rig got no results"
        assert len(collect(view_sub, 5, timeout=5.0)) == 5, "the viewer got no outputs"
        st = status(viewer)
        assert st is not None and st["counters"]["processed"] == 5 and st["zenoh"]["routers"] == 1
        assert status(rig) is not None  # a rig reads its own status


def _no_certificate(site: Site) -> Path:
    off = {
        'connect_private_key: "': '// connect_private_key: "',
        'connect_certificate: "': '// connect_certificate: "',
        "enable_mtls: true": "enable_mtls: false",
    }
    return site.config_file("rig0", replace=off)


def _certificate_of_another_ca(site: Site) -> Path:
    # its key and certificate come from another CA; it still trusts the site CA to verify the router
    other = {f"{site.certs}/rig0{x}": f"{site.other}/rig0{x}" for x in ("-key.pem", ".pem")}
    return site.config_file("rig0", replace=other)


def _trusts_another_ca(site: Site) -> Path:
    return site.config_file("rig0", certs=site.other)  # everything from another site: the router is not trusted


@pytest.mark.parametrize("config", [_no_certificate, _certificate_of_another_ca, _trusts_another_ca])
def test_unauthenticated_clients_are_refused(site, config):
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        zenoh.open(zenoh.Config.from_file(str(config(site))))


def test_another_rigs_certificate_cannot_publish_into_rig0(site):
    """rig1's certificate is authenticated, but nothing it puts on rig0's keys reaches the service."""
    with site.client("viewer") as viewer, site.rig("rig1") as rig1:
        before = wait_status(viewer)["counters"]["received"]
        sub = rig1.declare_subscriber("vpp/rig0/out/disparity", zenoh.handlers.FifoChannel(64))
        pub = rig1.declare_publisher("vpp/rig0/in/frame", congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.5)
        for payload in frames("rig0", 3):
            pub.put(payload)
        time.sleep(1.0)
        assert status(viewer)["counters"]["received"] == before
        assert status(rig1) is None  # nor may it read rig0's status
        assert collect(sub, 1, timeout=0.5) == []
