#!/usr/bin/env python3
"""Coefficients and table images of the benchmark image (tools/bench-target).

Writes ``bench_tables.h``: the reference configuration's tables, built the way
the host builds them (the golden models quantize, ``piezoctl.tables.build``
makes the sections, ``piezoctl.tables.image`` the image with its CRC), so that
the benchmark commits them through the controller exactly as an upload would:

- ``bench_dcc_img``: kind ``kp_dcc``, the KP plane L = 20 (210 operators,
  the reference law of issue 15), its demo density, g = 1 / sum(w);
- ``bench_eupi_inv_img``: kind ``eupi_inverse``, the EUPI reference model
  (10 CPI, 10 x 3 UPI, u^2..u^4) with k_ex from the small-gain margin 0.2;
- ``bench_eupi_*``: the EUPI reference model itself (forward, no k_ex);
- ``bench_rkp_*``: the RKP reference model (L = 10, 13 Gaussians);
- ``bench_dcc<L>_*``, L = 10, 20, 30: DCC coefficients on the KP plane of
  L intervals (L (L + 1) / 2 operators, demo density), for the kernel alone;
  L = 20 is the image's.

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
from piezoctl.models import kp as fkp
from piezoctl.tables.build import ctl_section, eupi_inverse_sections, kp_dcc_sections
from piezoctl.tables.image import build_image


def main(out: str) -> None:
    h = CHeader("bench")
    h.comment("Benchmark tables (firmware/targets/cortex-m4/bench/gen_bench_tables.py).")

    for L in (10, 20, 30):
        grid = fkp.kp_grid(L)
        d = gdcc.quantize(grid, gkp.demo_density(grid))
        gkp.emit_grid(h, f"bench_dcc{L}", d.grid)
        h.define(f"bench_dcc{L}_G", d.g)
        h.array(f"bench_dcc{L}_c", "int32_t", d.c)
        if L == 20:
            img = build_image("kp_dcc", [ctl_section(1.0)] + kp_dcc_sections(d), table_version=1)
            h.array("bench_dcc_img", "uint8_t", np.frombuffer(img, np.uint8))
            h.define("BENCH_DCC_IMG_LEN", len(img))

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
