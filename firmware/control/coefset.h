/*
 * coefset.h - a coefficient set: the kernels' coefficient structs and the
 * arrays behind them, filled from a validated table image.
 *
 * The controller owns two sets: the active one (read by the tick) and a spare
 * that a commit fills and validates; a valid spare becomes active at the next
 * tick boundary. Loading never touches the active set, so a refused image
 * leaves the running table as it was.
 *
 * Validation on load (reason codes from common/interface.toml):
 *   - the image itself: piezo_table_check() (CRC, versions, lengths, sections,
 *     every element in its documented range), done once by the caller;
 *   - every section the kind needs, with the right type and count;
 *   - ranges and order: each kernel's own init check (thresholds monotonic,
 *     weights and gains in range) on a scratch instance;
 *   - EUPI inverse: the small-gain condition in integers,
 *       a0 + k_ex > max(S + Pb - k_ex, k_ex + Pb),
 *       S = sum_ij d_ij max(1, a_j),  Pb = sum_m (m + 2) |p_m|,
 *     a bound on |d(G_UPI + P - k_ex u)/du| for |u| <= 1 (normalized drive),
 *     and a0_inv * (a0 + k_ex) = 1 within the rounding of a0_inv. The host
 *     runs the same integer check before it builds a table
 *     (piezoctl.tables.build.firmware_small_gain);
 *   - at commit (the controller's, after the load): the sweep
 *     (piezo_coefset_sweep): the set's own kernel, in its own
 *     integer arithmetic, over the whole q15 reference range, both directions
 *     and minor loops nested inside each half (PIEZO_CS_SWEEP_STEP_Q15 per
 *     sample, about 5600 samples), the drive fed back as the tick does.
 *     Refused: a drive that falls while the reference rises (or the reverse)
 *     by more than PIEZO_CS_SWEEP_TOL_Q15 (not_monotonic); a reference whose
 *     drive sits on the same q15 rail on the rising and on the falling major
 *     branch (64-LSB bins) although the table's own straight line (the
 *     stage's uncompensated drive, ctl_scalars) reaches it with a drive
 *     within +-PIEZO_CS_SWEEP_LINE_Q15, and a line on a rail at the middle
 *     of the position range (output_range). It runs at commit, in the main
 *     context: never in the tick.
 */
#ifndef PIEZO_COEFSET_H
#define PIEZO_COEFSET_H

#include <stdint.h>

#include "dcc.h"
#include "table_image.h"
#include "eupi_inv.h"
#include "kp.h"
#include "rkp.h"
#include "xcouple.h"

/* Compile-time capacity of one set (a table beyond it is refused: bad_length).
 * A target may override them (-D) to fit its RAM. */
#ifndef PIEZO_CS_MAX_KP_OPS
#define PIEZO_CS_MAX_KP_OPS 465u   /* L = 30 */
#endif
#ifndef PIEZO_CS_MAX_RKP_OPS
#define PIEZO_CS_MAX_RKP_OPS 120u  /* L = 15 */
#endif
#ifndef PIEZO_CS_MAX_RBF
#define PIEZO_CS_MAX_RBF 16u
#endif
#define PIEZO_CS_MAX_CPI 32u
#define PIEZO_CS_MAX_UPI_R 16u
#define PIEZO_CS_MAX_UPI_A 8u
#define PIEZO_CS_MAX_POLY PIEZO_EUPI_MAX_POLY

typedef struct {
    uint16_t kind;                 /* PIEZO_TABLE_KIND_*, 0 = empty */
    uint32_t crc;
    uint32_t version;
    /* Straight-line maps of the reference r (q15 position):
     *   uncompensated drive  u  = sat_q15(rshift_rnd(r g_ol + o_ol 2^24, 24))
     *   DCC law input        yd = sat_q15(rshift_rnd(r g_y + o_y 2^24, 24)) */
    int32_t open_loop_gain_q24;
    int32_t open_loop_offset_q15;
    int32_t y_to_u_gain_q24;
    int32_t y_offset_q15;

    /* KP operators: DCC (kp_dcc) and rate-dependent DCC (rkp). For rkp the
     * DCC weights are the RKP density of the tick (g folded into Theta), so
     * dcc.c_q24 is bound to the state's w_q24 by piezo_ff_bind(). */
    struct piezo_dcc_coeffs dcc;
    struct piezo_rkp_coeffs rkp;
    int16_t n1_q15[PIEZO_CS_MAX_KP_OPS];
    int16_t n2_q15[PIEZO_CS_MAX_KP_OPS];
    int32_t c_q24[PIEZO_CS_MAX_KP_OPS];
    union {
        int32_t theta_q24[PIEZO_CS_MAX_RKP_OPS * PIEZO_CS_MAX_RBF]; /* rkp */
        int32_t dcc_csum_q24[2u * (PIEZO_CS_MAX_KP_OPS + 1u)];     /* kp_dcc: c's prefix sums (dcc.h) */
    } by_kind; /* one set holds one kind */
    int32_t center_q24[PIEZO_CS_MAX_RBF];
    int32_t inv_width_q16[PIEZO_CS_MAX_RBF];

    /* EUPI inverse */
    struct piezo_eupi_inv_coef inv;
    int32_t a0_q24;
    int32_t cpi_r_q15[PIEZO_CS_MAX_CPI];
    int32_t cpi_w_q24[PIEZO_CS_MAX_CPI];
    int32_t upi_r_q15[PIEZO_CS_MAX_UPI_R];
    int32_t upi_a_q24[PIEZO_CS_MAX_UPI_A];
    int32_t upi_w_q24[PIEZO_CS_MAX_UPI_R * PIEZO_CS_MAX_UPI_A];
    int32_t poly_q24[PIEZO_CS_MAX_POLY];
} piezo_coefset_t;

/* Kernel state for running one set. */
typedef struct {
    struct piezo_dcc dcc;
    struct piezo_dcc_coeffs dcc_rate;  /* rkp: the DCC weights are w_q24 below */
    struct piezo_rkp rkp;
    struct piezo_eupi_inv inv;
    int32_t cpsi_q15[PIEZO_CS_MAX_KP_OPS];
    int32_t zo_q15[PIEZO_CS_MAX_KP_OPS];
    int16_t psi_q15[PIEZO_CS_MAX_RKP_OPS];
    int32_t w_q24[PIEZO_CS_MAX_RKP_OPS];
    int32_t inv_state_q15[PIEZO_CS_MAX_CPI + PIEZO_CS_MAX_UPI_R * PIEZO_CS_MAX_UPI_A];
    int64_t inv_work_q39[PIEZO_EUPI_INV_WORK_LEN(PIEZO_CS_MAX_UPI_R, PIEZO_CS_MAX_UPI_A)];
} piezo_ff_state_t;

/* The commit sweep (see above). */
#define PIEZO_CS_SWEEP_STEP_Q15 64u      /* reference step per sample */
#define PIEZO_CS_SWEEP_TOL_Q15 64u       /* drive may move against the reference by this much */
#define PIEZO_CS_SWEEP_LINE_Q15 28672u  /* no rail where the line's drive is within 7/8 FS */

typedef struct {
    uint32_t samples;        /* kernel calls */
    int32_t worst_step_q15;  /* most negative drive step along the reference's direction */
} piezo_sweep_stats_t;

/**
 * Fill cs from an image (len bytes) and validate it; ff is scratch state for
 * the kernel checks. Returns PIEZO_TABLE_REASON_OK or the reason; on failure
 * cs->kind is 0 and cs must not be used. piezo_coefset_load_info() takes an
 * image already checked by piezo_table_check() (the controller's commit).
 * Neither runs the sweep: the controller's commit and boot do, after the load
 * (a benchmark may load a table whose straight line is only a placeholder).
 */
uint16_t piezo_coefset_load(piezo_coefset_t *cs, piezo_ff_state_t *ff, const uint8_t *img, uint32_t len);
uint16_t piezo_coefset_load_info(piezo_coefset_t *cs, piezo_ff_state_t *ff, const piezo_table_info_t *info);

/** Run the sweep on a loaded set (ff is bound and left bound and reset). */
uint16_t piezo_coefset_sweep(piezo_coefset_t *cs, piezo_ff_state_t *ff, piezo_sweep_stats_t *stats);

/** Bind the feedforward state to a loaded set and reset it. Returns a piezo_err code. */
int piezo_ff_bind(piezo_ff_state_t *ff, const piezo_coefset_t *cs);

/**
 * One tick of the feedforward: the drive (q15) for reference r (q15,
 * displacement). u_applied is the drive the stage received last tick (after
 * feedback, clamp and slew limit): the DCC operators follow it.
 */
int16_t piezo_ff_process(piezo_ff_state_t *ff, const piezo_coefset_t *cs, int16_t r_q15, int16_t u_applied_q15);

/** r g + o with one rounding, saturated: the straight-line maps above. */
int16_t piezo_line_q15(int16_t r_q15, int32_t gain_q24, int32_t offset_q15);

/*
 * Cross-coupling table (kind cross_coupling): the coefficients of the
 * xcouple kernel (xcouple.h) and where its position input comes from. A
 * controller holds it in slots of its own beside the feedforward set, so a
 * stage can run a hysteresis table and a coupling table at once. Validation
 * on load: the image check, every xc_* section with the counts the sizes in
 * xc_scalars imply, x_source 0 or 1, and the kernel's init (its bounds).
 */
typedef struct {
    uint16_t kind;                 /* PIEZO_TABLE_KIND_CROSS_COUPLING, 0 = empty */
    uint32_t crc;
    uint32_t version;
    uint8_t x_source;              /* 0: this axis' position y, 1: the other axis' y2 */
    struct piezo_xc_coef xc;       /* points into the arrays below */
    int32_t a_q24[PIEZO_XC_MAX_M * PIEZO_XC_MAX_M];
    int32_t b_q24[PIEZO_XC_MAX_M];
    int32_t e_q24[PIEZO_XC_MAX_M];
    int32_t eta_q24[PIEZO_XC_MAX_CH * PIEZO_XC_MAX_POW * PIEZO_XC_MAX_DEG];
    int32_t xi_q24[PIEZO_XC_MAX_CH * PIEZO_XC_MAX_M * PIEZO_XC_MAX_DEG];
} piezo_xcset_t;

/**
 * Fill xs from a cross_coupling image and validate it; st is the kernel
 * instance, initialized on success. Returns PIEZO_TABLE_REASON_OK or the
 * reason; on failure xs->kind is 0.
 */
uint16_t piezo_xcset_load(piezo_xcset_t *xs, struct piezo_xc *st, const uint8_t *img, uint32_t len);
uint16_t piezo_xcset_load_info(piezo_xcset_t *xs, struct piezo_xc *st, const piezo_table_info_t *info);

#endif /* PIEZO_COEFSET_H */
