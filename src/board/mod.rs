//! Boards: the glue between the driver traits and real or simulated hardware.

#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "sim")]
pub mod sim_factory;
#[cfg(feature = "sim")]
pub mod sim_script;

#[cfg(all(target_os = "none", feature = "qemu"))]
pub mod qemu;
#[cfg(all(target_os = "none", feature = "stm32"))]
pub mod stm32g474;
#[cfg(all(target_os = "none", any(feature = "qemu", feature = "stm32")))]
pub mod tasks;
#[cfg(target_os = "none")]
pub mod tx_queue;

/// A firmware board's parts, as the application takes them over from its `init`: each board
/// names its own types (`qemu::Parts`, `stm32g474::Parts`).
#[cfg(target_os = "none")]
pub struct Parts<Stream, Watchdog, Flash, Uart, LinkTx, LoadCell> {
    /// The sample stream (not yet started).
    pub stream: Stream,
    /// The watchdog.
    pub watchdog: Watchdog,
    /// The store's flash.
    pub flash: Flash,
    /// Host link: receive side.
    pub uart: Uart,
    /// Host link: transmit side, as the task `link_tx` drives it.
    pub link_tx: LinkTx,
    /// The load cell (`None` when there is none, or its pins cannot be driven).
    pub load_cell: Option<LoadCell>,
}

/// The NVIC priority register value of RTIC logical priority `logical` on a core that
/// implements the top `bits` bits of each priority (higher logical priority, lower value).
pub const fn nvic_priority(logical: u8, bits: u8) -> u8 {
    ((1u8 << bits).wrapping_sub(logical)) << (8 - bits)
}

#[cfg(test)]
mod tests {
    /// RM0440 / ARMv7-M: the STM32G4 implements 4 priority bits (values 0x00–0xF0 in steps of
    /// 0x10, 0 the most urgent); RTIC's logical 1 is the least urgent task priority.
    #[test]
    fn logical_priorities_map_to_the_top_bits() {
        assert_eq!(super::nvic_priority(1, 4), 0xF0);
        assert_eq!(super::nvic_priority(2, 4), 0xE0);
        assert_eq!(super::nvic_priority(3, 3), 0xA0);
    }
}
