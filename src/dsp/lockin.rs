//! Synchronous demodulation as an exact three-parameter sine fit (IEEE 1057 style).
//!
//! For every sample the interrupt adds integer products of the ADC code `x` (centred) with the
//! reference `c = cos`, `s = sin` (the DDS's own Q15 table values): `Σxc, Σxs, Σx, Σx²` per
//! channel and `Σc², Σs², Σcs, Σc, Σs, N` for the reference. The sums are exact (i64, no
//! rounding), so at the end of an integration window the least-squares fit
//! `x ≈ a cos φ + b sin φ + d` is solved exactly in f64 — with no leakage from a window that is
//! not a whole number of cycles — and its residual sum of squares `Σx² − βᵀ Xᵀx` gives the noise
//! variance of that very point. The phasor `a − j b` and its covariance follow.
//!
//! Cost in the interrupt: 13 integer multiply-accumulates per sample (both channels and the
//! reference), summed by [`LockInSums::integrate`] a run of at most [`RUN_MAX`] samples at a
//! time in 32-bit registers (the reference's squares in 64 bits) and added to the window's
//! `i64` sums once a run: the same integers as adding each sample's products to the `i64` sums.
//! The solve (a 3×3 inverse) runs once per point at low priority.

use crate::dsp::dds::{cos_q15, run_to_wrap, sin_q15};
use crate::hal::AdcFrame;
use crate::linalg::inverse3;
use crate::units::AdcCode;
use num_complex::Complex64;

/// Scale of the Q15 reference (`table = 32767 sin`).
const Q15: f64 = 32767.0;

/// Integer sums of one ADC channel against the reference.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ChannelSums {
    /// Σ x c.
    pub xc: i64,
    /// Σ x s.
    pub xs: i64,
    /// Σ x.
    pub x: i64,
    /// Σ x².
    pub xx: i64,
}

/// Most samples one run sums in 32 bits: a product `x c` of a centred 12-bit code
/// (`|x| ≤ 2048`) and a Q15 reference (`|c| ≤ 32767`: the table's entries and the interpolation
/// between two of them) is at most `2048 · 32767`, and 32 of them stay below `2^31`.
pub const RUN_MAX: usize = 32;
const _: () = assert!(RUN_MAX as i64 * 2048 * 32767 <= i32::MAX as i64);

/// One channel's sums over a run of at most [`RUN_MAX`] samples, exact in `i32`.
#[derive(Clone, Copy, Default)]
struct RunChannel {
    xc: i32,
    xs: i32,
    x: i32,
    xx: i32,
    rails: u32,
}

impl RunChannel {
    #[inline(always)]
    fn add(&mut self, code: AdcCode, c: i32, s: i32) {
        let x = code.centered();
        self.xc += x * c;
        self.xs += x * s;
        self.x += x;
        self.xx += x * x;
        // At a rail ([`AdcCode::is_rail`]) exactly when `x` is −2048 or 2047, the two values
        // that `x ^ (x >> 31)` (`x` or `−1 − x`, 0..=2047) takes to 2047.
        self.rails += (((x ^ (x >> 31)) + 1) >> 11) as u32;
    }

    #[inline(always)]
    fn add_to(self, sums: &mut ChannelSums, rails: &mut u32) {
        sums.xc += self.xc as i64;
        sums.xs += self.xs as i64;
        sums.x += self.x as i64;
        sums.xx += self.xx as i64;
        *rails += self.rails;
    }
}

/// Integer sums of the reference with itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReferenceSums {
    /// Σ c².
    pub cc: i64,
    /// Σ s².
    pub ss: i64,
    /// Σ c s.
    pub cs: i64,
    /// Σ c.
    pub c: i64,
    /// Σ s.
    pub s: i64,
    /// Number of samples.
    pub n: u32,
}

/// All sums of one integration window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LockInSums {
    /// Sense-current channel.
    pub current: ChannelSums,
    /// Drive-monitor channel.
    pub monitor: ChannelSums,
    /// Reference.
    pub reference: ReferenceSums,
    /// Samples of the current channel at a converter rail.
    pub current_rail_hits: u32,
    /// Samples of the monitor channel at a converter rail.
    pub monitor_rail_hits: u32,
}

impl LockInSums {
    /// Demodulate at most [`RUN_MAX`] of `frames` against the reference from `phase` on (the
    /// DDS's phase of the first frame, advancing `ftw` a sample) until the phase wraps — a
    /// cycle boundary: the sample whose step wraps is the cycle's last and is summed — or the
    /// frames or the run end. Returns how many frames were summed and whether the last of them
    /// wrapped; `phase` is left at the next frame's. The rail hits are the codes
    /// [`AdcCode::is_rail`] finds; the sums take each code as [`AdcCode::centered`] does. Exact
    /// (the same integers as adding every sample's products to the `i64` sums), never panics.
    ///
    /// Three passes that each keep their sums in registers: the reference (`Σc²`, `Σs²`, and
    /// each sample's `c`, `s` kept in `refs` for the next passes: scratch, whatever it held),
    /// then the current channel against it (with `Σc`, `Σs`) and the monitor (with `Σcs`);
    /// their sums added to the window's once. Not inlined: the passes then have the registers
    /// to themselves.
    #[inline(never)]
    pub fn integrate(
        &mut self,
        frames: &[AdcFrame],
        phase: &mut u32,
        ftw: u32,
        refs: &mut [u32; RUN_MAX],
    ) -> (usize, bool) {
        let (n, wrapped) = reference_run(refs, frames.len(), phase, ftw, &mut self.reference);
        let frames = frames.get(..n).unwrap_or_default();
        let (mut c_sum, mut s_sum) = (0i32, 0i32);
        let cur = channel_run(
            frames,
            refs,
            |f| f.current,
            |c, s| {
                c_sum += c;
                s_sum += s;
            },
        );
        cur.add_to(&mut self.current, &mut self.current_rail_hits);
        let mut cs = 0i64;
        let mon = channel_run(
            frames,
            refs,
            |f| f.monitor,
            |c, s| {
                cs += (c as i64) * (s as i64);
            },
        );
        mon.add_to(&mut self.monitor, &mut self.monitor_rail_hits);
        let r = &mut self.reference;
        r.c += c_sum as i64;
        r.s += s_sum as i64;
        r.cs += cs;
        r.n += frames.len() as u32;
        (frames.len(), wrapped)
    }

    /// Add one sample pair (centred codes) with reference `c`, `s` (Q15) straight to the `i64`
    /// sums: the definition [`integrate`](Self::integrate) is tested against.
    #[cfg(test)]
    pub(crate) fn accumulate(&mut self, c: i32, s: i32, current: i32, monitor: i32) {
        for (ch, x) in [(&mut self.current, current), (&mut self.monitor, monitor)] {
            ch.xc += (x as i64) * (c as i64);
            ch.xs += (x as i64) * (s as i64);
            ch.x += x as i64;
            ch.xx += (x as i64) * (x as i64);
        }
        let r = &mut self.reference;
        r.cc += (c as i64) * (c as i64);
        r.ss += (s as i64) * (s as i64);
        r.cs += (c as i64) * (s as i64);
        r.c += c as i64;
        r.s += s as i64;
        r.n += 1;
    }
}

/// The reference of up to `n` samples (at most [`RUN_MAX`]) from `phase` on, stopping after the
/// sample whose step wraps: each sample's `c` (low half) and `s` (high half) into `out`, `Σc²`
/// and `Σs²` added to `r`. Returns the samples and whether the last wrapped; `phase` is left at
/// the next sample's.
#[inline(always)]
fn reference_run(
    out: &mut [u32; RUN_MAX],
    n: usize,
    phase: &mut u32,
    ftw: u32,
    r: &mut ReferenceSums,
) -> (usize, bool) {
    let (n, wrapped) = run_to_wrap(*phase, ftw, n.min(RUN_MAX));
    let (mut cc, mut ss) = (0i64, 0i64);
    let mut p = *phase;
    for slot in out.get_mut(..n).unwrap_or_default() {
        let (c, s) = (cos_q15(p), sin_q15(p));
        *slot = (c as u16 as u32) | ((s as u32) << 16);
        cc += (c as i64) * (c as i64);
        ss += (s as i64) * (s as i64);
        p = p.wrapping_add(ftw);
    }
    *phase = p;
    r.cc += cc;
    r.ss += ss;
    (n, wrapped)
}

/// One channel (`code` of each frame) against the reference `refs` ([`reference_run`]'s, one
/// a frame): its run sums; `also` sees each sample's `c`, `s` (the reference's remaining sums,
/// shared out between the passes so that none runs out of registers).
#[inline(always)]
fn channel_run(
    frames: &[AdcFrame],
    refs: &[u32; RUN_MAX],
    code: impl Fn(&AdcFrame) -> AdcCode,
    mut also: impl FnMut(i32, i32),
) -> RunChannel {
    let mut ch = RunChannel::default();
    for (f, &w) in frames.iter().zip(refs) {
        let (c, s) = (w as u16 as i16 as i32, (w as i32) >> 16);
        ch.add(code(f), c, s);
        also(c, s);
    }
    ch
}

/// A fitted phasor in code units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phasor {
    /// Complex amplitude `a − j b` (peak codes): the channel is `Re(P e^{jφ})` plus offset.
    pub value: Complex64,
    /// Variance of each of the real and imaginary parts (codes², averaged over both).
    pub variance: f64,
    /// Fitted offset `d` in codes.
    pub offset: f64,
    /// RMS of the residual in codes (noise, quantisation, harmonics).
    pub residual_rms: f64,
}

/// Solve the sine fit of one channel. `None` if the window is too short (fewer than 4 samples)
/// or the reference does not span a sine (degenerate normal matrix).
pub fn solve(ch: &ChannelSums, r: &ReferenceSums) -> Option<Phasor> {
    let (value, variance, beta, sigma2) = fit(ch, r)?;
    Some(Phasor {
        value,
        variance,
        offset: beta[2],
        residual_rms: libm::sqrt(sigma2),
    })
}

/// [`solve`]'s complex amplitude and its variance alone (to rounding), at a third of the work on
/// the Cortex-M4F, which emulates `f64`: the offset is eliminated exactly in integers — the
/// centred sums `N Σcc − (Σc)²`, `N Σxc − Σx Σc`, `N Σx² − (Σx)²`, … ([`centred`]) — which leaves
/// a 2×2 system over (cosine, sine) solved by Cramer's rule, the residual `N Σx² − (Σx)² − βᵀu`
/// of the exact centred `Σx²` (no square root). The hold solves one a window. `None` where the
/// centred reference is singular to working precision (`det ≤ 10⁻¹³` of its diagonal's
/// product: the reference does not span a sine) or there are fewer than 4 samples.
pub fn solve_value(ch: &ChannelSums, r: &ReferenceSums) -> Option<(Complex64, f64)> {
    solve_value_scaled(ch, r, 1.0)
}

/// [`solve_value`] in units of `scale` codes (the amplitude times `scale`, its variance times
/// `scale²`; `scale` finite, nonzero and within `f32`'s range, as a front end's amperes per
/// code): the scale folded into the Cramer solve's `1/det` (no products of the results).
pub fn solve_value_scaled(
    ch: &ChannelSums,
    r: &ReferenceSums,
    scale: f64,
) -> Option<(Complex64, f64)> {
    if r.n < 4 {
        return None;
    }
    let n = r.n as i64;
    // N² times the centred (co)variances of the reference, and N² times the centred products
    // of the channel with it.
    let a = centred(n, r.cc, r.c, r.c);
    let b = centred(n, r.cs, r.c, r.s);
    let c = centred(n, r.ss, r.s, r.s);
    let ac = a * c;
    let det = ac - b * b;
    if !(det > 1e-13 * ac) || !det.is_finite() {
        return None;
    }
    let u = centred(n, ch.xc, ch.x, r.c);
    let v = centred(n, ch.xs, ch.x, r.s);
    // `k` the reference's Q15 units times `scale`: the coefficients `(ca, cb)` come out times
    // `k`, and so does the residual below.
    let k = Q15 * scale;
    let k_det = k / det;
    let ca = (c * u - b * v) * k_det;
    let cb = (a * v - b * u) * k_det;
    // `k` × N × the residual sum of squares; its variance σ² = rss_n / (N (N − 3)).
    let rss_nk = (k * centred(n, ch.xx, ch.x, ch.x) - (ca * u + cb * v)).max(0.0);
    // Each component's variance: half of σ² ((M⁻¹)_aa + (M⁻¹)_bb), the full normal matrix's
    // `N (C + A) / det` of the centred one (the N's cancel), times `k²`. In `f32` once the
    // residual has cancelled (a product of positive factors: 1e-7 of itself, where a variance
    // is known to a few percent; `f64` is emulated on the Cortex-M4F).
    // (`k (A + C)/det` itself in `f64`: its factors pass `f32`'s range on long windows.)
    let var = 0.5 * (rss_nk as f32) / (r.n as f32 - 3.0) * ((a + c) * k_det) as f32;
    Some((Complex64::new(ca, -cb), var.max(0.0) as f64))
}

/// `N Σpq − Σp Σq` (`N` times a centred sum of products) exactly in integers, then in `f64`:
/// `i64` while the products fit (every window below 92 000 samples: `N Σc² ≤ N² 32767²`),
/// `i128` otherwise (any `i64` sums: products below 2¹²⁶).
fn centred(n: i64, pq: i64, p: i64, q: i64) -> f64 {
    match (n.checked_mul(pq), p.checked_mul(q)) {
        (Some(x), Some(y)) => match x.checked_sub(y) {
            Some(d) => d as f64,
            None => (x as i128 - y as i128) as f64,
        },
        _ => (n as i128 * pq as i128 - p as i128 * q as i128) as f64,
    }
}

/// The sine fit: the amplitude, its variance, the coefficients `(a, b, d)` and the residual
/// variance.
fn fit(ch: &ChannelSums, r: &ReferenceSums) -> Option<(Complex64, f64, [f64; 3], f64)> {
    if r.n < 4 {
        return None;
    }
    let m = [
        [r.cc as f64, r.cs as f64, r.c as f64],
        [r.cs as f64, r.ss as f64, r.s as f64],
        [r.c as f64, r.s as f64, r.n as f64],
    ];
    let inv = inverse3(&m)?;
    let rhs = [ch.xc as f64, ch.xs as f64, ch.x as f64];
    let mut beta = [0.0; 3];
    for (i, b) in beta.iter_mut().enumerate() {
        *b = inv[i][0] * rhs[0] + inv[i][1] * rhs[1] + inv[i][2] * rhs[2];
    }
    let explained = beta[0] * rhs[0] + beta[1] * rhs[1] + beta[2] * rhs[2];
    let rss = (ch.xx as f64 - explained).max(0.0);
    let dof = (r.n - 3) as f64;
    let sigma2 = rss / dof;
    let var_a = Q15 * Q15 * sigma2 * inv[0][0];
    let var_b = Q15 * Q15 * sigma2 * inv[1][1];
    Some((
        Complex64::new(beta[0] * Q15, -beta[1] * Q15),
        0.5 * (var_a + var_b).max(0.0),
        beta,
        sigma2,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dsp::dds::{tuning_word, QUARTER_TURN};

    /// Reference: an f64 least-squares fit by explicit normal equations on the same samples.
    #[test]
    fn exact_fit_of_non_integer_window() {
        let ftw = tuning_word(231.7, 10_000.0);
        let mut sums = LockInSums::default();
        let mut phase = 123_456_789u32;
        let (amp, ph0, off) = (812.3, 0.7f64, 17.0);
        for _ in 0..777 {
            // not a whole number of cycles
            let x = phase as f64 / 4_294_967_296.0 * 2.0 * core::f64::consts::PI;
            let v = amp * (x + ph0).cos() + off;
            let xi = v.round() as i32;
            sums.accumulate(cos_q15(phase), sin_q15(phase), xi, xi);
            phase = phase.wrapping_add(ftw);
        }
        let p = solve(&sums.current, &sums.reference).unwrap();
        // amp cos(x + ph0) = Re(amp e^{j ph0} e^{jx}) -> phasor amp e^{j ph0}
        assert!((p.value.norm() - amp).abs() < 0.05, "{}", p.value.norm());
        assert!((p.value.arg() - ph0).abs() < 1e-4);
        assert!((p.offset - off).abs() < 0.05);
        // Residual is the rounding of the codes: uniform, rms 1/sqrt(12) = 0.289.
        assert!((p.residual_rms - 0.289).abs() < 0.03, "{}", p.residual_rms);
        // The value-only solve agrees to rounding: the amplitude to `f64`'s, the variance
        // (formed in `f32` once the residual has cancelled) to `f32`'s.
        let (dv, dvar) = value_solve_error(&sums);
        assert!(dv <= 1e-12 * p.value.norm(), "{dv:e}");
        assert!(dvar < 1e-6, "{dvar:e}");
    }

    /// The value-only solve against the full one on `sums`: the amplitude's distance and the
    /// variance's relative error.
    fn value_solve_error(sums: &LockInSums) -> (f64, f64) {
        let p = solve(&sums.current, &sums.reference).unwrap();
        let (v, var) = solve_value(&sums.current, &sums.reference).unwrap();
        ((v - p.value).norm(), (var / p.variance - 1.0).abs())
    }

    /// `integrate` at the sums' extremes — a code at either rail against a reference held at
    /// ±32767 (zero frequency: no wrap) for 100 samples, three full runs and a part — against the
    /// per-sample `i64` definition; the test build checks every `i32` step for overflow.
    #[test]
    fn integrating_at_the_extremes_is_exact() {
        for (phase0, code) in [
            (0, 0),
            (0, 4095),
            (QUARTER_TURN, 0),
            (2 * QUARTER_TURN, 4095),
        ] {
            let frames = [AdcFrame {
                current: AdcCode(code),
                monitor: AdcCode(4095 - code),
            }; 100];
            let (mut run, mut phase, mut rest) = (LockInSums::default(), phase0, &frames[..]);
            while !rest.is_empty() {
                let (n, wrapped) = run.integrate(rest, &mut phase, 0, &mut [7; RUN_MAX]);
                assert_eq!((n, wrapped), (rest.len().min(RUN_MAX), false));
                rest = &rest[n..];
            }
            let mut want = LockInSums::default();
            for f in &frames {
                let (c, s) = (cos_q15(phase0), sin_q15(phase0));
                want.accumulate(c, s, f.current.centered(), f.monitor.centered());
            }
            want.current_rail_hits = 100;
            want.monitor_rail_hits = 100;
            assert_eq!(run, want);
        }
    }

    /// The value-only solve against the full one (its 3×3 `f64` inverse) on random windows:
    /// 5 to 20 000 samples, 0.5 Hz to 4.9 kHz at 10 kHz (one cycle to thousands), amplitudes of
    /// 1 to 2 000 codes on offsets of ±2 000 with noise of 0 to 50 codes; and scaled
    /// ([`solve_value_scaled`], 1e-12 to 1 of a code) against the full one's times the scale.
    /// The amplitude within 1e-9 of its standard uncertainty plus 1e-12 of itself, the variance
    /// within 1e-6 of itself: rounding (the full solve's own, on the worst-conditioned windows).
    #[test]
    fn value_only_solve_agrees_with_the_full_one_on_random_windows() {
        let mut rng = probe_rng::Rng::new(1057);
        let (mut worst_v, mut worst_var, mut solved) = (0.0f64, 0.0f64, 0);
        for _ in 0..3000 {
            let f = 0.5 * 9800f64.powf(rng.uniform());
            let n = 4 + (20_000f64.powf(rng.uniform()) as u32);
            // A cycle or more: the engine's windows are whole cycles (shorter, the full solve's
            // 3×3 inverse loses the digits the exact centring keeps, and is no reference).
            if f * n as f64 / 10_000.0 < 1.0 {
                continue;
            }
            let (amp, off) = (2000f64.powf(rng.uniform()), 4000.0 * (rng.uniform() - 0.5));
            let (ph0, noise) = (7.0 * rng.uniform(), 50.0 * rng.uniform() * rng.uniform());
            let ftw = tuning_word(f, 10_000.0);
            let mut sums = LockInSums::default();
            let mut phase = rng.next_u64() as u32;
            for _ in 0..n {
                let x = phase as f64 / 4_294_967_296.0 * core::f64::consts::TAU;
                let v = amp * (x + ph0).cos() + off + noise * rng.normal();
                let xi = (v.round() as i32).clamp(-2048, 2047);
                sums.accumulate(cos_q15(phase), sin_q15(phase), xi, xi);
                phase = phase.wrapping_add(ftw);
            }
            let full = solve(&sums.current, &sums.reference);
            let fast = solve_value(&sums.current, &sums.reference);
            let scale = 10f64.powf(-12.0 * rng.uniform());
            let scaled = solve_value_scaled(&sums.current, &sums.reference, scale);
            for (k, fast) in [(1.0, fast), (scale, scaled)] {
                match (full, fast) {
                    (Some(p), Some((v, var))) => {
                        solved += 1;
                        let sd = p.variance.sqrt() + 1e-12 * p.value.norm();
                        let dv = (v - p.value * k).norm() / (k * sd);
                        worst_v = worst_v.max(dv);
                        if p.variance > 0.0 {
                            worst_var = worst_var.max((var / (p.variance * k * k) - 1.0).abs());
                        }
                    }
                    (None, None) => {}
                    (a, b) => panic!("f {f} n {n} scale {k:e}: {a:?} vs {b:?}"),
                }
            }
        }
        std::eprintln!("{solved} solved; worst: value {worst_v:e} (of σ), variance {worst_var:e}");
        assert!(solved > 2400, "{solved}");
        assert!(worst_v < 1e-9, "{worst_v:e}");
        assert!(worst_var < 1e-6, "{worst_var:e}");
    }

    /// A window too long for [`centred`]'s `i64` products (300 000 samples, the `i128` path):
    /// the value-only solve agrees with the full one to rounding.
    #[test]
    fn value_only_solve_of_a_very_long_window() {
        let ftw = tuning_word(241.3, 10_000.0);
        let mut rng = probe_rng::Rng::new(3);
        let mut sums = LockInSums::default();
        let mut phase = 0x1234_5678u32;
        for _ in 0..300_000 {
            let x = phase as f64 / 4_294_967_296.0 * core::f64::consts::TAU;
            let v = 1500.0 * (x + 0.3).cos() - 700.0 + 3.0 * rng.normal();
            let xi = (v.round() as i32).clamp(-2048, 2047);
            sums.accumulate(cos_q15(phase), sin_q15(phase), xi, xi);
            phase = phase.wrapping_add(ftw);
        }
        let r = &sums.reference;
        assert!(
            (r.n as i64).checked_mul(r.cc).is_none(),
            "not the i128 path"
        );
        let sigma = solve(&sums.current, r).unwrap().variance.sqrt();
        let (dv, dvar) = value_solve_error(&sums);
        assert!(dv <= 1e-9 * sigma, "{dv:e} of σ {sigma:e}");
        assert!(dvar < 1e-6, "{dvar:e}");
    }

    #[test]
    fn degenerate_windows_are_rejected() {
        let s = LockInSums::default();
        assert!(solve(&s.current, &s.reference).is_none());
        assert!(solve_value(&s.current, &s.reference).is_none());
        let mut s = LockInSums::default();
        for _ in 0..100 {
            s.accumulate(32767, 0, 5, 5); // zero frequency: no sine to fit
        }
        assert!(solve(&s.current, &s.reference).is_none());
        assert!(solve_value(&s.current, &s.reference).is_none());
    }
}
