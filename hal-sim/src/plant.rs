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

/// The chain's states in the order of the state vector, `[v1, v, q, q', a1, y_i, b1, y_v, q2,
/// q2']` (module documentation): one name per index of [`Discrete::x`] and of the matrices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    /// Inner node of the reconstruction filter, V.
    V1,
    /// The PZT voltage, V.
    V,
    /// Modal displacement, m.
    Q,
    /// Modal velocity, m/s.
    Velocity,
    /// Inner node of the sense current's anti-alias filter, A. A charge `Q` entering the sense
    /// input at once steps it by `w_a Q`.
    A1,
    /// The filtered sense current, A.
    YI,
    /// Inner node of the PZT voltage's anti-alias filter, V.
    B1,
    /// The filtered PZT voltage, V.
    YV,
    /// The second mode's displacement, m (two-mode chain only).
    Q2,
    /// The second mode's velocity, m/s (two-mode chain only).
    Velocity2,
}

impl State {
    /// Its index in the state vector.
    pub const fn at(self) -> usize {
        self as usize
    }
}

/// Number of states of the full chain (those before the second mode's).
pub const CHAIN_STATES: usize = State::Q2.at();
/// Number of states of the full chain with a second mechanical mode.
pub const CHAIN2_STATES: usize = State::Velocity2.at() + 1;

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
    use State::*;
    let wr = 2.0 * PI * reconstruction_hz;
    let wa = 2.0 * PI * antialias_hz;
    let m = mech.mass_kg;
    let (k, c) = (mech.stiffness_n_m, mech.damping_n_s_m);
    let al = pzt.force_factor_n_v;
    let c0 = pzt.c0_f;
    let gd = pzt.leakage_s;
    let mut a = [[0.0; CHAIN2_STATES]; CHAIN2_STATES];
    let mut set = |row: State, col: State, v: f64| a[row.at()][col.at()] = v;
    // Reconstruction filter: v1' = wr (u - v1), v' = wr (v1 - v).
    set(V1, V1, -wr);
    set(V, V1, wr);
    set(V, V, -wr);
    // Mode 1: q'' = (alpha v - c q' - k q) / m.
    set(Q, Velocity, 1.0);
    set(Velocity, V, al / m);
    set(Velocity, Q, -k / m);
    set(Velocity, Velocity, -c / m);
    // a1' = wa (i - a1), i = C0 wr (v1 - v) + alpha q' + G_d v (+ alpha2 q2').
    set(A1, V1, wa * c0 * wr);
    set(A1, V, wa * (gd - c0 * wr));
    set(A1, Velocity, wa * al);
    set(A1, A1, -wa);
    set(YI, A1, wa);
    set(YI, YI, -wa);
    set(B1, V, wa);
    set(B1, B1, -wa);
    set(YV, B1, wa);
    set(YV, YV, -wa);
    set(Q2, Velocity2, 1.0);
    if let Some((k2, al2)) = mode2 {
        let m2 = k2.mass_kg;
        set(Velocity2, V, al2 / m2);
        set(Velocity2, Q2, -k2.stiffness_n_m / m2);
        set(Velocity2, Velocity2, -k2.damping_n_s_m / m2);
        set(A1, Velocity2, wa * al2);
    }
    let mut b = [0.0; CHAIN2_STATES];
    b[V1.at()] = wr;
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
