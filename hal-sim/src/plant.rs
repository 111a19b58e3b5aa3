//! The linear plant and its exact discretisation.
//!
//! State of the full chain, `x = [v1, v, q, q', a1, y_i, b1, y_v]`: the reconstruction filter
//! (two first-order sections, inner node `v1`, output the PZT voltage `v`), modal displacement
//! and velocity, the sense current through a two-section anti-alias filter (`a1`, `y_i`, in A)
//! and the PZT voltage through an identical one (`b1`, `y_v`, in V). Input `u`: drive amplifier
//! output (V), held constant over each sample period (zero-order hold, as a DAC does).
//!
//! ```text
//! v1'  = w_r (u - v1)          v'   = w_r (v1 - v)
//! q''  = (alpha v - c q' - k q) / m
//! i    = C0 v' + alpha q' + G_d v
//! a1'  = w_a (i - a1)          y_i' = w_a (a1 - y_i)
//! b1'  = w_a (v - b1)          y_v' = w_a (b1 - y_v)
//! ```
//!
//! Two-pole filters matter: the DAC's zero-order-hold image at `fs − f` aliases back onto the
//! drive frequency, and the capacitive current `C0 dv/dt` amplifies it by `(fs − f)/f ≈ 40`;
//! with two poles at 1 kHz on each side the aliased current is ~1e-4 of the capacitive current.
//!
//! A scene with a second mechanical mode ([`crate::tissue::SecondMode`]) adds its displacement
//! and velocity `q2, q2'` as states 9 and 10 ([`chain_two_modes`]):
//! `q2'' = (alpha2 v - c2 q2' - k2 q2) / m2`, and `alpha2 q2'` joins the sense current. Scenes
//! without one keep the 8-state chain (and its cost per sample).
//!
//! With a held input the exact discrete system is `x[n+1] = Ad x[n] + Bd u[n]`, where
//! `[[Ad, Bd], [0, 1]] = expm([[A, B], [0, 0]] dt)`: no step-size error, whatever `dt`.

use crate::linalg::{expm, mul_vec, Mat};
use crate::pzt::Pzt;
use crate::tissue::Kelvin;
use core::f64::consts::PI;

/// Exactly discretised linear time-invariant system with scalar zero-order-hold input.
#[derive(Clone, Debug)]
pub struct Discrete<const N: usize> {
    /// State transition over one sample.
    pub ad: Mat<N>,
    /// Input vector over one sample.
    pub bd: [f64; N],
    /// Current state.
    pub x: [f64; N],
}

impl<const N: usize> Discrete<N> {
    /// Advance one sample with input `u` held over it.
    #[inline]
    pub fn step(&mut self, u: f64) {
        let mut y = mul_vec(&self.ad, &self.x);
        for (yi, bi) in y.iter_mut().zip(self.bd.iter()) {
            *yi += bi * u;
        }
        self.x = y;
    }
}

/// Discretise `x' = A x + B u` over `dt` with a held input.
pub fn discretize<const N: usize, const M: usize>(
    a: &Mat<N>,
    b: &[f64; N],
    dt: f64,
) -> Discrete<N> {
    assert!(M == N + 1, "augmented size must be N + 1");
    let mut aug = [[0.0; M]; M];
    for i in 0..N {
        for j in 0..N {
            aug[i][j] = a[i][j] * dt;
        }
        aug[i][N] = b[i] * dt;
    }
    let e = expm(&aug);
    let mut ad = [[0.0; N]; N];
    let mut bd = [0.0; N];
    for i in 0..N {
        ad[i][..N].copy_from_slice(&e[i][..N]);
        bd[i] = e[i][N];
    }
    Discrete {
        ad,
        bd,
        x: [0.0; N],
    }
}

/// Mechanics alone (layer 1): state `[q, q']`, input force in N.
pub fn mechanics(mech: &Kelvin, dt: f64) -> Discrete<2> {
    let m = mech.mass_kg;
    let a = [
        [0.0, 1.0],
        [-mech.stiffness_n_m / m, -mech.damping_n_s_m / m],
    ];
    discretize::<2, 3>(&a, &[0.0, 1.0 / m], dt)
}

/// Number of states of the full chain.
pub const CHAIN_STATES: usize = 8;
/// Number of states of the full chain with a second mechanical mode.
pub const CHAIN2_STATES: usize = 10;
/// Index of the PZT voltage in the chain state.
pub const V: usize = 1;
/// Index of the modal velocity in the chain state.
pub const VELOCITY: usize = 3;
/// Index of the first anti-alias section of the sense current (its inner node) in the chain
/// state. A charge `Q` entering the sense input at once steps it by `w_a Q`.
pub const A1: usize = 4;
/// Index of the filtered sense current in the chain state.
pub const Y_I: usize = 5;
/// Index of the filtered PZT voltage in the chain state.
pub const Y_V: usize = 7;
/// Index of the second mode's velocity in the two-mode chain state.
pub const VELOCITY2: usize = 9;

/// Continuous-time model of the chain with an optional second motional branch (`mode2` and its
/// force factor): states `[v1, v, q, q', a1, y_i, b1, y_v, q2, q2']`. Without a second mode the
/// last two states are decoupled and stay at rest.
fn chain_continuous(
    mech: &Kelvin,
    pzt: &Pzt,
    mode2: Option<(&Kelvin, f64)>,
    reconstruction_hz: f64,
    antialias_hz: f64,
) -> (Mat<CHAIN2_STATES>, [f64; CHAIN2_STATES]) {
    let wr = 2.0 * PI * reconstruction_hz;
    let wa = 2.0 * PI * antialias_hz;
    let m = mech.mass_kg;
    let (k, c) = (mech.stiffness_n_m, mech.damping_n_s_m);
    let al = pzt.force_factor_n_v;
    let c0 = pzt.c0_f;
    let gd = pzt.leakage_s;
    let mut a = [[0.0; CHAIN2_STATES]; CHAIN2_STATES];
    // Reconstruction filter: v1' = wr (u - v1), v' = wr (v1 - v).
    a[0][0] = -wr;
    a[1][0] = wr;
    a[1][1] = -wr;
    // Mode 1: q'' = (alpha v - c q' - k q) / m.
    a[2][3] = 1.0;
    a[3][1] = al / m;
    a[3][2] = -k / m;
    a[3][3] = -c / m;
    // a1' = wa (i - a1), i = C0 wr (v1 - v) + alpha q' + G_d v (+ alpha2 q2').
    a[4][0] = wa * c0 * wr;
    a[4][1] = wa * (gd - c0 * wr);
    a[4][3] = wa * al;
    a[4][4] = -wa;
    a[5][4] = wa;
    a[5][5] = -wa;
    a[6][1] = wa;
    a[6][6] = -wa;
    a[7][6] = wa;
    a[7][7] = -wa;
    a[8][9] = 1.0;
    if let Some((k2, al2)) = mode2 {
        let m2 = k2.mass_kg;
        a[9][1] = al2 / m2;
        a[9][8] = -k2.stiffness_n_m / m2;
        a[9][9] = -k2.damping_n_s_m / m2;
        a[4][9] = wa * al2;
    }
    let mut b = [0.0; CHAIN2_STATES];
    b[0] = wr;
    (a, b)
}

/// Full chain (layers 1–3): state `[v1, v, q, q', a1, y_i, b1, y_v]`, input drive amplifier
/// volts. The reconstruction filter and both anti-alias filters are two cascaded first-order
/// sections (`v1`, `a1`, `b1` are their inner nodes).
pub fn chain(
    mech: &Kelvin,
    pzt: &Pzt,
    reconstruction_hz: f64,
    antialias_hz: f64,
    dt: f64,
) -> Discrete<CHAIN_STATES> {
    let (a2, b2) = chain_continuous(mech, pzt, None, reconstruction_hz, antialias_hz);
    let mut a = [[0.0; CHAIN_STATES]; CHAIN_STATES];
    for (row, row2) in a.iter_mut().zip(a2.iter()) {
        row.copy_from_slice(&row2[..CHAIN_STATES]);
    }
    let mut b = [0.0; CHAIN_STATES];
    b.copy_from_slice(&b2[..CHAIN_STATES]);
    discretize::<CHAIN_STATES, 9>(&a, &b, dt)
}

/// Full chain with a second motional branch (`mode2`, driven and sensed through the force factor
/// `alpha2` N/V): state `[v1, v, q, q', a1, y_i, b1, y_v, q2, q2']`. The sense current gains
/// `alpha2 q2'`; the first eight states mean what they mean in [`chain`].
pub fn chain_two_modes(
    mech: &Kelvin,
    pzt: &Pzt,
    mode2: &Kelvin,
    alpha2: f64,
    reconstruction_hz: f64,
    antialias_hz: f64,
    dt: f64,
) -> Discrete<CHAIN2_STATES> {
    let (a, b) = chain_continuous(
        mech,
        pzt,
        Some((mode2, alpha2)),
        reconstruction_hz,
        antialias_hz,
    );
    discretize::<CHAIN2_STATES, 11>(&a, &b, dt)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mechanics_matches_closed_form_free_response() {
        // Underdamped free response from q(0) = 1: q(t) = e^{-z w t}(cos wd t + z w / wd sin wd t)
        let k = Kelvin {
            mass_kg: 1e-3,
            stiffness_n_m: 2000.0,
            damping_n_s_m: 0.02,
        };
        let dt = 1e-4;
        let mut d = mechanics(&k, dt);
        d.x = [1.0, 0.0];
        let w = (k.stiffness_n_m / k.mass_kg).sqrt();
        let z = k.damping_n_s_m / (2.0 * (k.stiffness_n_m * k.mass_kg).sqrt());
        let wd = w * (1.0 - z * z).sqrt();
        for n in 1..=5000 {
            d.step(0.0);
            let t = n as f64 * dt;
            let q = (-z * w * t).exp() * ((wd * t).cos() + z * w / wd * (wd * t).sin());
            assert!((d.x[0] - q).abs() < 1e-9, "n={n} {} vs {q}", d.x[0]);
        }
    }
}
