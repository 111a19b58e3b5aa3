//! The independent watchdog (RM0440 "Independent watchdog (IWDG)"; registers from
//! stm32-metapac `iwdg_v2`), clocked by the 32 kHz LSI.
//!
//! Covers: the key register (0xCCCC start, 0xAAAA reload, 0x5555 write access to PR/RLR/WINR),
//! the prescaler and reload, the down-counter and the reset at its end (the board turns it
//! into a system reset with IWDGRSTF). Once started it cannot be stopped.
//! Leaves out: the window (WINR stored, never checked), the update-in-progress flags' timing
//! (PVU/RVU/WVU read 0: updates apply at once), the LSI's ±5 % tolerance (exactly 32 kHz), the
//! hardware watchdog option (OPTR.IWDG_SW), stop/standby freezing; DBGMCU's freeze applies
//! only while a debugger halts the core, which never happens here.

/// LSI frequency, Hz.
pub const LSI_HZ: f64 = 32_000.0;

/// The IWDG's state.
#[derive(Clone, Debug)]
pub struct Iwdg {
    pr: u32,
    rlr: u32,
    winr: u32,
    access: bool,
    /// Started (0xCCCC written).
    pub running: bool,
    /// When the counter reaches 0 (seconds), while running.
    expires: f64,
}

impl Default for Iwdg {
    fn default() -> Self {
        Iwdg {
            pr: 0,
            rlr: 0xFFF,
            winr: 0xFFF,
            access: false,
            running: false,
            expires: f64::INFINITY,
        }
    }
}

impl Iwdg {
    fn period(&self) -> f64 {
        let div = 4u32 << self.pr.min(6);
        (self.rlr as f64 + 1.0) * div as f64 / LSI_HZ
    }

    /// When the watchdog resets the core, s.
    pub fn next_event(&self) -> Option<f64> {
        self.running.then_some(self.expires)
    }

    /// True when the counter ran out by `t`.
    pub fn expired(&self, t: f64) -> bool {
        self.running && t >= self.expires
    }

    /// Register read.
    pub fn read(&self, off: u32, t: f64) -> Option<u32> {
        let _ = t;
        Some(match off {
            0x0 => 0,
            0x4 => self.pr,
            0x8 => self.rlr,
            0xC => 0,
            0x10 => self.winr,
            _ => return None,
        })
    }

    /// Register write at `t` (seconds).
    pub fn write(&mut self, off: u32, v: u32, t: f64) -> Option<()> {
        match off {
            0x0 => match v & 0xFFFF {
                0xCCCC => {
                    self.running = true;
                    self.expires = t + self.period();
                }
                0xAAAA => {
                    self.access = false;
                    if self.running {
                        self.expires = t + self.period();
                    }
                }
                0x5555 => self.access = true,
                _ => self.access = false,
            },
            0x4 if self.access => self.pr = v & 7,
            0x8 if self.access => self.rlr = v & 0xFFF,
            0x10 if self.access => {
                // Writing WINR reloads the counter (RM0440 IWDG "Window option").
                self.winr = v & 0xFFF;
                if self.running {
                    self.expires = t + self.period();
                }
            }
            0x4 | 0x8 | 0xC | 0x10 => {}
            _ => return None,
        }
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timeout_is_reload_times_prescaler_over_lsi() {
        // RM0440 IWDG: t = (RL + 1) × 4 × 2^PR / f_LSI. PR = 4 (/64), RL = 249 → 0.5 s.
        let mut w = Iwdg::default();
        w.write(0x0, 0x5555, 0.0).unwrap();
        w.write(0x4, 4, 0.0).unwrap();
        w.write(0x8, 249, 0.0).unwrap();
        w.write(0x0, 0xCCCC, 1.0).unwrap();
        assert!((w.next_event().unwrap() - 1.5).abs() < 1e-12);
        w.write(0x0, 0xAAAA, 1.25).unwrap();
        assert!(!w.expired(1.6));
        assert!(w.expired(1.75));
        // Without the 0x5555 key, PR and RLR ignore writes.
        w.write(0x4, 0, 2.0).unwrap();
        assert_eq!(w.read(0x4, 2.0), Some(4));
    }
}
