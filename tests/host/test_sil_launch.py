"""The one launcher of the virtual controller (piezoctl.sil.launch)."""

from __future__ import annotations

import pytest

from piezoctl.device import connect
from piezoctl.sil.launch import SilLaunchError, VirtualController

from sil_fixture import sil_binary


def test_start_connect_stop(tmp_path):
    flash = tmp_path / "f.flash"
    with VirtualController(exe=sil_binary(), flash=flash, seed=3) as vc:
        assert vc.port == f"tcp:127.0.0.1:{vc.tcp_port}" and vc.running()
        ctl = connect(vc.port)
        assert ctl.identity.tick_hz == 10000
        ctl.client.close()
    assert not vc.running()
    assert vc.stats.startswith("sil-stage: stats ticks=")
    assert flash.exists()                 # a flash file given is kept


def test_default_flash_is_temporary():
    vc = VirtualController(exe=sil_binary()).start()
    flash = vc.flash
    rc, _ = vc.stop()
    assert rc == 0
    assert not __import__("os").path.exists(flash)
    assert vc.stop()[0] == 0              # twice is harmless


def test_refused_start_names_the_reason(tmp_path):
    with pytest.raises(SilLaunchError, match="sil-stage: .*no-such-stage.json"):
        VirtualController(exe=sil_binary(), stage=tmp_path / "no-such-stage.json").start()
