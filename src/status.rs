//! The closed set of ways a reading can fail, shared by firmware and host.
//!
//! A reading either carries a number with an honest uncertainty or one of these codes; it never
//! carries a number that the probe cannot stand behind.

coded_enum! {
    /// Why a reading produced no modulus.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub enum Failure {
        /// The probe is not touching tissue (the loaded signature equals the stored air reference).
        NoContact: "no_contact" => "probe is not in contact with tissue: press it on";
        /// Contact was lost during the reading.
        ContactLost: "contact_lost" => "contact was lost during the reading: hold the probe still";
        /// The resonance maps below the calibrated modulus span (too soft to read).
        BelowRange: "below_range" => "softer than the calibrated range";
        /// The resonance maps above the calibrated span, or at/above the calibration asymptote.
        AboveRange: "above_range" => "stiffer than the calibrated range";
        /// The resonance lies at or beyond an edge of the swept band.
        OutOfBand: "out_of_band" => "resonance is outside the swept band: widen the band";
        /// No resonance peak stands out of the noise.
        NoResonance: "no_resonance" => "no resonance found: check contact and drive";
        /// A peak was found but the signal-to-noise ratio is too low for a trustworthy number.
        LowSnr: "low_snr" => "signal too weak for a reliable reading: raise the drive or integrate longer";
        /// The sense ADC clipped (drive too high or a fault).
        Clipped: "clipped" => "sense amplifier clipped; lower the drive";
        /// No current flows: the PZT or its wiring is open.
        OpenCircuit: "open_circuit" => "no current: PZT or wiring open";
        /// The PZT or its wiring is shorted.
        ShortCircuit: "short_circuit" => "PZT or wiring shorted";
        /// The phase tracker did not lock.
        NotLocked: "not_locked" => "phase tracker did not lock: hold the probe still and retry";
        /// Interference (mains, knocks) corrupts the measurement.
        Interference: "interference" => "interference corrupts the measurement: retry away from the source";
        /// The drive does not follow the commanded waveform (DAC or amplifier fault).
        DriveFault: "drive_fault" => "drive does not follow the command";
        /// The board's DMA failed (a transfer error on one of its channels): the sample stream
        /// stopped. A fault of the board, not of the probe or the press.
        DmaError: "dma_error" => "the board's DMA failed (transfer error), not the probe: power-cycle it, and report it if it comes back";
        /// The settings given were invalid.
        BadSettings: "bad_settings" => "invalid settings";
        /// The contact is not the calibrated one: the quality factor stands above the unit's
        /// calibrated Q(E, F) curve (a contact narrower or looser than the calibration's; without a
        /// load cell, off the curve either way).
        BadContact: "bad_contact" => "contact unlike calibration: press at the calibrated force (Q off its curve), or retake the air reference";
        /// The resonance is too broad to read to the instrument's accuracy: the tissue's loss
        /// lowers Q below [`crate::reading::pipeline::MIN_READABLE_Q`].
        BroadResonance: "broad_resonance" => "resonance too broad to read (tissue too lossy at this stiffness): no modulus to the stated accuracy";
        /// The unit has no air reference, so contact cannot be told from no contact.
        NoAirReference: "no_air_reference" => "no air reference: lift the probe into free air and take one (air)";
        /// The unit has no calibrated contact condition (Q model): it was never calibrated.
        Uncalibrated: "uncalibrated" => "unit not calibrated (for this method): calibrate it on reference phantoms with this method";
        /// The resonance moved during the reading (drift, a creeping contact).
        Unstable: "unstable" => "the resonance moved during the reading: hold the probe still and retry";
        /// The unit reads with a load cell and it gave no force for the reading.
        NoForce: "no_force" => "the load cell gave no contact force: check its cable, or retake the air reference";
        /// Pressed more lightly than the unit's force window.
        TooLight: "too_light" => "pressed too lightly: press harder, into the force window";
        /// Pressed harder than the unit's force window.
        TooHard: "too_hard" => "pressed too hard: press more lightly, into the force window";
        /// The contact force changed during the reading.
        ForceUnstable: "force_unstable" => "the contact force changed during the reading: hold the probe still and retry";
    }
    /// Every code, in declaration order.
    const ALL;
    /// Stable snake_case code, as used in JSON and logs.
    fn code;
    /// One line for a human.
    fn message;
}

impl Failure {
    /// A fault of the instrument or of its setup (the converters, the drive, the PZT and its
    /// wiring, the settings, the unit's data), which no press explains.
    pub const fn is_fault(self) -> bool {
        matches!(
            self,
            Failure::Clipped
                | Failure::OpenCircuit
                | Failure::ShortCircuit
                | Failure::DriveFault
                | Failure::DmaError
                | Failure::BadSettings
                | Failure::NoAirReference
                | Failure::Uncalibrated
        )
    }

    /// True for a failure of the press itself, which the load cell tells before the resonance
    /// is read: no contact, no force, too light, too hard, a force that changed.
    pub const fn is_press(self) -> bool {
        matches!(
            self,
            Failure::NoContact
                | Failure::NoForce
                | Failure::TooLight
                | Failure::TooHard
                | Failure::ForceUnstable
        )
    }
}

impl Failure {
    /// The failure a stalled stream ends a reading in: [`Failure::DmaError`] once the board
    /// counted a DMA transfer error (its stream stops at the first, so every later stall is
    /// the DMA's), else [`Failure::DriveFault`].
    pub const fn of_stall(dma_errors: u32) -> Failure {
        if dma_errors > 0 {
            Failure::DmaError
        } else {
            Failure::DriveFault
        }
    }
}

impl core::fmt::Display for Failure {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.code())
    }
}

/// Outcome of a reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Status {
    /// A valid reading.
    Ok,
    /// No valid modulus, for this reason.
    Failed(Failure),
}

impl Status {
    /// `"ok"` or the failure code.
    pub const fn code(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Failed(f) => f.code(),
        }
    }
    /// True for [`Status::Ok`].
    pub const fn is_ok(self) -> bool {
        matches!(self, Status::Ok)
    }
}
