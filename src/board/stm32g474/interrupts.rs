//! The STM32 board's DMA1 and LPUART1 interrupt bindings: embassy's handlers behind a count of
//! DMA transfer errors ([`DmaFaults`]), the two vectors that are RTIC tasks bound by hand.

use core::sync::atomic::{AtomicU32, Ordering};
use embassy_stm32::interrupt::typelevel::{Binding, Handler};
use embassy_stm32::peripherals::DMA1_CH1;
use embassy_stm32::{bind_interrupts, dma, interrupt, pac, peripherals, usart};

/// DMA1 transfer errors (TEIF) on channels 1–4 since boot ([`super::stream_faults`]).
pub(super) static DMA_TRANSFER_ERRORS: AtomicU32 = AtomicU32::new(0);

bind_interrupts!(pub(super) struct Irqs {
    DMA1_CHANNEL2 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH2>;
    DMA1_CHANNEL3 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH3>;
    DMA1_CHANNEL4 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH4>;
    DMA1_CHANNEL5 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH5>;
    DMA1_CHANNEL6 => dma::InterruptHandler<peripherals::DMA1_CH6>;
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

/// Counts and clears DMA1 transfer errors before embassy's DMA handler sees them.
///
/// Gap: embassy-stm32 0.6's DMA interrupt handler (`dma_bdma.rs`, `on_irq`) panics on TEIF; the
/// stream must count a transfer error and stop instead (the hardware has already disabled the
/// channel: RM0440 12, DMA: "DMA error management").
pub(super) struct DmaFaults;

impl<I: interrupt::typelevel::Interrupt> Handler<I> for DmaFaults {
    unsafe fn on_interrupt() {
        // RAW 1/16: DMA1_ISR TEIF1..4 (RM0440 12, DMA: DMA_ISR).
        let isr = pac::DMA1.isr().read();
        // RAW 2/16: DMA1_IFCR CTEIF1..4, write-one-to-clear (RM0440 12, DMA: DMA_IFCR).
        let n = pac::DMA1.ifcr().write(|w| {
            let mut n = 0;
            for ch in 0..4 {
                if isr.teif(ch) {
                    w.set_teif(ch, true);
                    n += 1;
                }
            }
            n
        });
        if n != 0 {
            DMA_TRANSFER_ERRORS.fetch_add(n, Ordering::Relaxed);
        }
    }
}
