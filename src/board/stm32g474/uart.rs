//! The STM32 board's host link on the ST-LINK virtual COM port: LPUART1 receive (PA3, a DMA
//! ring) and transmit (PA2, by DMA from the link's transmit queue; `docs/protocol.md`).

use core::ptr::addr_of_mut;
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{RingBufferedUartRx, Uart as Lpuart, UartTx};
use embassy_stm32::{peripherals, Peri};

use super::interrupts::{take_rx_ring_failed, Irqs};
use super::reset::record;
use super::BootError;
use crate::board::tx_queue;

/// LPUART1 baud rate (ST-LINK virtual COM port).
const LPUART_BAUD: u32 = 115_200;
/// Received bytes buffered by LPUART1's DMA ring.
const UART_RING: usize = 64;

/// LPUART1 receiver (115 200 Bd, 8N1) on the ST-LINK virtual COM port: embassy's DMA ring
/// (DMA1 CH4, [`UART_RING`] bytes), drained by the RTIC task `uart_rx` on the LPUART1 vector.
///
/// embassy enables LPUART1's idle-line and error interrupts for its ring; the vector is RTIC's,
/// and [`Uart::read_byte`] reads through embassy's non-blocking `embedded_hal_nb` read, which
/// clears those flags (`check_idle_and_errors`) and restarts the ring after an error. Bytes that
/// arrive without a pause wait in the ring until the idle line.
pub struct Uart(Option<RingBufferedUartRx<'static>>);

impl Uart {
    /// No room for more bytes: drop what the ring holds (reading clears the idle and error
    /// flags, which would otherwise raise the interrupt again at once); the host link answers
    /// the frame they belonged to with its error (`BadCrc`, `BadCobs`).
    pub fn hold(&mut self) {
        while self.read_byte().is_some() {}
    }

    /// The next received byte, if any (reading clears the receive interrupt). A receive error
    /// (overrun, noise, framing) is dropped and the read retried once: the lost byte shows up
    /// as a bad frame, which the host link reports.
    ///
    /// After a DMA transfer error stopped the ring's channel, the ring is started again first
    /// (the error's handler pends this task's vector): embassy's ring would otherwise wait for
    /// ever on a channel that no longer runs (its restart follows only a ring overrun it sees
    /// itself).
    pub fn read_byte(&mut self) -> Option<u8> {
        let rx = self.0.as_mut()?;
        if take_rx_ring_failed() {
            rx.start_uart();
        }
        for _ in 0..2 {
            match embedded_hal_nb::serial::Read::read(rx) {
                Ok(b) => return Some(b),
                Err(nb::Error::WouldBlock) => return None,
                Err(nb::Error::Other(_)) => {}
            }
        }
        None
    }
}

/// LPUART1 on PA3 (RX, AF12; its DMA ring on DMA1 CH4, started) and PA2 (TX, AF12; DMA1 CH6);
/// without it ([`BootError::Uart`]) no byte ever arrives or leaves.
pub(super) fn open(
    lpuart1: Peri<'static, peripherals::LPUART1>,
    pa3: Peri<'static, peripherals::PA3>,
    pa2: Peri<'static, peripherals::PA2>,
    rx_dma: Peri<'static, peripherals::DMA1_CH4>,
    tx_dma: Peri<'static, peripherals::DMA1_CH6>,
) -> (Uart, LinkTx) {
    let mut cfg = embassy_stm32::usart::Config::default();
    cfg.baudrate = LPUART_BAUD;
    static mut UART_BUF: [u8; UART_RING] = [0; UART_RING];
    // SAFETY: init context; the ring is handed to embassy for good.
    let uart_buf = unsafe { &mut *addr_of_mut!(UART_BUF) };
    match Lpuart::new(lpuart1, pa3, pa2, tx_dma, rx_dma, Irqs, cfg) {
        Ok(uart) => {
            let (tx, rx) = uart.split();
            let mut rx = rx.into_ring_buffered(uart_buf);
            // The ring's DMA and the idle/error interrupts; embassy starts them only from a
            // read, and the first read here waits for the first interrupt.
            rx.start_uart();
            (Uart(Some(rx)), LinkTx(Some(tx)))
        }
        Err(_) => {
            record(BootError::Uart);
            (Uart(None), LinkTx(None))
        }
    }
}

/// Queue a whole frame of the host link ([`tx_queue::queue`]), or refuse it (`false`) when the
/// queue has no room for all of it: never waits. The task `link_tx` sends it.
pub fn link_send(frame: &[u8]) -> bool {
    tx_queue::queue(frame)
}

/// LPUART1's transmitter (DMA1 CH6), driven by the task `link_tx`: queued bytes in chunks, each
/// written by DMA (embassy's async write, woken by the channel's interrupt).
pub struct LinkTx(Option<UartTx<'static, Async>>);

impl LinkTx {
    /// The task `link_tx` has work on this board.
    pub const BY_TASK: bool = true;

    /// Move the queued bytes, up to `buf`'s length, into `buf`: how many.
    pub fn take(buf: &mut [u8]) -> usize {
        tx_queue::take(buf)
    }

    /// Send `bytes` by DMA; without a transmitter ([`BootError::Uart`]) they are dropped.
    pub async fn write(&mut self, bytes: &[u8]) {
        if let Some(tx) = self.0.as_mut() {
            let _ = tx.write(bytes).await;
        }
    }
}
