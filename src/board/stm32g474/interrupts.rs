//! The STM32 board's DMA1 and LPUART1 interrupt bindings: embassy's handlers behind a count of
//! DMA transfer errors ([`DmaFaults`]), the two vectors that are RTIC tasks bound by hand.

use core::sync::atomic::{AtomicBool, Ordering};
use embassy_stm32::interrupt::typelevel::{Binding, Handler};
use embassy_stm32::peripherals::DMA1_CH1;
use embassy_stm32::{bind_interrupts, dma, interrupt, pac, peripherals, usart};

/// The DMA1 channels the board uses: 1–6 (ADC1, ADC2, DAC1, LPUART1 RX, the DAC driver's
/// unused channel, LPUART1 TX).
const CHANNELS: usize = 6;
/// The DMA1 channel of LPUART1's receive ring.
const LPUART_RX_DMA: usize = 4;

/// A transfer error stopped the receive ring's channel and the ring was not restarted since.
static RX_RING_FAILED: AtomicBool = AtomicBool::new(false);

/// True, once, when a transfer error stopped LPUART1's receive ring since the last call
/// ([`super::Uart::read_byte`] restarts it).
pub(super) fn take_rx_ring_failed() -> bool {
    RX_RING_FAILED.swap(false, Ordering::Relaxed)
}

bind_interrupts!(pub(super) struct Irqs {
    DMA1_CHANNEL2 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH2>;
    DMA1_CHANNEL3 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH3>;
    DMA1_CHANNEL4 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH4>;
    DMA1_CHANNEL5 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH5>;
    DMA1_CHANNEL6 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH6>;
});

// DMA1 CH1's vector (`DMA1_CHANNEL1`) is the RTIC task `sample` (src/bin/probe.rs), which calls
// embassy's handler for the channel itself (after [`DmaFaults`]) in [`Stream::capture`];
// `bind_interrupts!` would define the same vector symbol a second time.
// SAFETY: the handler runs on every DMA1_CH1 interrupt, from `Stream::capture`.
unsafe impl Binding<interrupt::typelevel::DMA1_CHANNEL1, dma::InterruptHandler<DMA1_CH1>> for Irqs {}
// The LPUART1 vector is the RTIC task `uart_rx`, which reads the ring through embassy's
// non-blocking read ([`Uart::read_byte`]); that read clears the idle and error flags the
// interrupt is enabled for, and embassy's handler (which only masks them and wakes an async
// reader) is not needed.
// SAFETY: every `uart_rx` run reads until the ring is empty, clearing the flags.
unsafe impl Binding<interrupt::typelevel::LPUART1, usart::InterruptHandler<peripherals::LPUART1>>
    for Irqs
{
}

/// Counts ([`crate::counters::DMA_ERRORS`]) and clears DMA1 transfer errors on every channel the
/// board uses before embassy's DMA handler sees them, on each of their vectors.
///
/// Gap: embassy-stm32 0.6's DMA interrupt handler (`dma_bdma.rs`, `on_irq`) panics on TEIF; the
/// board must count a transfer error and stop its stream instead (the hardware has already
/// disabled the channel: RM0440 12, DMA: "DMA error management"). embassy's handler wakes a
/// transfer's waiter only on half and full transfer: the link's transmit task polls its
/// transfer (`board::tasks::link_tx`), and LPUART1's receive ring is restarted by its task.
pub(super) struct DmaFaults;

impl<I: interrupt::typelevel::Interrupt> Handler<I> for DmaFaults {
    unsafe fn on_interrupt() {
        // RAW 1/17: DMA1_ISR TEIF1..6 (RM0440 12, DMA: DMA_ISR).
        let isr = pac::DMA1.isr().read();
        // RAW 2/17: DMA1_IFCR CTEIF1..6, write-one-to-clear (RM0440 12, DMA: DMA_IFCR).
        let failed = pac::DMA1.ifcr().write(|w| {
            let mut failed = 0u8;
            for ch in 0..CHANNELS {
                if isr.teif(ch) {
                    w.set_teif(ch, true);
                    failed |= 1 << ch;
                }
            }
            failed
        });
        if failed != 0 {
            crate::counters::DMA_ERRORS.fetch_add(failed.count_ones(), Ordering::Relaxed);
            // The receive ring stopped: its task (the LPUART1 vector) restarts it now rather
            // than at the next byte, which would be lost.
            if failed & 1 << (LPUART_RX_DMA - 1) != 0 {
                RX_RING_FAILED.store(true, Ordering::Relaxed);
                <interrupt::typelevel::LPUART1 as interrupt::typelevel::Interrupt>::pend();
            }
        }
    }
}
