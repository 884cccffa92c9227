/* usb_board.c - the OTG FS device in the firmware image (see usb_board.h). */
#include "usb_board.h"

#include "usb_otgfs.h"

piezo_usbd_t piezo_usb_dev;
static volatile uint32_t usb_pending;
static uint32_t usb_state;

#define IRQ_WORD (PIEZO_IRQ_OTG_FS / 32u)
#define IRQ_BIT (1u << (PIEZO_IRQ_OTG_FS % 32u))

static void set_bits(uint32_t addr, uint32_t clear, uint32_t set)
{
    piezo_usb_board_wr(addr, (piezo_usb_board_rd(addr) & ~clear) | set);
}

int piezo_usb_init(const piezo_mb_regs_t *regs)
{
    usb_state = PIEZO_USB_ABSENT;
    usb_pending = 0u;
    piezo_usbd_init(&piezo_usb_dev, regs);
    /* the line stays masked until the core is up */
    piezo_usb_board_wr(PIEZO_NVIC_ICER(IRQ_WORD), IRQ_BIT);
    /* PA11, PA12: AF10, high speed (MODER 10b, OSPEEDR 11b, AFRH nibbles 3 and 4) */
    set_bits(PIEZO_RCC_AHB1ENR, 0u, PIEZO_RCC_AHB1ENR_GPIOAEN);
    (void)piezo_usb_board_rd(PIEZO_RCC_AHB1ENR); /* two cycles before the port is used (errata 2.1.11) */
    set_bits(PIEZO_GPIOA_AFRH, (0xFu << 12) | (0xFu << 16), (PIEZO_USB_AF << 12) | (PIEZO_USB_AF << 16));
    set_bits(PIEZO_GPIOA_OSPEEDR, (3u << 22) | (3u << 24), (3u << 22) | (3u << 24));
    set_bits(PIEZO_GPIOA_MODER, (3u << 22) | (3u << 24), (2u << 22) | (2u << 24));
    /* the core's clock (48 MHz from PLLQ), then the core */
    set_bits(PIEZO_RCC_AHB2ENR, 0u, PIEZO_RCC_AHB2ENR_OTGFSEN);
    (void)piezo_usb_board_rd(PIEZO_RCC_AHB2ENR);
    if (piezo_otgfs_init(&piezo_usb_dev) != 0) {
        return -1; /* no core (QEMU) or it did not reset: no USB, the rest runs */
    }
    piezo_usb_board_wr8(PIEZO_NVIC_IPR8(PIEZO_IRQ_OTG_FS), (uint8_t)PIEZO_PRIO_USB);
    usb_state = PIEZO_USB_RUNNING;
    piezo_usb_board_wr(PIEZO_NVIC_ISER(IRQ_WORD), IRQ_BIT);
    return 0;
}

/* Mask the line and leave the work to the background loop. */
void OTG_FS_IRQHandler(void)
{
    piezo_usb_board_wr(PIEZO_NVIC_ICER(IRQ_WORD), IRQ_BIT);
    usb_pending = 1u;
}

int piezo_usb_poll(void)
{
    if (usb_pending == 0u || usb_state != PIEZO_USB_RUNNING) {
        return 0;
    }
    usb_pending = 0u;
    piezo_otgfs_irq(&piezo_usb_dev);
    /* a source still set raises the line again at once */
    piezo_usb_board_wr(PIEZO_NVIC_ISER(IRQ_WORD), IRQ_BIT);
    return 1;
}

uint32_t piezo_usb_state(void)
{
    return usb_state;
}
