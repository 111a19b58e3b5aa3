//! Physical units of the public interface and newtypes for raw converter codes.
//!
//! Every quantity that crosses a public API carries its unit in its type: frequencies in [`Hz`],
//! durations in [`Seconds`], drive levels in [`Volts`], moduli in [`KPa`], forces in [`Newtons`], the static
//! admittance in [`Farads`] and [`Siemens`].
//! Raw converter values are [`DacCode`] and [`AdcCode`], never bare integers.

macro_rules! unit {
    ($(#[$doc:meta])* $name:ident, $sym:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
        #[repr(transparent)]
        pub struct $name(pub f32);

        impl $name {
            /// The bare value in this unit.
            #[inline]
            pub const fn get(self) -> f32 {
                self.0
            }
            /// Unit symbol.
            pub const SYMBOL: &'static str = $sym;
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                if let Some(p) = f.precision() {
                    write!(f, "{:.*} {}", p, self.0, $sym)
                } else {
                    write!(f, "{} {}", self.0, $sym)
                }
            }
        }

        #[cfg(feature = "defmt")]
        impl defmt::Format for $name {
            fn format(&self, f: defmt::Formatter) {
                defmt::write!(f, "{=f32}", self.0)
            }
        }
    };
}

unit!(
    /// Frequency in hertz.
    Hz,
    "Hz"
);
unit!(
    /// Time in seconds.
    Seconds,
    "s"
);
unit!(
    /// Voltage in volts.
    Volts,
    "V"
);
unit!(
    /// Current in amperes.
    Amps,
    "A"
);
unit!(
    /// Elastic modulus in kilopascals.
    KPa,
    "kPa"
);
unit!(
    /// Force in newtons.
    Newtons,
    "N"
);
unit!(
    /// Capacitance in farads.
    Farads,
    "F"
);
unit!(
    /// Conductance in siemens.
    Siemens,
    "S"
);

/// A 12-bit DAC code (0..=4095, mid-scale 2048 is zero drive).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(transparent)]
pub struct DacCode(pub u16);

/// A 12-bit ADC code (0..=4095, mid-scale 2048 is zero signal).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(transparent)]
pub struct AdcCode(pub u16);

/// Largest 12-bit code.
pub const MAX_CODE: u16 = 4095;
/// Mid-scale code (zero signal).
pub const MID_CODE: u16 = 2048;

impl DacCode {
    /// Mid-scale: drive off.
    pub const MID: DacCode = DacCode(MID_CODE);
}

impl AdcCode {
    /// True at either rail (the converter clipped).
    #[inline]
    pub const fn is_rail(self) -> bool {
        self.0 == 0 || self.0 >= MAX_CODE
    }
    /// Signed offset from mid-scale, `-2048..=2047`: a value above [`MAX_CODE`] (not a 12-bit
    /// code) is taken as the rail it is beyond.
    #[inline]
    pub fn centered(self) -> i32 {
        (self.0 as i32).clamp(0, MAX_CODE as i32) - MID_CODE as i32
    }
}

/// `x` limited to `lo..=hi`: `lo` below, `hi` above, `x` itself between (and a NaN `x` stays
/// NaN). Unlike `f64::clamp` it never panics: bounds out of order give `lo` below `lo` and `hi`
/// otherwise, and a NaN bound is ignored, so computed bounds (a band, the room left in a
/// buffer) cannot stop the firmware.
pub fn bounded<T: PartialOrd + Copy>(x: T, lo: T, hi: T) -> T {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::bounded;

    #[test]
    fn bounded_limits_and_never_panics() {
        assert_eq!(bounded(5.0, 1.0, 3.0), 3.0);
        assert_eq!(bounded(-5.0, 1.0, 3.0), 1.0);
        assert_eq!(bounded(2.5, 1.0, 3.0), 2.5);
        assert!(bounded(f64::NAN, 1.0, 3.0).is_nan());
        // Where `f64::clamp` panics: bounds out of order, a NaN bound.
        assert_eq!(bounded(2.0, 3.0, 1.0), 3.0);
        assert_eq!(bounded(5.0, 3.0, 1.0), 1.0);
        assert_eq!(bounded(2.0, f64::NAN, 1.0), 1.0);
        assert_eq!(bounded(2.0, 1.0, f64::NAN), 2.0);
        assert_eq!(bounded(7_i32, 0, 4), 4);
    }
}
