"""tools/flash-firmware: the image checks and the command lines it builds,
on small ELF images made here (no cross toolchain needed)."""
import importlib.machinery
import importlib.util
import pathlib
import struct

import pytest

TOOL = pathlib.Path(__file__).resolve().parents[2] / "tools" / "flash-firmware"
_loader = importlib.machinery.SourceFileLoader("flash_firmware", str(TOOL))
_spec = importlib.util.spec_from_loader("flash_firmware", _loader)
ff = importlib.util.module_from_spec(_spec)
_loader.exec_module(ff)

FLASH, RAM_TOP = 0x08000000, 0x20020000


def elf(segments, entry=None, machine=40):
    """A minimal ELF32 little-endian executable with PT_LOAD segments
    [(paddr, bytes)]; entry defaults to the reset vector of the first."""
    if entry is None:
        entry = struct.unpack_from("<I", segments[0][1], 4)[0]
    phoff, phentsize = 52, 32
    data_off = phoff + phentsize * len(segments)
    header = b"\x7fELF" + bytes([1, 1, 1]) + bytes(9)
    header += struct.pack("<HHIIIIIHHHHHH", 2, machine, 1, entry, phoff, 0, 0x05000400, 52,
                          phentsize, len(segments), 40, 0, 0)
    phdrs, blobs, off = b"", b"", data_off
    for paddr, blob in segments:
        phdrs += struct.pack("<IIIIIIII", 1, off, paddr, paddr, len(blob), len(blob), 5, 4)
        blobs += blob
        off += len(blob)
    return header + phdrs + blobs


def vectors(sp=RAM_TOP, reset=FLASH + 0x101, size=0x200):
    return struct.pack("<II", sp, reset) + bytes(size - 8)


def test_good_image_passes_and_flashes_exactly_its_load_bytes():
    data = (FLASH + 0x200, b"\x01\x02\x03\x04")  # .data's initial values after the code
    image, summary = ff.check_image(elf([(FLASH, vectors()), data]))
    assert len(image) == 0x204
    assert image[:8] == struct.pack("<II", RAM_TOP, FLASH + 0x101)
    assert image[0x200:] == b"\x01\x02\x03\x04"
    assert "0x08000000" in summary and "initial SP 0x20020000" in summary


def test_gaps_between_segments_are_erased_flash():
    image, _ = ff.check_image(elf([(FLASH, vectors(reset=FLASH + 9, size=16)), (FLASH + 32, b"\xaa")]))
    assert image[16:32] == b"\xff" * 16 and image[32] == 0xAA


@pytest.mark.parametrize("segments, message", [
    ([(FLASH + 0x100, vectors())], "not at the flash base"),
    ([(FLASH, vectors(sp=0x10010000))], "initial stack pointer"),
    ([(FLASH, vectors(sp=RAM_TOP + 4))], "initial stack pointer"),
    ([(FLASH, vectors(sp=RAM_TOP - 4))], "8-byte aligned"),
    ([(FLASH, vectors(reset=FLASH + 0x100))], "Thumb bit"),
    ([(FLASH, vectors(reset=FLASH + 0x1001))], "outside the image"),
    ([(FLASH, vectors()), (FLASH + 1024 * 1024 - 2, b"\0\0\0\0")], "does not fit"),
    ([(0x20000000, vectors())], "does not fit"),
])
def test_bad_layouts_are_refused_with_the_reason(segments, message):
    with pytest.raises(ff.ImageError, match=message):
        ff.check_image(elf(segments, entry=FLASH + 0x101))


def test_entry_point_must_be_the_reset_vector():
    with pytest.raises(ff.ImageError, match="ELF entry point"):
        ff.check_image(elf([(FLASH, vectors())], entry=FLASH + 0x181))


def test_not_arm_or_not_elf_is_refused():
    with pytest.raises(ff.ImageError, match="not an ARM image"):
        ff.check_image(elf([(FLASH, vectors())], machine=62))
    with pytest.raises(ff.ImageError, match="not an ELF file"):
        ff.check_image(b"\0" * 100)


def test_dfu_command_writes_the_flash_base_and_leaves_the_bootloader():
    cmd = ff.command("dfu", "fw.bin")
    assert cmd == ["dfu-util", "-a", "0", "-d", "0483:df11", "-s", "0x08000000:leave", "-D", "fw.bin"]
    assert ff.command("dfu", "fw.bin", serial="3574")[1:3] == ["-S", "3574"]


def test_openocd_command_programs_verifies_and_resets():
    cmd = ff.command("openocd", "fw.bin")
    assert cmd[:5] == ["openocd", "-f", "interface/stlink.cfg", "-f", "target/stm32f4x.cfg"]
    assert cmd[-2:] == ["-c", "program fw.bin 0x08000000 verify reset exit"]


def test_dry_run_prints_the_command_and_writes_the_checked_bytes(tmp_path, capsys):
    path = tmp_path / "fw.elf"
    path.write_bytes(elf([(FLASH, vectors())]))
    assert ff.main(["--image", str(path), "--dry-run"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == f"dfu-util -a 0 -d 0483:df11 -s 0x08000000:leave -D {tmp_path / 'fw.bin'}"
    assert (tmp_path / "fw.bin").read_bytes() == vectors()


def test_refused_image_is_not_flashed(tmp_path, capsys):
    path = tmp_path / "fw.elf"
    path.write_bytes(elf([(FLASH, vectors(reset=FLASH + 0x100))], entry=FLASH + 0x100))
    assert ff.main(["--image", str(path), "--dry-run"]) == 1
    assert "Thumb bit" in capsys.readouterr().err
    assert not (tmp_path / "fw.bin").exists()
