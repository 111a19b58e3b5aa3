//! The resonance model every estimator fits: the motional branch of the Butterworth–Van Dyke
//! circuit, normalised to its peak conductance,
//!
//! ```text
//! h(f) = 1 / (1 + j Q u),   u = f/f0 − f0/f
//! ```
//!
//! so the PZT's admittance is `Y(f) = G0 + j b0 f/f_ref + g h(f)` (the static branch is the
//! caller's; see [`super::fit`]). `h` traces the admittance circle through 1 at `f = f0`; its
//! half-power points lie at `u = ±1/Q`, so `f0/Q` is the linewidth. With it come the two
//! derivatives a Gauss–Newton step needs, `∂h/∂f0 = −j Q h² ∂u/∂f0` (`∂u/∂f0 = −f/f0² − 1/f`)
//! and `∂h/∂Q = −j u h²`. `tests` check them against the closed form at the peak and against
//! central differences.

use num_complex::Complex64 as C64;

/// The motional response at one drive frequency.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motional {
    /// Detuning `u = f/f0 − f0/f`.
    pub u: f64,
    /// `h = 1 / (1 + j Q u)`.
    pub h: C64,
}

impl Motional {
    /// The response of a resonance at `f0` (Hz) with quality factor `q` at drive frequency `f`
    /// (Hz).
    pub fn at(f0: f64, q: f64, f: f64) -> Self {
        let u = f / f0 - f0 / f;
        let x = q * u;
        let d = 1.0 + x * x;
        // 1 / (1 + j x) = (1 − j x) / (1 + x²)
        Self {
            u,
            h: C64::new(1.0 / d, -x / d),
        }
    }

    /// `(∂h/∂f0, ∂h/∂Q)` at drive frequency `f` (Hz) for a resonance at `f0` with quality `q`:
    /// `−j Q h² ∂u/∂f0` (1/Hz) and `−j u h²`, with `h²` formed once (the fits call this for
    /// every point of every iteration; on the target each `f64` operation is software).
    pub fn derivatives(&self, f0: f64, q: f64, f: f64) -> (C64, C64) {
        let h2 = self.h * self.h;
        let du_df0 = -f / (f0 * f0) - 1.0 / f;
        // −j x h² = (x Im h², −x Re h²)
        let minus_j = |x: f64| C64::new(x * h2.im, -x * h2.re);
        (minus_j(q * du_df0), minus_j(self.u))
    }
}

#[cfg(test)]
mod tests {
    use super::Motional;

    /// At resonance `h = 1`; at the half-power points `f0 (sqrt(1 + 1/(4Q²)) ± 1/(2Q))`
    /// (where `u = ±1/Q`) `h = (1 ∓ j)/2`, |h|² = 1/2.
    #[test]
    fn peak_and_half_power_points() {
        let (f0, q) = (232.0, 10.0);
        let m = Motional::at(f0, q, f0);
        assert_eq!((m.h.re, m.h.im, m.u), (1.0, 0.0, 0.0));
        let r = (1.0 + 1.0 / (4.0 * q * q)).sqrt();
        for (s, im) in [(1.0, -0.5), (-1.0, 0.5)] {
            let f = f0 * (r + s / (2.0 * q));
            let h = Motional::at(f0, q, f).h;
            assert!(
                (h.re - 0.5).abs() < 1e-12 && (h.im - im).abs() < 1e-12,
                "{h}"
            );
        }
    }

    /// The derivatives against central differences. Step 1e-6 of the parameter: the truncation
    /// error `e² h'''/6` is about `(e Q/f0)²/6` of `h'` (below 1e-9 at Q = 40), the rounding error
    /// about 1e-16/1e-6; 1e-7 bounds both.
    #[test]
    fn derivatives_match_central_differences() {
        for &(f0, q, f) in &[
            (232.0, 10.0, 225.0),
            (185.0, 4.0, 260.0),
            (250.0, 40.0, 250.3),
        ] {
            let m = Motional::at(f0, q, f);
            let (e0, eq) = (f0 * 1e-6, q * 1e-6);
            let num_f0 =
                (Motional::at(f0 + e0, q, f).h - Motional::at(f0 - e0, q, f).h) / (2.0 * e0);
            let num_q =
                (Motional::at(f0, q + eq, f).h - Motional::at(f0, q - eq, f).h) / (2.0 * eq);
            let (a, b) = m.derivatives(f0, q, f);
            assert!((a - num_f0).norm() <= 1e-7 * a.norm(), "{a} {num_f0}");
            assert!((b - num_q).norm() <= 1e-7 * b.norm(), "{b} {num_q}");
        }
    }
}
