//! The STM32 board's host link: LPUART1 receive on the ST-LINK virtual COM port.

use core::ptr::addr_of_mut;
use embassy_stm32::usart::{RingBufferedUartRx, UartRx};
use embassy_stm32::{peripherals, Peri};

use super::interrupts::Irqs;
use super::reset::record;
use super::BootError;

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
    /// flags, which would otherwise raise the interrupt again at once); the line they belonged
    /// to then fails to parse and is reported.
    pub fn hold(&mut self) {
        while self.read_byte().is_some() {}
    }

    /// The next received byte, if any (reading clears the receive interrupt). A receive error
    /// (overrun, noise, framing) is dropped and the read retried once: the lost byte shows up
    /// as a malformed line, which the parser reports.
    pub fn read_byte(&mut self) -> Option<u8> {
        let rx = self.0.as_mut()?;
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

/// LPUART1 RX on PA3 (AF12), its DMA ring on DMA1 CH4, started; without one
/// ([`BootError::Uart`]) no byte ever arrives.
pub(super) fn open(
    lpuart1: Peri<'static, peripherals::LPUART1>,
    pa3: Peri<'static, peripherals::PA3>,
    dma: Peri<'static, peripherals::DMA1_CH4>,
) -> Uart {
    let mut cfg = embassy_stm32::usart::Config::default();
    cfg.baudrate = LPUART_BAUD;
    static mut UART_BUF: [u8; UART_RING] = [0; UART_RING];
    // SAFETY: init context; the ring is handed to embassy for good.
    let uart_buf = unsafe { &mut *addr_of_mut!(UART_BUF) };
    Uart(match UartRx::new(lpuart1, pa3, dma, Irqs, cfg) {
        Ok(rx) => {
            let mut rx = rx.into_ring_buffered(uart_buf);
            // The ring's DMA and the idle/error interrupts; embassy starts them only from a
            // read, and the first read here waits for the first interrupt.
            rx.start_uart();
            Some(rx)
        }
        Err(_) => {
            record(BootError::Uart);
            None
        }
    })
}
