/*
 * pil_stage.c - processor in the loop: the firmware image with the C stage
 * model (firmware/targets/sil/stage, double precision) behind its ADC and DAC
 * seams, for QEMU's netduinoplus2 (docs/target-cortex-m4.md, "PIL").
 *
 * Order per tick, as in the SIL loop (firmware/targets/sil/sil_loop.c): the
 * tick reads the ADC code the stage produced after the previous tick,
 * computes its DAC code, and piezo_dac_write() pends PendSV; PendSV, below
 * the tick and above the UART, advances the stage one sample with that code
 * and leaves the next ADC code. So the controller sees one tick of
 * computational delay, as in SIL, and the tick itself (what the board runs)
 * stays free of floating point: the stage's double arithmetic (software
 * routines on the single-precision FPU) runs in PendSV, which check_image.py
 * does not reach from SysTick_Handler.
 *
 * Configuration: the default stage (stage_params_default()), its converters
 * and ranges through piezo_sil_ctl_config(), as sil-stage sets them, seed 1.
 */
#include <stdint.h>

#include "board.h"
#include "control.h"
#include "converters.h"
#include "flash_f4.h"
#include "sil_loop.h"
#include "stage_model.h"

#define SCB_ICSR PIEZO_REG(0xE000ED04u)
#define ICSR_PENDSVSET (1u << 28)
#define PIEZO_PRIO_STAGE 0x20u /* below the tick (0x00), above the UART (0x40) */

#ifndef PIEZO_PIL_SEED
#define PIEZO_PIL_SEED 1u
#endif

static stage_t stage;
static volatile int32_t stage_dac[STAGE_MAX_AXES];
static volatile int32_t stage_adc[STAGE_MAX_AXES];
static volatile uint32_t stage_steps;

void piezo_control_board(piezo_ctl_cfg_t *cfg, piezo_control_range_t *range)
{
    stage_params p = stage_params_default();
    piezo_scale_t sc;
    int32_t dac[STAGE_MAX_AXES] = {0}, adc[STAGE_MAX_AXES] = {0};
    if (stage_init(&stage, &p, PIEZO_PIL_SEED) != STAGE_OK || piezo_sil_ctl_config(&p, 0, cfg, &sc) != 0) {
        piezo_board_fault("pil stage", 0);
    }
    range->drive_min_mv = (int32_t)(sc.drive_min_v * 1000.0);
    range->drive_max_mv = (int32_t)(sc.drive_max_v * 1000.0);
    range->position_min_nm = (int32_t)(sc.position_min_um * 1000.0);
    range->position_max_nm = (int32_t)(sc.position_max_um * 1000.0);
    /* the sensor's first reading: the stage at rest under the safe drive */
    dac[0] = cfg->dac_zero + (int32_t)(((int64_t)cfg->u_safe_q15 * cfg->dac_gain_q16) >> 16);
    dac[1] = dac[0];
    stage_step(&stage, dac, adc);
    stage_dac[0] = dac[0];
    stage_dac[1] = dac[1];
    stage_adc[0] = adc[0];
    stage_adc[1] = adc[1];
    SCB_SHPR3 = (SCB_SHPR3 & 0xFF00FFFFu) | ((uint32_t)PIEZO_PRIO_STAGE << 16);
}

void piezo_adc_read(int32_t adc[2])
{
    adc[0] = stage_adc[0];
    adc[1] = 0;
}

void piezo_dac_write(int32_t code)
{
    stage_dac[0] = code;
    SCB_ICSR = ICSR_PENDSVSET;
}

void PendSV_Handler(void);
void PendSV_Handler(void)
{
    int32_t dac[STAGE_MAX_AXES] = {stage_dac[0], stage_dac[1]};
    int32_t adc[STAGE_MAX_AXES] = {0};
    stage_step(&stage, dac, adc);
    stage_adc[0] = adc[0];
    stage_adc[1] = adc[1];
    stage_steps = stage_steps + 1u;
}

/* Tables in RAM behind the flash driver's storage interface (QEMU 7.2 models
 * no flash interface, and its flash is ROM): the same A/B store, lost when
 * QEMU exits. */
#define PIL_SLOT_BYTES (PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES)
static uint8_t pil_flash[2u * PIL_SLOT_BYTES];

const piezo_storage_t *piezo_control_storage(void)
{
    static piezo_storage_t io;
    io = piezo_ram_storage(pil_flash, PIL_SLOT_BYTES);
    return &io;
}

/* The controller parameters likewise: two RAM slots, lost when QEMU exits. */
static uint8_t pil_params[2u * PIEZO_PARAMS_MIN_SLOT_BYTES]; /* no room for the wave: params_wave left_out */
static piezo_ram_store_t pil_params_store;

const piezo_storage_t *piezo_control_params_storage(void)
{
    static piezo_storage_t io;
    io = piezo_ram_storage_in(&pil_params_store, pil_params, PIEZO_PARAMS_MIN_SLOT_BYTES);
    return &io;
}
