"""Table images and expected drives for the controller's tests.

The controller runs the kernels of a committed table; with no feedback and
no clamping its feedforward drive must equal the kernel golden models bit for
bit. Also images that the controller must refuse at commit, each with the
reason it must give.
"""

from __future__ import annotations

import functools

import numpy as np

from .. import interface
from ..tables.build import ctl_section, eupi_inverse_sections, kp_dcc_sections
from ..tables.image import Section, build_image
from ..tables.image import build_image as _build_image
from . import dcc as gdcc
from . import eupi_inv as ginv
from . import kp as gkp
from .export import CHeader


# The straight lines of the test tables: the uncompensated drive of each
# reference model (fitted to its branches), so that the commit's sweep
# compares the compensator with a consistent line (coefset.h).
DCC_LINE = (1.9, -0.85)
EUPI_LINE = (1.35, -0.015)


def _sil_stage() -> dict:
    """The stage the test images are built for: axis 0 of the default SIL
    stage, the virtual controller the host tests flash them to (the C tests
    load them into controllers that do not compare stages)."""
    from .sil_tables import stage_scale
    sc = stage_scale()
    return dict(axis=0, drive_range_v=(sc.drive_min_v, sc.drive_max_v),
                position_range_um=(sc.position_min_um, sc.position_max_um))


def dcc_image(version: int = 1):
    grid, w = gdcc.std_model()
    d = gdcc.quantize(grid, w)
    img = build_image("kp_dcc", [ctl_section(*DCC_LINE)] + kp_dcc_sections(d), table_version=version,
                      **_sil_stage())
    return img, d


def eupi_image(version: int = 2):
    params = ginv.reference_inverse_params()
    q = ginv.quantize_eupi_inv(params)
    img = build_image("eupi_inverse", [ctl_section(*EUPI_LINE)] + eupi_inverse_sections(q, params.a0),
                      table_version=version, **_sil_stage())
    return img, q


def _replace(sections: list[Section], name: str, values) -> list[Section]:
    sid = interface.TABLE_SECTIONS[name][0]
    return [Section(s.id, np.asarray(values), s.type) if s.id == sid else s for s in sections]


def refused_images() -> list[tuple[str, bytes, str]]:
    """(name, image, reason) of images that pass the CRC but not the commit
    (built for the SIL stage, so that nothing but the named fault differs)."""
    st = _sil_stage()
    build_image = functools.partial(_build_image, **st)
    grid, w = gdcc.std_model()
    d = gdcc.quantize(grid, w)
    base = [ctl_section(*DCC_LINE)] + kp_dcc_sections(d)
    out = []
    n1, n2 = d.grid.n1.copy(), d.grid.n2.copy()
    n1[3], n2[3] = n2[3] + 100, n1[3]  # one cell with n1 > n2
    out.append(("thresholds_out_of_order",
                build_image("kp_dcc", _replace(_replace(base, "kp_n1_q15", n1), "kp_n2_q15", n2)),
                "not_monotonic"))
    out.append(("missing_section", build_image("kp_dcc", base[:-1]), "missing_section"))
    out.append(("unknown_section", build_image("kp_dcc", base + [Section(999, np.array([0]))]), "unknown_section"))
    out.append(("foreign_section", build_image("kp_dcc", base + [Section(interface.TABLE_SECTIONS["rkp_alpha_q16"][0],
                                                                          np.array([0]))]), "unknown_section"))
    out.append(("negative_gain", build_image("kp_dcc", _replace(base, "ctl_scalars", [-(1 << 24), 0, 1 << 24, 0])),
                "out_of_range"))
    out.append(("offset_too_large", build_image("kp_dcc", _replace(base, "ctl_scalars", [1 << 24, 70000, 1 << 24, 0])),
                "out_of_range"))
    out.append(("weights_count", build_image("kp_dcc", _replace(base, "dcc_c_q24", d.c[:-1])), "bad_length"))
    out.append(("unknown_kind", build_image("cascade", base), "bad_kind"))
    # an EUPI inverse whose UPI part is too strong for the small-gain bound
    params = ginv.reference_inverse_params()
    q = ginv.quantize_eupi_inv(params)
    secs = [ctl_section(*EUPI_LINE)] + eupi_inverse_sections(q, params.a0)
    strong = _replace(secs, "eupi_upi_w_q24", q.upi.w_q24 * 6)
    out.append(("unstable_inverse", build_image("eupi_inverse", strong), "unstable_inverse"))
    # a0_inv that is not 1 / (a0 + k_ex)
    sc = [q.a0_inv_q24 // 2, q.kex_q24, q.p0_q24, int(np.floor(params.a0 * (1 << 24) + 0.5))]
    out.append(("inconsistent_a0_inv", build_image("eupi_inverse", _replace(secs, "eupi_inv_scalars", sc)),
                "out_of_range"))
    return out


def reference_signal(n: int = 3000) -> np.ndarray:
    return gkp.realistic_signal(n, seed=21)


def c_header() -> str:
    h = CHeader("ctl")
    r = reference_signal()
    h.define("CTL_N", r.size)
    h.array("ctl_ref_q15", "int16_t", r)
    img, d = dcc_image()
    h.array("ctl_dcc_img", "uint8_t", np.frombuffer(img, np.uint8))
    h.define("CTL_DCC_IMG_LEN", len(img))
    h.array("ctl_dcc_u_q15", "int16_t", gdcc.dcc_process_q(r, d))
    img, q = eupi_image()
    h.array("ctl_eupi_img", "uint8_t", np.frombuffer(img, np.uint8))
    h.define("CTL_EUPI_IMG_LEN", len(img))
    h.array("ctl_eupi_u_q15", "int16_t", ginv.eupi_inv_run(q, r))
    bad = refused_images()
    for i, (name, b, _) in enumerate(bad):
        h.array(f"ctl_bad_{i}", "uint8_t", np.frombuffer(b, np.uint8))
    h.parts.append("static const struct { const char *name; const uint8_t *img; uint32_t len; uint16_t reason; }"
                   " ctl_bad[] = {\n" + "\n".join(
                       f'    {{"{n}", ctl_bad_{i}, {len(b)}u, {interface.TABLE_REASONS[reason]}u}},'
                       for i, (n, b, reason) in enumerate(bad)) + "\n};")
    h.define("CTL_BAD_N", len(bad))
    return str(h)
