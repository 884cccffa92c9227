"""Sessions against the virtual controller (issue 13, docs/protocol.md): the
unlock belongs to a connection, a wrong key is a Modbus exception, the staged
image belongs to the connection that staged it, an image built for another
stage is refused, and the client's key comes from ``--unlock-key`` /
``$PIEZOCTL_UNLOCK_KEY``."""

from __future__ import annotations

import pytest

from piezoctl import interface
from piezoctl.device import DeviceError, connect, unlock_key
from piezoctl.errors import CliError
from piezoctl.transport.errors import ModbusExceptionError
from piezoctl.fixtures.ctl import dcc_image, eupi_image
from piezoctl.tables.image import build_image, check_image
from piezoctl.tables.build import ctl_section
from sil_fixture import SilStage, sil  # noqa: F401  (fixture)


def test_unlock_key_sources(monkeypatch):
    monkeypatch.delenv("PIEZOCTL_UNLOCK_KEY", raising=False)
    assert unlock_key() == interface.MODBUS_UNLOCK["default_sil_key"]
    monkeypatch.setenv("PIEZOCTL_UNLOCK_KEY", "0x1234ABCD")
    assert unlock_key() == 0x1234ABCD
    assert unlock_key("deadBEEF") == 0xDEADBEEF
    for bad in ("50A5", "0x00000000", "123456789", "xyz12345"):
        with pytest.raises(CliError):
            unlock_key(bad)


def test_wrong_key_is_an_exception_and_counted(sil):
    ctl = connect(sil.spec, key=0x11111111)
    with pytest.raises(DeviceError, match="refused the unlock key"):
        ctl.unlock()
    assert ctl.status()["bad_unlocks"] == 1
    good = connect(sil.spec)
    good.unlock()
    unlock_reg = interface.HOLDING_REGISTERS["unlock"][0]
    assert good.client.read_holding(unlock_reg, 1) == [1]   # this connection
    assert ctl.client.read_holding(unlock_reg, 1) == [0]    # not that one


def test_staged_image_belongs_to_its_connection(sil):
    a, b = connect(sil.spec), connect(sil.spec)
    img, _ = dcc_image()
    a.upload_table(img)
    # b never unlocked: its commit is refused, a's upload stays
    with pytest.raises(ModbusExceptionError):
        b.write("table_command", 1)
    b.unlock()
    assert b.commit_table() == "not_owner"
    assert a.status()["staged_bytes"] == len(img)
    assert a.status()["active_table_crc"] == 0
    assert a.commit_table() == "ok"


def test_upload_dies_with_its_connection(sil):
    a = connect(sil.spec)
    img, _ = eupi_image()
    a.upload_table(img)
    a.client.close()
    b = connect(sil.spec)
    for _ in range(50):
        if b.status()["staged_bytes"] == 0:
            break
    assert b.status()["staged_bytes"] == 0
    b.unlock()
    assert b.commit_table() == "nothing_staged"


def test_image_for_another_stage_is_refused(sil):
    ctl = connect(sil.spec)
    img, d = dcc_image()
    t = check_image(img)
    assert (t.header["drive_min_mv"], t.header["drive_max_mv"]) == (0, 150000)
    from piezoctl.tables.build import kp_dcc_sections
    from piezoctl.fixtures.ctl import DCC_LINE
    valve = build_image("kp_dcc", [ctl_section(*DCC_LINE)] + kp_dcc_sections(d),
                        drive_range_v=(-90.0, 90.0), position_range_um=(-6.0, 4.0))
    ctl.upload_table(valve)
    assert ctl.commit_table() == "wrong_stage"
    other_axis = build_image("kp_dcc", [ctl_section(*DCC_LINE)] + kp_dcc_sections(d), axis=1,
                             drive_range_v=(0.0, 150.0), position_range_um=(-2.0, 22.0))
    ctl.upload_table(other_axis)
    assert ctl.commit_table() == "wrong_axis"
    assert ctl.status()["active_table_crc"] == 0


def test_provisioned_key(tmp_path):
    s = SilStage(tmp_path, "--unlock-key", "0C0FFEE5")
    try:
        with pytest.raises(DeviceError):
            connect(s.spec, key=interface.MODBUS_UNLOCK["default_sil_key"]).unlock()
        connect(s.spec, key="0C0FFEE5").unlock()
    finally:
        s.stop()


def test_idle_and_half_sent_connections_do_not_lock_clients_out(sil):
    """Four connections that never send, then three half-sent requests: a new
    client is served once they have idled evict_min_idle_ms, and a half-sent
    request is closed after partial_timeout_ms (docs/protocol.md)."""
    import socket
    import time

    slots = interface.MODBUS_TCP["slots"]
    idle = [socket.create_connection(("127.0.0.1", sil.port)) for _ in range(slots)]
    time.sleep(interface.MODBUS_TCP["evict_min_idle_ms"] / 1000.0 + 0.2)
    ctl = connect(sil.spec)
    assert ctl.status()["tick_count"] > 0
    half = socket.create_connection(("127.0.0.1", sil.port))
    half.sendall(bytes([0, 1, 0, 0, 0, 6, 1, 4]))  # 8 of 12 bytes
    half.settimeout(5.0)
    t0 = time.monotonic()
    assert half.recv(10) == b""
    dt = time.monotonic() - t0
    assert interface.MODBUS_TCP["partial_timeout_ms"] / 1000.0 - 0.1 <= dt < 3.0
    assert ctl.status()["tick_count"] > 0  # the polling client kept its slot
    for s in idle + [half]:
        s.close()
