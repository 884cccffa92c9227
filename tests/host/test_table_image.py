"""Host table images: build/parse round trip, and the same refusals as the firmware."""

import numpy as np
import pytest

from piezoctl import interface
from piezoctl.fixtures.tables import bad_images, valid_image
from piezoctl.tables.image import Section, TableImageError, build_image, parse_image


def test_round_trip_keeps_header_and_sections():
    img = valid_image()
    t = parse_image(img)
    assert t.header["kind"] == interface.TABLE_KINDS["kp_dcc"]
    assert t.header["table_version"] == 7
    assert t.header["fit_nrmse_ppm"] == 12300
    assert t.header["data_sha256"] == bytes(range(16))
    assert t.sections[3].tolist() == [123456]
    assert len(t.sections[1]) == 11


@pytest.mark.parametrize("name", sorted(bad_images()))
def test_host_parser_names_the_same_reason_as_the_firmware_test(name):
    img, reason = bad_images()[name]
    with pytest.raises(TableImageError) as exc:
        parse_image(img)
    assert exc.value.reason == reason


def test_every_bit_flip_is_refused():
    img = bytearray(valid_image())
    for bit in range(0, 8 * len(img), 7):
        flipped = bytearray(img)
        flipped[bit >> 3] ^= 1 << (bit & 7)
        with pytest.raises(TableImageError):
            parse_image(bytes(flipped))


def test_out_of_range_values_are_refused_when_building():
    with pytest.raises(TableImageError, match="out_of_range"):
        build_image("kp_dcc", [Section(1, np.array([40000]), interface.SECTION_TYPES["int16"])])
    with pytest.raises(TableImageError, match="bad_section"):
        build_image("kp_dcc", [Section(1, np.arange(2)), Section(1, np.arange(2))])
    with pytest.raises(TableImageError, match="bad_kind"):
        build_image("nonsense", [])
