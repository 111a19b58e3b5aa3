//! Layer 2: PZT electromechanics.
//!
//! The d31 plate is a two-port: the voltage `V` across it pushes the mode with force `alpha V`
//! and the mode's velocity `x'` returns a current `alpha x'`. The plate's own static capacitance
//! `C0` carries `C0 dV/dt` in parallel, and an optional dielectric leakage conductance `G_d`
//! carries `G_d V`. In the frequency domain this is the Butterworth–Van Dyke admittance
//! `Y = G_d + j w C0 + alpha^2 / (c + j w m + k / (j w))`.

use crate::complex::C64;
use crate::tissue::Kelvin;
use core::f64::consts::PI;

/// PZT plate parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pzt {
    /// Static (clamped) capacitance in F.
    pub c0_f: f64,
    /// Force factor `alpha` in N/V (equal to the current per velocity, A s/m).
    pub force_factor_n_v: f64,
    /// Dielectric leakage conductance in S (0: lossless).
    pub leakage_s: f64,
}

impl Default for Pzt {
    /// 7 x 1 x 0.5 mm PZT-5A: `C0 = eps33 A / t = 1700 eps0 * 7 mm^2 / 0.5 mm = 210 pF`;
    /// `alpha` fitted so that, pressed on 300 kPa tissue, the motional current at resonance is
    /// half the capacitive one (the static capacitance masks the resonance, as in the paper).
    fn default() -> Self {
        Self {
            c0_f: 210e-12,
            force_factor_n_v: 1.14e-4,
            leakage_s: 0.0,
        }
    }
}

impl Pzt {
    /// Closed-form electrical admittance (S) of the plate driving `mech` at `freq_hz`.
    pub fn admittance(&self, mech: &Kelvin, freq_hz: f64) -> C64 {
        let w = 2.0 * PI * freq_hz;
        let z_mech = C64::new(
            mech.damping_n_s_m,
            w * mech.mass_kg - mech.stiffness_n_m / w,
        );
        let a2 = self.force_factor_n_v * self.force_factor_n_v;
        let motional = if a2 > 0.0 {
            C64::new(a2, 0.0) / z_mech
        } else {
            C64::default()
        };
        C64::new(self.leakage_s, w * self.c0_f) + motional
    }

    /// Peak motional conductance `alpha^2 / c` in S.
    pub fn motional_peak_s(&self, mech: &Kelvin) -> f64 {
        self.force_factor_n_v * self.force_factor_n_v / mech.damping_n_s_m
    }
}
