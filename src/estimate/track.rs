//! What a continuous tracker carries from segment to segment: a Kalman filter over the
//! resonance and the quality factor `(f0, Q)`, fed with each segment's fit
//! (its estimate and the `(JᵀWJ)⁻¹` covariance of `f0` and `Q`,
//! [`crate::estimate::resonator::HoldFit`]) as the measurement.
//!
//! **Why.** A segment driven `±d` half-linewidths off its resonance measures the detuning
//! through the steady state's phase, `φ = −atan(Q u)`: its `f0` follows its `Q` with slope
//! `∂f0/∂Q = ±d f0/(2Q²)`, the sign of the offset, and each segment's `Q` rests on the first few
//! `τ` of its transient. Alone, a segment's `f0` error is `offset · δQ/Q` plus its noise, and
//! the first term does not shrink with the segment's length. `Q` changes slowly; pooled over
//! segments it is known far better than one segment measures it, and the update moves each
//! segment's `f0` by `cov(f0, Q)/var(Q)` times the pooled correction of its `Q` — the
//! correlated part of its error removed. The resonance is pooled too, as far as the process
//! model lets it.
//!
//! **Process model** ([`Process`]): between two measurements `dt` apart, `f0` and `Q` each take
//! an independent random step of standard deviation `rate · dt` (`f0` in Hz/s, `Q` relative,
//! per s): a steady drift at that rate moves them by one standard deviation a step. Faster
//! changes — a step in stiffness, a lift-off, a new contact — are caught by the **innovation
//! gate**: when the measurement lies further than [`Process::gate`] (χ² of two degrees of
//! freedom) from the prediction, the filter restarts from the measurement alone.
//!
//! The state is the estimate `x` and its covariance `P`; an empty filter takes the first
//! measurement as it is. The measurement is the state itself (`H = I`), so one update needs one
//! inverse, of the innovation's covariance `S = P + R`: the gate `νᵀ S⁻¹ ν`, the gain
//! `K = P S⁻¹`, `x + K ν`, and the new covariance `P S⁻¹ R` — `(P⁻¹ + R⁻¹)⁻¹` without its
//! three inverses and without the cancellation of `P − K P`. Every operation is a fixed number of
//! operations on 2 × 2 matrices; no input panics (a singular or non-finite matrix restarts the
//! filter or is refused).
//!
//! **Precision.** The estimate `x` and the times stay `f64` (`f32` would round a resonance near
//! 240 Hz to 1.5e-5 Hz, a part of its σ that pooling would accumulate); the covariances, the
//! gain and the innovation — differences from the prediction, a few σ — are `f32` (the
//! Cortex-M4F's FPU; `f64` is emulated): their relative precision, 1e-7 over the 2 × 2
//! algebra's few roundings, moves the estimate by a small fraction of its σ
//! (`matches_a_covariance_form_reference` and `f32_agrees_with_f64_over_the_range` hold it to
//! an `f64` filter).

/// A 2 × 2 symmetric matrix `[[a, b], [b, c]]` over `(f0, Q)`, in `f32` (see the module's
/// "Precision").
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sym2 {
    /// `(f0, f0)` element.
    pub a: f32,
    /// `(f0, Q)` element.
    pub b: f32,
    /// `(Q, Q)` element.
    pub c: f32,
}

impl Sym2 {
    /// The inverse of a positive-definite matrix; `None` otherwise (or non-finite).
    pub fn inverse(&self) -> Option<Self> {
        let det = self.a * self.c - self.b * self.b;
        let ok = self.a > 0.0 && self.c > 0.0 && det > 0.0 && det.is_finite();
        ok.then(|| Self {
            a: self.c / det,
            b: -self.b / det,
            c: self.a / det,
        })
        .filter(|m| m.a.is_finite() && m.b.is_finite() && m.c.is_finite())
    }

    /// True for a finite positive-definite matrix.
    pub fn is_positive_definite(&self) -> bool {
        let det = self.a * self.c - self.b * self.b;
        self.a > 0.0 && self.c > 0.0 && det > 0.0 && det.is_finite() && self.b.is_finite()
    }

    fn add(&self, o: &Self) -> Self {
        Self {
            a: self.a + o.a,
            b: self.b + o.b,
            c: self.c + o.c,
        }
    }

    /// `M v`.
    pub fn mul(&self, v: [f32; 2]) -> [f32; 2] {
        [self.a * v[0] + self.b * v[1], self.b * v[0] + self.c * v[1]]
    }

    /// `vᵀ M v`.
    fn quad(&self, v: [f32; 2]) -> f32 {
        let m = self.mul(v);
        v[0] * m[0] + v[1] * m[1]
    }
}

/// One measurement of `(f0, Q)`: a segment's fit, its covariance, its time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Resonance, Hz.
    pub f0: f64,
    /// Quality factor.
    pub q: f64,
    /// Covariance of `(f0, Q)`: Hz², Hz, 1.
    pub cov: Sym2,
    /// Time of the measurement (the segment's end), s.
    pub t: f64,
}

/// How fast the resonance and `Q` may move between measurements, and the innovation gate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Process {
    /// How fast `f0` may move, Hz/s: a random step of `rate · dt` standard deviation.
    pub f0_rate: f64,
    /// How fast `Q` may move, as a fraction of it per s.
    pub q_rate: f64,
    /// Innovation gate: χ² with two degrees of freedom of the measurement against the
    /// prediction above which the filter restarts from the measurement.
    pub gate: f64,
}

/// What an update did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Update {
    /// The measurement was pooled with what the filter knew.
    Pooled,
    /// The filter restarted from the measurement alone (no information yet, or the innovation
    /// failed the gate: a real change).
    Restarted,
    /// The measurement was not usable (a covariance that is not positive definite, or a value
    /// that is not finite); the filter is unchanged.
    Refused,
}

/// The filter's state: the estimate `x` over `(f0, Q)` and its covariance `P` (when it has one),
/// the time of the last measurement.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Track {
    x: [f64; 2],
    p: Sym2,
    /// False while the filter knows nothing (`x`, `P` unset).
    known: bool,
    t: f64,
    /// The last update's gain on the resonance's own innovation (`K[f0][f0]`, 0–1; 1 after a
    /// restart) and the time it stepped over, s.
    gain: f32,
    dt: f64,
}

/// The filter's estimate: `(f0, Q)` and their covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate2 {
    /// Resonance, Hz.
    pub f0: f64,
    /// Quality factor.
    pub q: f64,
    /// Covariance of `(f0, Q)`.
    pub cov: Sym2,
}

impl Track {
    /// A filter that knows nothing.
    pub const EMPTY: Self = Self {
        x: [0.0, 0.0],
        p: Sym2 {
            a: 0.0,
            b: 0.0,
            c: 0.0,
        },
        known: false,
        t: 0.0,
        gain: 1.0,
        dt: 0.0,
    };

    /// Forget everything (the next measurement is taken as it is).
    pub fn clear(&mut self) {
        *self = Self::EMPTY;
    }

    /// The estimate, when the filter has one.
    pub fn estimate(&self) -> Option<Estimate2> {
        self.known.then_some(Estimate2 {
            f0: self.x[0],
            q: self.x[1],
            cov: self.p,
        })
    }

    /// The estimate predicted to time `t` (s) under `process`: the same values, the covariance
    /// grown by the random steps over `t` less the last measurement's time.
    pub fn predicted(&self, t: f64, process: &Process) -> Option<Estimate2> {
        let e = self.estimate()?;
        let dt = (t - self.t).max(0.0);
        let sf = (process.f0_rate * dt) as f32;
        let sq = (process.q_rate * e.q * dt) as f32;
        Some(Estimate2 {
            cov: e.cov.add(&Sym2 {
                a: sf * sf,
                b: 0.0,
                c: sq * sq,
            }),
            ..e
        })
    }

    /// How far behind a steady drift of `rate` (Hz/s) the estimate settles when every update
    /// is like the last: the random walk's filter follows a ramp with the lag
    /// `rate dt (1 − K)/K` (`K` the gain on the resonance's innovation, `dt` the step), which
    /// its covariance does not hold (Hz; 0 after a restart).
    pub fn drift_lag(&self, rate: f64) -> f64 {
        let k = self.gain as f64;
        if k > 0.0 && k < 1.0 && self.dt.is_finite() {
            libm::fabs(rate) * self.dt * (1.0 - k) / k
        } else {
            0.0
        }
    }

    /// Take one measurement: predict to its time, gate its innovation, pool it (or restart
    /// from it).
    pub fn update(&mut self, m: &Measurement, process: &Process) -> Update {
        let finite = m.f0.is_finite() && m.q.is_finite() && m.t.is_finite();
        let r = m.cov;
        if !finite || !r.is_positive_definite() {
            return Update::Refused;
        }
        let z = [m.f0, m.q];
        let restart = |s: &mut Self| {
            *s = Self {
                x: z,
                p: r,
                known: true,
                t: m.t,
                gain: 1.0,
                dt: 0.0,
            };
            Update::Restarted
        };
        let Some(pred) = self.predicted(m.t, process) else {
            return restart(self);
        };
        // The innovation, a few σ of the prediction: `f32` from here.
        let nu = [(z[0] - pred.f0) as f32, (z[1] - pred.q) as f32];
        let s_inv = pred.cov.add(&r).inverse();
        let d2 = s_inv.map(|s| s.quad(nu) as f64);
        let Some(s_inv) = s_inv.filter(|_| d2.is_some_and(|d| d <= process.gate)) else {
            return restart(self);
        };
        // K = P S⁻¹ (not symmetric), by rows.
        let (p, s) = (pred.cov, s_inv);
        let k = [s.mul([p.a, p.b]), s.mul([p.b, p.c])];
        // x + K ν and P S⁻¹ R = K R (symmetric: its upper triangle).
        let cov = Sym2 {
            a: k[0][0] * r.a + k[0][1] * r.b,
            b: k[0][0] * r.b + k[0][1] * r.c,
            c: k[1][0] * r.b + k[1][1] * r.c,
        };
        let x = [
            pred.f0 + (k[0][0] * nu[0] + k[0][1] * nu[1]) as f64,
            pred.q + (k[1][0] * nu[0] + k[1][1] * nu[1]) as f64,
        ];
        if !(x[0].is_finite() && x[1].is_finite() && cov.is_positive_definite()) {
            return restart(self);
        }
        self.gain = k[0][0];
        self.dt = (m.t - self.t).max(0.0);
        self.x = x;
        self.p = cov;
        self.t = m.t;
        Update::Pooled
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use probe_rng::Rng as ProbeRng;

    const PROCESS: Process = Process {
        f0_rate: 0.3,
        q_rate: 0.2,
        gate: 13.8,
    };

    /// An f64 reference Kalman filter in covariance form (`P`, `x`; `K = P Hᵀ (H P Hᵀ + R)⁻¹`
    /// with `H = I`, Joseph's form for `P`): written apart from the filter under test.
    struct Reference {
        x: [f64; 2],
        p: [[f64; 2]; 2],
        t: f64,
    }

    #[allow(clippy::needless_range_loop)] // 2 × 2 index arithmetic reads best as indices
    impl Reference {
        fn step(&mut self, m: &Measurement, pr: &Process) {
            let dt = m.t - self.t;
            self.p[0][0] += (pr.f0_rate * dt).powi(2);
            self.p[1][1] += (pr.q_rate * self.x[1] * dt).powi(2);
            let c = m.cov;
            let r = [[c.a as f64, c.b as f64], [c.b as f64, c.c as f64]];
            let s = [
                [self.p[0][0] + r[0][0], self.p[0][1] + r[0][1]],
                [self.p[1][0] + r[1][0], self.p[1][1] + r[1][1]],
            ];
            let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
            let si = [
                [s[1][1] / det, -s[0][1] / det],
                [-s[1][0] / det, s[0][0] / det],
            ];
            let mut k = [[0.0; 2]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    k[i][j] = (0..2).map(|l| self.p[i][l] * si[l][j]).sum();
                }
            }
            let nu = [m.f0 - self.x[0], m.q - self.x[1]];
            for i in 0..2 {
                self.x[i] += k[i][0] * nu[0] + k[i][1] * nu[1];
            }
            // Joseph: (I − K) P (I − K)ᵀ + K R Kᵀ.
            let ik = [[1.0 - k[0][0], -k[0][1]], [-k[1][0], 1.0 - k[1][1]]];
            let mut np = [[0.0; 2]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    for a in 0..2 {
                        for b in 0..2 {
                            np[i][j] +=
                                ik[i][a] * self.p[a][b] * ik[j][b] + k[i][a] * r[a][b] * k[j][b];
                        }
                    }
                }
            }
            self.p = np;
            self.t = m.t;
        }
    }

    fn gauss2(rng: &mut ProbeRng, cov: &Sym2) -> [f64; 2] {
        // Cholesky of the 2 × 2 covariance.
        let (a, b, c) = (cov.a as f64, cov.b as f64, cov.c as f64);
        let l00 = a.sqrt();
        let l10 = b / l00;
        let l11 = (c - l10 * l10).sqrt();
        let (u, v) = (rng.normal(), rng.normal());
        [l00 * u, l10 * u + l11 * v]
    }

    /// The filter (`f32` covariances) against the `f64` covariance-form reference (Joseph's
    /// form) over 200 measurements of standard uncertainties `sf` (Hz) and `sq`, correlated by
    /// `rho` with its sign alternating (as the tracker's offset drive makes it), under
    /// `process` (whose gate must pass every measurement: the reference has none). The worst
    /// difference over the steps: of `f0` and of `Q` in the reference's standard
    /// uncertainties, and of the covariance's elements in units of `sqrt(P_ii P_jj)`.
    #[allow(clippy::needless_range_loop)] // 2 × 2 index arithmetic reads best as indices
    fn worst_against_reference(
        sf: f64,
        sq: f64,
        rho: f64,
        process: &Process,
        seed: u64,
    ) -> [f64; 3] {
        let mut rng = ProbeRng::new(seed);
        let mut t = Track::EMPTY;
        let mut r = Reference {
            x: [0.0; 2],
            p: [[0.0; 2]; 2],
            t: 0.0,
        };
        let mut worst = [0.0f64; 3];
        for k in 0..200 {
            let side = if k % 2 == 0 { 1.0 } else { -1.0 };
            let cov = Sym2 {
                a: (sf * sf) as f32,
                b: (side * rho * sf * sq) as f32,
                c: (sq * sq) as f32,
            };
            let n = gauss2(&mut rng, &cov);
            let m = Measurement {
                f0: 238.0 + n[0],
                q: 10.0 + n[1],
                cov,
                t: 0.038 * k as f64,
            };
            let u = t.update(&m, process);
            if k == 0 {
                assert_eq!(u, Update::Restarted);
                r.x = [m.f0, m.q];
                r.p = [[cov.a as f64, cov.b as f64], [cov.b as f64, cov.c as f64]];
                r.t = m.t;
            } else {
                assert_eq!(u, Update::Pooled, "{k}");
                r.step(&m, process);
            }
            let e = t.estimate().unwrap();
            let got = [[e.cov.a, e.cov.b], [e.cov.b, e.cov.c]];
            worst[0] = worst[0].max((e.f0 - r.x[0]).abs() / r.p[0][0].sqrt());
            worst[1] = worst[1].max((e.q - r.x[1]).abs() / r.p[1][1].sqrt());
            for i in 0..2 {
                for j in 0..2 {
                    let unit = (r.p[i][i] * r.p[j][j]).sqrt();
                    worst[2] = worst[2].max((got[i][j] as f64 - r.p[i][j]).abs() / unit);
                }
            }
        }
        worst
    }

    /// The tracker's setting (σ 0.02 Hz and 0.3, correlated 0.85, the default rates and gate):
    /// the estimate within 1e-5 of its σ of the `f64` reference, the covariance within 1e-5.
    #[test]
    fn matches_a_covariance_form_reference() {
        let w = worst_against_reference(0.02, 0.3, 0.85, &PROCESS, 7);
        assert!(w.iter().all(|&e| e < 1e-5), "{w:?}");
    }

    /// `f32` against the `f64` reference over the range the tracker meets: a segment's σ of `f0`
    /// from 1e-4 Hz to 1 Hz and of `Q` from 1e-3 to 3, uncorrelated to correlated 0.99, the
    /// process rates from the settings' least to their most (`TrackerConfig`'s 0.01–100):
    /// within 1e-3 of the estimate's σ and of the covariance, eight times the worst case
    /// measured (the correlated 0.99 cases, where `det = ac − b²` cancels to 2 % of `ac`).
    #[test]
    fn f32_agrees_with_f64_over_the_range() {
        let mut worst = [0.0f64; 3];
        let mut seed = 1;
        for sf in [1e-4, 1e-2, 1.0] {
            for sq in [1e-3, 0.3, 3.0] {
                for rho in [0.0, 0.85, 0.99] {
                    for rate in [0.01, 1.0, 100.0] {
                        let pr = Process {
                            f0_rate: rate,
                            q_rate: rate,
                            gate: f64::INFINITY,
                        };
                        seed += 1;
                        let w = worst_against_reference(sf, sq, rho, &pr, seed);
                        for (a, b) in worst.iter_mut().zip(w) {
                            *a = a.max(b);
                        }
                    }
                }
            }
        }
        assert!(worst.iter().all(|&e| e < 1e-3), "{worst:?}");
    }

    /// The steady state against the closed form: with `f0` measured alone (uncorrelated with `Q`)
    /// at variance `R` every `dt`, and a random step of variance `W = (rate dt)²`, the posterior
    /// variance settles at `P = (−W + sqrt(W² + 4 W R)) / 2` (the fixed point of
    /// `P = (P + W) R / (P + W + R)`); and the estimate's error over 20 000 simulated steps of a
    /// resonance that really walks so scatters by that `P` (within 3 %, the standard error of a
    /// variance of 20 000 correlated errors).
    #[test]
    fn steady_state_error_is_the_closed_forms() {
        let (r, dt) = (4e-4, 0.038);
        let pr = Process {
            f0_rate: 0.3,
            q_rate: 0.0,
            gate: f64::INFINITY,
        };
        let w = (pr.f0_rate * dt).powi(2);
        let p = (-w + (w * w + 4.0 * w * r).sqrt()) / 2.0;
        let mut rng = ProbeRng::new(11);
        let mut t = Track::EMPTY;
        let (mut truth, mut sq, mut n) = (238.0, 0.0, 0);
        for k in 0..20_200 {
            truth += w.sqrt() * rng.normal();
            let m = Measurement {
                f0: truth + r.sqrt() * rng.normal(),
                q: 10.0,
                cov: Sym2 {
                    a: r as f32,
                    b: 0.0,
                    c: 1e-6,
                },
                t: dt * k as f64,
            };
            t.update(&m, &pr);
            let e = t.estimate().unwrap();
            if k >= 200 {
                assert!(
                    (e.cov.a as f64 / p - 1.0).abs() < 1e-6,
                    "{} vs {p}",
                    e.cov.a
                );
                sq += (e.f0 - truth).powi(2);
                n += 1;
            }
        }
        let v = sq / n as f64;
        assert!((v / p - 1.0).abs() < 0.03, "{v} vs {p}");
    }

    /// The correlated part of a measurement's `f0` error goes with the pooled `Q`: measurements
    /// whose `f0` error is `s · δQ` (alternating `s`) and nothing else give, once `Q` is pooled,
    /// an `f0` error far below a single measurement's.
    #[test]
    fn a_pooled_q_removes_the_correlated_part_of_f0() {
        let mut rng = ProbeRng::new(3);
        let pr = Process {
            f0_rate: 0.3,
            q_rate: 0.2,
            gate: 13.8,
        };
        let mut t = Track::EMPTY;
        let (mut single, mut pooled, mut n) = (0.0, 0.0, 0);
        for k in 0..400 {
            let s = if k % 2 == 0 { 1.0 } else { -1.0 };
            // f0 error = 1 Hz per unit of Q error × s, plus a small independent part.
            let dq = 0.3 * rng.normal();
            let df = s * dq + 0.005 * rng.normal();
            let cov = Sym2 {
                a: 0.09 + 0.005f32.powi(2),
                b: s as f32 * 0.09,
                c: 0.09,
            };
            let m = Measurement {
                f0: 238.0 + df,
                q: 10.0 + dq,
                cov,
                t: 0.038 * k as f64,
            };
            assert_ne!(t.update(&m, &pr), Update::Refused);
            if k >= 50 {
                single += df * df;
                pooled += (t.estimate().unwrap().f0 - 238.0).powi(2);
                n += 1;
            }
        }
        let (single, pooled) = ((single / n as f64).sqrt(), (pooled / n as f64).sqrt());
        assert!(pooled < 0.25 * single, "{pooled} vs {single}");
    }

    /// The lag the estimate settles at behind a steady ramp (no noise, measurements on the
    /// ramp) is what [`Track::drift_lag`] states from the last gain.
    #[test]
    fn the_lag_behind_a_ramp_is_stated() {
        let (rate, dt) = (0.3, 0.038);
        let cov = Sym2 {
            a: 4e-4,
            b: 0.0,
            c: 1e-4,
        };
        let mut t = Track::EMPTY;
        let mut lag = 0.0;
        for k in 0..400 {
            let at = dt * k as f64;
            let m = Measurement {
                f0: 238.0 + rate * at,
                q: 10.0,
                cov,
                t: at,
            };
            assert_ne!(t.update(&m, &PROCESS), Update::Refused);
            lag = m.f0 - t.estimate().unwrap().f0;
        }
        let stated = t.drift_lag(rate);
        assert!(
            lag > 0.0 && (stated / lag - 1.0).abs() < 1e-3,
            "{lag} vs {stated}"
        );
    }

    /// A step far outside the prediction restarts the filter from the measurement; one inside
    /// is pooled.
    #[test]
    fn the_gate_restarts_on_a_real_change() {
        let cov = Sym2 {
            a: 4e-4,
            b: 0.0,
            c: 0.01,
        };
        let mut t = Track::EMPTY;
        let at = |f0: f64, k: usize| Measurement {
            f0,
            q: 10.0,
            cov,
            t: 0.038 * k as f64,
        };
        for k in 0..20 {
            t.update(&at(238.0, k), &PROCESS);
        }
        assert_eq!(t.update(&at(238.03, 20), &PROCESS), Update::Pooled);
        assert_eq!(t.update(&at(252.6, 21), &PROCESS), Update::Restarted);
        let e = t.estimate().unwrap();
        assert!(
            (e.f0 - 252.6).abs() < 1e-9 && (e.cov.a / cov.a - 1.0).abs() < 1e-9,
            "{e:?}"
        );
    }

    /// No input panics: non-finite or singular measurements are refused and leave the filter
    /// as it was; an empty filter has no estimate.
    #[test]
    fn bad_measurements_are_refused() {
        let mut t = Track::EMPTY;
        assert!(t.estimate().is_none());
        let good = Measurement {
            f0: 238.0,
            q: 10.0,
            cov: Sym2 {
                a: 4e-4,
                b: 0.0,
                c: 0.01,
            },
            t: 0.0,
        };
        t.update(&good, &PROCESS);
        let before = t;
        for bad in [
            Measurement {
                f0: f64::NAN,
                ..good
            },
            Measurement {
                cov: Sym2 {
                    a: 1.0,
                    b: 2.0,
                    c: 1.0,
                },
                ..good
            },
            Measurement {
                cov: Sym2 {
                    a: f32::INFINITY,
                    b: 0.0,
                    c: 1.0,
                },
                ..good
            },
            Measurement {
                t: f64::NAN,
                ..good
            },
        ] {
            assert_eq!(t.update(&bad, &PROCESS), Update::Refused);
            assert_eq!(t, before);
        }
    }
}
