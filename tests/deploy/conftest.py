"""Test certificates made at test time by deploy/make_certs.sh (no key is committed)."""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
# Addresses the two-host test gives the router and the rig (the direct peers' listener) inside
# its own network namespaces.
ROUTER_SANS = ("IP:10.200.1.2", "IP:10.200.2.2", "IP:10.200.3.1")


@dataclass(frozen=True)
class Certs:
    """``good``: CA + router, master, slave and intruder (CN haptic-intruder, same CA);
    ``rogue``: an unrelated CA and a master certificate signed by it."""

    good: Path
    rogue: Path

    def tls_overrides(self, name: str, rogue: bool = False) -> tuple[tuple[str, str], ...]:
        """Zenoh ``(key, json5)`` overrides pointing the shipped configs at ``name``'s files."""
        folder = self.rogue if rogue else self.good
        pairs = [("root_ca_certificate", folder / "ca.pem")]
        for end in ("listen", "connect"):
            pairs += [(f"{end}_private_key", folder / f"{name}.key"),
                      (f"{end}_certificate", folder / f"{name}.pem")]
        return tuple((f"transport/link/tls/{key}", f'"{path}"') for key, path in pairs)


@pytest.fixture(scope="session")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Certs:
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: deploy/make_certs.sh needs it")
    root = tmp_path_factory.mktemp("certs")
    script = str(DEPLOY / "make_certs.sh")
    sans = [arg for san in ROUTER_SANS for arg in ("--san", san)]
    subprocess.run([script, str(root / "good"), *sans], check=True, capture_output=True)
    subprocess.run([script, str(root / "good"), "--name", "intruder"], check=True,
                   capture_output=True)
    subprocess.run([script, str(root / "rogue"), "--name", "master"], check=True,
                   capture_output=True)
    return Certs(root / "good", root / "rogue")
