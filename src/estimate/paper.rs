//! **paper**: the method of paper 003 — the frequency where the impedance dips (`|Z|` minimum,
//! i.e. `|Y|` maximum), refined by a three-point parabola.
//!
//! Kept as the baseline. The static capacitance `C0` in parallel with the motional branch makes
//! `|Y| ≈ w C0` rise across the band, so the dip is taken as the largest maximum of `|Y|` above
//! the straight line through the band's end points (a global `|Z|` minimum would sit on the
//! band edge whenever `C0` dominates). The dip lies between the motional (series) resonance and
//! the parallel resonance, moved by an amount that depends on `C0`, the coupling and the damping;
//! a calibration on the same unit absorbs the bias only while those stay as they were during
//! calibration. The method gives no quality factor.
//!
//! Its uncertainty comes from a parametric bootstrap: a weighted parabola through the top 3 % of
//! the dip stands for the noise-free curve (the dip is the motional susceptance's extremum, a
//! skewed peak: wider windows fit a flatter parabola and over-state σ up to 2×),
//! [`BOOTSTRAP`] replicates add each point's own noise to it, and the spread of their
//! three-point vertices is the reported σ. With the paper's 1 Hz
//! steps across a 23 Hz wide dip the maximum lands on different points from reading to reading,
//! which propagating the three points' noise through one vertex misses (it under-stated the
//! scatter 2–3× in the paper's noise).

use super::{screen, Estimate};
use crate::engine::sweep::SweepPoint;
use crate::linalg::Lsq3;
use crate::status::Failure;
use crate::units::Hz;

/// Estimate the resonance as the `|Z|` dip.
pub fn estimate(points: &[SweepPoint]) -> Result<Estimate, Failure> {
    screen(points)?;
    let n = points.len();
    let (f_a, y_a) = (points[0].freq.0 as f64, points[0].magnitude_s() as f64);
    let (f_b, y_b) = (
        points[n - 1].freq.0 as f64,
        points[n - 1].magnitude_s() as f64,
    );
    let span = f_b - f_a;
    if !(span > 0.0) || !y_a.is_finite() || !y_b.is_finite() {
        return Err(Failure::NoResonance);
    }
    let d = |i: usize| {
        let p = &points[i];
        let t = (p.freq.0 as f64 - f_a) / span;
        p.magnitude_s() as f64 - (y_a + t * (y_b - y_a))
    };
    let mut imax = 0;
    let mut best = f64::NEG_INFINITY;
    for i in 0..n {
        let v = d(i);
        if !v.is_finite() {
            return Err(Failure::NoResonance);
        }
        if v > best {
            best = v;
            imax = i;
        }
    }
    if imax == 0 || imax == n - 1 {
        return Err(Failure::OutOfBand);
    }
    let (ym, y0, yp) = (d(imax - 1), d(imax), d(imax + 1));
    let s = |i: usize| points[i].sigma_s as f64;
    if !(y0 > 5.0 * s(imax)) {
        return Err(Failure::NoResonance);
    }
    // Parabola through the three detrended |Y| values; vertex offset in steps.
    let curv = ym - 2.0 * y0 + yp;
    let num = ym - yp;
    if !(curv < 0.0) {
        return Err(Failure::NoResonance);
    }
    let delta = num / (2.0 * curv);
    let step = 0.5 * (points[imax + 1].freq.0 - points[imax - 1].freq.0) as f64;
    let f0 = points[imax].freq.0 as f64 + delta * step;
    let dm = (curv - num) / (2.0 * curv * curv);
    let dp = (-curv - num) / (2.0 * curv * curv);
    let d0 = num / (curv * curv);
    let sq = |v: f64| v * v;
    let var = sq(dm * s(imax - 1)) + sq(d0 * s(imax)) + sq(dp * s(imax + 1));
    let sigma_vertex = step * libm::sqrt(var);
    // The vertex's own propagation misses that the maximum can land on another point when the
    // top of the dip is flat against the noise; a parametric bootstrap does not.
    let freq = |i: usize| points[i].freq.0 as f64;
    let sigma = bootstrap_sigma(&d, &s, &freq, n, imax, y0).unwrap_or(sigma_vertex);
    // A vertex more than a step away from the sampled maximum is not resolved.
    // The acceptance test is the vertex's own (the paper method as it was calibrated).
    if !sigma.is_finite() || !f0.is_finite() || delta.abs() > 1.0 || sigma_vertex > step {
        return Err(Failure::LowSnr);
    }
    // The dip alone has no width to judge contact by: the quality factor comes from the
    // conductance peak of the same points (sweep-G's fit), and a sweep whose conductance peak
    // is not resolved (out of band, no peak) is no reading either — a |Z| dip without a
    // motional peak under it is the static branch's curvature, not a resonance.
    let peak = super::conductance::estimate(points)?;
    // Settled points scattering about the resonance beyond their own σ: a tone (mains hum)
    // that a three-point vertex would follow off the dip ([`super::interference::misfit`],
    // as the fit method checks its refine points).
    let q = peak.q.map_or(f64::NAN, f64::from);
    super::interference::misfit(points, peak.resonance.0 as f64, q)?;
    Ok(Estimate {
        resonance: Hz(f0 as f32),
        sigma: Hz(sigma as f32),
        q: peak.q,
        q_sigma: peak.q_sigma,
        points_used: 3,
    })
}

/// Replicates of the bootstrap: their spread is known to ±7 % (`1/sqrt(2·99)`). Each reading
/// draws its own replicates (the generator is seeded from the dip's top value), so that error
/// averages out over readings instead of repeating in every one: with 40 replicates drawn the
/// same for every sweep of one length, the paper scene's reported σ came out at 1/1.6 of the
/// scatter for one generator's draws. Cost on the target: `docs/firmware.md` (under the
/// 100 ms bound of a single call).
pub const BOOTSTRAP: usize = 100;
/// Most points of the dip's top that the bootstrap's parabola takes.
const TOP_MAX: usize = 48;

/// Spread of the three-point vertex over [`BOOTSTRAP`] replicates of the dip: the weighted
/// parabola through the points within the top 3 % of the dip (at least `imax ± 2`) plus each
/// point's noise (σ from `sigma`), the other points as measured. `None` when the parabola
/// cannot be fitted or fewer than half the replicates give a vertex.
fn bootstrap_sigma(
    d: &impl Fn(usize) -> f64,
    sigma: &impl Fn(usize) -> f64,
    freq: &impl Fn(usize) -> f64,
    n: usize,
    imax: usize,
    y0: f64,
) -> Option<f64> {
    let (mut lo, mut hi) = (imax, imax);
    while lo > 0 && d(lo - 1) >= 0.97 * y0 && imax - lo < TOP_MAX / 2 - 1 {
        lo -= 1;
    }
    while hi + 1 < n && d(hi + 1) >= 0.97 * y0 && hi - imax < TOP_MAX / 2 - 1 {
        hi += 1;
    }
    lo = lo.min(imax.saturating_sub(2));
    hi = hi.max((imax + 2).min(n - 1));
    let fc = freq(imax);
    let mut l = Lsq3::default();
    for i in lo..=hi {
        let u = freq(i) - fc;
        l.add(
            [1.0, u, u * u],
            d(i),
            1.0 / (sigma(i) * sigma(i)).max(1e-60),
        );
    }
    let p = l.solve()?.p;
    let mut rng = probe_rng::Rng::new(y0.to_bits() ^ n as u64);
    let mut top = [0.0f64; TOP_MAX];
    let (mut k, mut sum, mut sum2) = (0u32, 0.0, 0.0);
    for _ in 0..BOOTSTRAP {
        for (j, t) in top.iter_mut().enumerate().take(hi - lo + 1) {
            let u = freq(lo + j) - fc;
            *t = p[0] + p[1] * u + p[2] * u * u + sigma(lo + j) * rng.normal();
        }
        let value = |i: usize| {
            if (lo..=hi).contains(&i) {
                top[i - lo]
            } else {
                d(i)
            }
        };
        let mut best = (0, f64::NEG_INFINITY);
        for i in 0..n {
            let v = value(i);
            if v > best.1 {
                best = (i, v);
            }
        }
        let i = best.0;
        if i == 0 || i + 1 >= n {
            continue;
        }
        let (ym, y0, yp) = (value(i - 1), value(i), value(i + 1));
        let curv = ym - 2.0 * y0 + yp;
        let delta = (ym - yp) / (2.0 * curv);
        if !(curv < 0.0) || !(delta.abs() <= 1.0) {
            continue;
        }
        let f = freq(i) + delta * 0.5 * (freq(i + 1) - freq(i - 1));
        k += 1;
        sum += f - fc;
        sum2 += (f - fc) * (f - fc);
    }
    if (k as usize) < BOOTSTRAP / 2 {
        return None;
    }
    let mean = sum / k as f64;
    let var = (sum2 / k as f64 - mean * mean).max(0.0) * k as f64 / (k as f64 - 1.0);
    Some(libm::sqrt(var))
}
