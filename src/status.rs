//! The closed set of ways a reading can fail, shared by firmware and host.
//!
//! A reading either carries a number with an honest uncertainty or one of these codes; it never
//! carries a number that the probe cannot stand behind.

/// Why a reading produced no modulus.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Failure {
    /// The probe is not touching tissue (the loaded signature equals the stored air reference).
    NoContact,
    /// Contact was lost during the reading.
    ContactLost,
    /// The resonance maps below the calibrated modulus span (too soft to read).
    BelowRange,
    /// The resonance maps above the calibrated span, or at/above the calibration asymptote.
    AboveRange,
    /// The resonance lies at or beyond an edge of the swept band.
    OutOfBand,
    /// No resonance peak stands out of the noise.
    NoResonance,
    /// A peak was found but the signal-to-noise ratio is too low for a trustworthy number.
    LowSnr,
    /// The sense ADC clipped (drive too high or a fault).
    Clipped,
    /// No current flows: the PZT or its wiring is open.
    OpenCircuit,
    /// The PZT or its wiring is shorted.
    ShortCircuit,
    /// The phase tracker did not lock.
    NotLocked,
    /// Interference (mains, knocks) corrupts the measurement.
    Interference,
    /// The drive does not follow the commanded waveform (DAC or amplifier fault).
    DriveFault,
    /// The settings given were invalid.
    BadSettings,
    /// The contact is not the calibrated one: the quality factor stands above the unit's
    /// calibrated Q(E, F) curve (a contact narrower or looser than the calibration's; without a
    /// load cell, off the curve either way).
    BadContact,
    /// The resonance is too broad to read to the instrument's accuracy: the tissue's loss
    /// lowers Q below [`crate::reading::pipeline::MIN_READABLE_Q`].
    BroadResonance,
    /// The unit has no air reference, so contact cannot be told from no contact.
    NoAirReference,
    /// The unit has no calibrated contact condition (Q model): it was never calibrated.
    Uncalibrated,
    /// The resonance moved during the reading (drift, a creeping contact).
    Unstable,
    /// The unit reads with a load cell and it gave no force for the reading.
    NoForce,
    /// Pressed more lightly than the unit's force window.
    TooLight,
    /// Pressed harder than the unit's force window.
    TooHard,
    /// The contact force changed during the reading.
    ForceUnstable,
}

impl Failure {
    /// Every code, in declaration order.
    pub const ALL: [Failure; 23] = [
        Failure::NoContact,
        Failure::ContactLost,
        Failure::BelowRange,
        Failure::AboveRange,
        Failure::OutOfBand,
        Failure::NoResonance,
        Failure::LowSnr,
        Failure::Clipped,
        Failure::OpenCircuit,
        Failure::ShortCircuit,
        Failure::NotLocked,
        Failure::Interference,
        Failure::DriveFault,
        Failure::BadSettings,
        Failure::BadContact,
        Failure::BroadResonance,
        Failure::NoAirReference,
        Failure::Uncalibrated,
        Failure::Unstable,
        Failure::NoForce,
        Failure::TooLight,
        Failure::TooHard,
        Failure::ForceUnstable,
    ];

    /// Stable snake_case code, as used in JSON and logs.
    pub const fn code(self) -> &'static str {
        match self {
            Failure::NoContact => "no_contact",
            Failure::ContactLost => "contact_lost",
            Failure::BelowRange => "below_range",
            Failure::AboveRange => "above_range",
            Failure::OutOfBand => "out_of_band",
            Failure::NoResonance => "no_resonance",
            Failure::LowSnr => "low_snr",
            Failure::Clipped => "clipped",
            Failure::OpenCircuit => "open_circuit",
            Failure::ShortCircuit => "short_circuit",
            Failure::NotLocked => "not_locked",
            Failure::Interference => "interference",
            Failure::DriveFault => "drive_fault",
            Failure::BadSettings => "bad_settings",
            Failure::BadContact => "bad_contact",
            Failure::BroadResonance => "broad_resonance",
            Failure::NoAirReference => "no_air_reference",
            Failure::Uncalibrated => "uncalibrated",
            Failure::Unstable => "unstable",
            Failure::NoForce => "no_force",
            Failure::TooLight => "too_light",
            Failure::TooHard => "too_hard",
            Failure::ForceUnstable => "force_unstable",
        }
    }

    /// One line for a human.
    pub const fn message(self) -> &'static str {
        match self {
            Failure::NoContact => "probe is not in contact with tissue: press it on",
            Failure::ContactLost => "contact was lost during the reading: hold the probe still",
            Failure::BelowRange => "softer than the calibrated range",
            Failure::AboveRange => "stiffer than the calibrated range",
            Failure::OutOfBand => "resonance is outside the swept band: widen the band",
            Failure::NoResonance => "no resonance found: check contact and drive",
            Failure::LowSnr => "signal too weak for a reliable reading: raise the drive or integrate longer",
            Failure::Clipped => "sense amplifier clipped; lower the drive",
            Failure::OpenCircuit => "no current: PZT or wiring open",
            Failure::ShortCircuit => "PZT or wiring shorted",
            Failure::NotLocked => "phase tracker did not lock: hold the probe still and retry",
            Failure::Interference => "interference corrupts the measurement: retry away from the source",
            Failure::DriveFault => "drive does not follow the command",
            Failure::BadSettings => "invalid settings",
            Failure::BadContact => "contact unlike calibration: press at the calibrated force (Q off its curve), or retake the air reference",
            Failure::BroadResonance => "resonance too broad to read (tissue too lossy at this stiffness): no modulus to the stated accuracy",
            Failure::Unstable => "the resonance moved during the reading: hold the probe still and retry",
            Failure::NoForce => "the load cell gave no contact force: check its cable, or retake the air reference",
            Failure::TooLight => "pressed too lightly: press harder, into the force window",
            Failure::TooHard => "pressed too hard: press more lightly, into the force window",
            Failure::ForceUnstable => "the contact force changed during the reading: hold the probe still and retry",
            Failure::NoAirReference => "no air reference: lift the probe into free air and take one (air)",
            Failure::Uncalibrated => "unit not calibrated (for this method): calibrate it on reference phantoms with this method",
        }
    }

    /// A fault of the instrument or of its setup (the converters, the drive, the PZT and its
    /// wiring, the settings, the unit's data), which no press explains.
    pub const fn is_fault(self) -> bool {
        matches!(
            self,
            Failure::Clipped
                | Failure::OpenCircuit
                | Failure::ShortCircuit
                | Failure::DriveFault
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

    /// Parse a [`code`](Self::code).
    pub fn from_code(s: &str) -> Option<Failure> {
        Self::ALL.into_iter().find(|f| f.code() == s)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_are_unique() {
        for (i, a) in Failure::ALL.iter().enumerate() {
            assert_eq!(Failure::from_code(a.code()), Some(*a));
            assert!(!a.message().is_empty());
            for b in &Failure::ALL[i + 1..] {
                assert_ne!(a.code(), b.code());
            }
        }
        assert_eq!(Failure::from_code("nonsense"), None);
    }
}
