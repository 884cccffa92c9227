#!/usr/bin/env python3
"""Coefficients and table images of the benchmark image (tools/bench-target).

Writes ``bench_tables.h``: the reference configuration's tables, built the way
the host builds them (the golden models quantize, ``piezoctl.tables.build``
makes the sections, ``piezoctl.tables.image`` the image with its CRC), so that
the benchmark commits them through the controller exactly as an upload would:

- ``bench_dcc_img``: kind ``kp_dcc``, the KP reference plane L = 10
  (55 operators), its demo density, g = 1 / sum(w);
- ``bench_eupi_inv_img``: kind ``eupi_inverse``, the EUPI reference model
  (10 CPI, 10 x 3 UPI, u^2..u^4) with k_ex from the small-gain margin 0.2;
- ``bench_eupi_*``: the EUPI reference model itself (forward, no k_ex);
- ``bench_rkp_*``: the RKP reference model (L = 10, 13 Gaussians);
- ``bench_dcc_*``: the DCC coefficients of the image, for the kernel alone.

Usage: gen_bench_tables.py OUT.h (run with the project's venv Python).
"""
import sys

import numpy as np

from piezoctl.golden import dcc as gdcc
from piezoctl.golden import eupi as geupi
from piezoctl.golden import eupi_inv as ginv
from piezoctl.golden import kp as gkp
from piezoctl.golden import rkp as grkp
from piezoctl.golden.export import CHeader
from piezoctl.tables.build import ctl_section, eupi_inverse_sections, kp_dcc_sections
from piezoctl.tables.image import build_image


def main(out: str) -> None:
    h = CHeader("bench")
    h.comment("Benchmark tables (firmware/targets/cortex-m4/bench/gen_bench_tables.py).")

    grid, w = gdcc.std_model()
    d = gdcc.quantize(grid, w)
    img = build_image("kp_dcc", [ctl_section(1.0)] + kp_dcc_sections(d), table_version=1)
    h.array("bench_dcc_img", "uint8_t", np.frombuffer(img, np.uint8))
    h.define("BENCH_DCC_IMG_LEN", len(img))
    gkp.emit_grid(h, "bench_dcc", d.grid)
    h.define("bench_dcc_G", d.g)
    h.array("bench_dcc_c", "int32_t", d.c)

    params = ginv.reference_inverse_params()
    q = ginv.quantize_eupi_inv(params)
    img = build_image("eupi_inverse", [ctl_section(1.0)] + eupi_inverse_sections(q, params.a0),
                      table_version=2)
    h.array("bench_eupi_inv_img", "uint8_t", np.frombuffer(img, np.uint8))
    h.define("BENCH_EUPI_INV_IMG_LEN", len(img))

    geupi.header_coef(h, "bench_eupi", geupi.quantize_eupi(geupi.reference_params()))

    rgrid, theta, centers, widths, filt = grkp.std_model()
    r = grkp.quantize(rgrid, theta, grkp.DT, centers, widths, filt)
    gkp.emit_grid(h, "bench_rkp", r.grid)
    h.define("bench_rkp_NRBF", r.M)
    h.define("bench_rkp_ALPHA", r.alpha)
    h.array("bench_rkp_theta", "int32_t", r.theta.ravel())
    h.array("bench_rkp_center", "int32_t", r.center)
    h.array("bench_rkp_inv_width", "int32_t", r.inv_width)

    with open(out, "w") as f:
        f.write(str(h))


if __name__ == "__main__":
    main(sys.argv[1])
