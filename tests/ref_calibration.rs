//! `PowerLaw::invert` against an independent `f64` reference written here: the modulus by
//! bisection of `f = a + b E^c` (with `f64::powf`, not the crate's `pow`), its sensitivities by
//! central finite differences of that bisection, the combined uncertainty by the GUM sum of
//! those sensitivities over `sigma_f`, the curve misfit and the parameter covariance, and that
//! linear propagation itself by Monte Carlo through the bisection. The range checks against the
//! reference modulus at the f32 neighbours of the asymptote and of the span's ends.

mod reference;
use pzt_probe::unit::calibration::Source;
use pzt_probe::{Failure, Hz, PowerLaw};
use reference::modulus_by_bisection;

/// `u = 2^-24`: the relative rounding of a value to the nearest `f32` (the result's type).
const F32_ROUND: f64 = 1.0 / 16_777_216.0;

/// Sensitivities `dE/d(f, a, b, c)` by central differences of the bisection. Steps: 1e-5 of
/// `a − f` for `f` and `a` (E varies as `(a − f)^(1/c)`), 1e-5 of `|b|` (ln E is linear in
/// ln |b|) and 1e-6 of `|c|`; truncation error below 1e-9 relative, rounding (an ulp of E over
/// the step) ~1e-11.
fn gradient(p: &PowerLaw, f: f64) -> [f64; 4] {
    let e = |x: [f64; 4]| modulus_by_bisection(x[1], x[2], x[3], x[0]).expect("in range");
    let x0 = [f, p.a, p.b, p.c];
    let steps = [
        1e-5 * (p.a - f),
        1e-5 * (p.a - f),
        1e-5 * p.b.abs(),
        1e-6 * p.c.abs(),
    ];
    let mut g = [0.0; 4];
    for i in 0..4 {
        let h = steps[i];
        let (mut up, mut dn) = (x0, x0);
        up[i] += h;
        dn[i] -= h;
        g[i] = (e(up) - e(dn)) / (2.0 * h);
    }
    g
}

/// GUM combined standard uncertainty of the modulus: `(dE/df)^2 (sigma_f^2 + misfit^2) +
/// g^T cov g`, with the finite-difference sensitivities.
fn reference_sigma(p: &PowerLaw, f: f64, sigma_f: f64) -> (f64, f64) {
    let g = gradient(p, f);
    let repeat = g[0].abs() * sigma_f;
    let mut var = g[0] * g[0] * (sigma_f * sigma_f + p.model_sigma_hz * p.model_sigma_hz);
    for i in 0..3 {
        for j in 0..3 {
            var += g[i + 1] * p.cov[i][j] * g[j + 1];
        }
    }
    (var.sqrt(), repeat)
}

/// A covariance of `(a, b, c)` chosen here (not from the crate's fit): standard deviations
/// 0.3 Hz, 120 Hz kPa^-c, 0.012, with the strong correlations a saturating fit has
/// (`a` with `b` −0.9, `a` with `c` −0.95, `b` with `c` +0.8); built as `L L^T` so that it
/// is positive definite.
fn hand_covariance() -> [[f64; 3]; 3] {
    let sd = [0.3, 120.0, 0.012];
    let r = [[1.0, -0.9, -0.95], [-0.9, 1.0, 0.8], [-0.95, 0.8, 1.0]];
    // Cholesky of the correlation matrix (asserting it is positive definite).
    let mut l = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = r[i][i] - s;
                assert!(d > 0.0, "correlation matrix not positive definite");
                l[i][j] = d.sqrt();
            } else {
                l[i][j] = (r[i][j] - s) / l[j][j];
            }
        }
    }
    let mut cov = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let rij: f64 = (0..3).map(|k| l[i][k] * l[j][k]).sum();
            cov[i][j] = rij * sd[i] * sd[j];
        }
    }
    cov
}

/// Paper 003's experimental curve with the hand covariance and a misfit of 0.2 Hz, over
/// 150–2700 kPa.
fn law_with_covariance() -> PowerLaw {
    PowerLaw {
        a: 266.6,
        b: -2305.0,
        c: -0.7243,
        cov: hand_covariance(),
        model_sigma_hz: 0.2,
        min_kpa: 150.0,
        max_kpa: 2700.0,
        source: Source::Fitted,
    }
}

/// The `f32` `n` steps of one ulp above (`n > 0`) or below `x` (positive `x`).
fn f32_step(x: f32, n: i32) -> f32 {
    f32::from_bits((x.to_bits() as i64 + n as i64) as u32)
}

#[test]
fn modulus_matches_bisection() {
    let mut worst = 0.0f64;
    for p in [
        PowerLaw::paper_experiment(),
        PowerLaw::paper_simulation(),
        law_with_covariance(),
    ] {
        // 400 frequencies evenly over the calibrated span's frequencies.
        let (f_lo, f_hi) = (p.frequency(p.min_kpa), p.frequency(p.max_kpa));
        for k in 0..=400 {
            let f = (f_lo + (f_hi - f_lo) * (0.001 + 0.998 * k as f64 / 400.0)) as f32;
            let m = p.invert(Hz(f), Hz(0.0)).expect("inside the span");
            let e = modulus_by_bisection(p.a, p.b, p.c, f as f64).unwrap();
            let rel = (m.value.0 as f64 - e).abs() / e;
            worst = worst.max(rel / F32_ROUND);
            // The reading is the exact inverse of its (f32) frequency, rounded once to f32;
            // 1e-12 covers pow and the bisection.
            assert!(
                rel <= F32_ROUND + 1e-12,
                "{:?} f {f}: {} vs {e} kPa ({rel:e})",
                p.source,
                m.value.0
            );
        }
    }
    println!("worst |E - E_ref| / E: {worst:.3} x 2^-24");
}

#[test]
fn combined_sigma_matches_finite_difference_propagation() {
    let mut worst = 0.0f64;
    for p in [PowerLaw::paper_experiment(), law_with_covariance()] {
        for e_true in [160.0, 279.0, 500.0, 1146.0, 2465.0] {
            for sigma_f in [0.0f32, 0.05, 0.5] {
                let f = p.frequency(e_true) as f32;
                let m = p.invert(Hz(f), Hz(sigma_f)).unwrap();
                let (sigma, repeat) = reference_sigma(&p, f as f64, sigma_f as f64);
                let rel = (m.sigma.0 as f64 / sigma - 1.0).abs();
                worst = worst.max(rel);
                // The f32 rounding of the result (2^-24 = 6.0e-8) plus the finite
                // differences' error (< 1e-9); measured worst 5.0e-8.
                assert!(
                    rel <= F32_ROUND + 1e-9,
                    "{:?} {e_true} kPa ± {sigma_f} Hz: sigma {} vs {sigma} ({rel:e})",
                    p.source,
                    m.sigma.0
                );
                if sigma_f == 0.0 {
                    assert_eq!(m.sigma_repeat.0, 0.0);
                } else {
                    let rel = (m.sigma_repeat.0 as f64 / repeat - 1.0).abs();
                    worst = worst.max(rel);
                    assert!(
                        rel <= F32_ROUND + 1e-9,
                        "repeat {} vs {repeat}",
                        m.sigma_repeat.0
                    );
                }
            }
        }
    }
    println!("worst relative sigma error: {worst:e}");
}

#[test]
fn linear_propagation_matches_monte_carlo() {
    // Draw (a, b, c) from N(law, cov) through the Cholesky factor, the frequency from
    // N(f, sigma_f^2 + misfit^2), invert each draw by bisection and compare the spread of the
    // moduli with the combined sigma that `invert` reports.
    const N: usize = 40_000;
    let p = PowerLaw {
        cov: {
            // A quarter of the hand covariance's standard deviations: small enough that the
            // curve is linear over the spread.
            let mut c = hand_covariance();
            c.iter_mut().flatten().for_each(|v| *v /= 16.0);
            c
        },
        model_sigma_hz: 0.05,
        ..law_with_covariance()
    };
    let mut l = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            l[i][j] = if i == j {
                (p.cov[i][i] - s).sqrt()
            } else {
                (p.cov[i][j] - s) / l[j][j]
            };
        }
    }
    let mut rng = probe_rng::Rng::new(2024);
    let sigma_f = 0.05f32;
    for e_true in [200.0, 500.0, 1146.0] {
        let f = p.frequency(e_true) as f32;
        let m = p.invert(Hz(f), Hz(sigma_f)).unwrap();
        let sf = ((sigma_f as f64).powi(2) + p.model_sigma_hz.powi(2)).sqrt();
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..N {
            let z = [rng.normal(), rng.normal(), rng.normal()];
            let d: Vec<f64> = (0..3)
                .map(|i| (0..=i).map(|k| l[i][k] * z[k]).sum())
                .collect();
            let fi = f as f64 + sf * rng.normal();
            let e = modulus_by_bisection(p.a + d[0], p.b + d[1], p.c + d[2], fi).unwrap();
            sum += e;
            sum2 += e * e;
        }
        let mean = sum / N as f64;
        let sd = ((sum2 - N as f64 * mean * mean) / (N as f64 - 1.0)).sqrt();
        let ratio = m.sigma.0 as f64 / sd;
        println!(
            "{e_true} kPa: invert sigma {:.3} kPa ({:.2} %), Monte Carlo {sd:.3} kPa, ratio {ratio:.4}",
            m.sigma.0,
            100.0 * m.sigma.0 as f64 / e_true
        );
        // The standard deviation of N normal draws is uncertain by 1/sqrt(2N) = 0.35 %; the
        // curve's curvature over a 2.5 % spread changes it by ~(1/2)((1 + 1/|c|) sigma_E/E)^2
        // = 0.2 %. Tolerance: 4 of the first plus the second, 1.6 % (measured worst 0.4 %).
        assert!((ratio - 1.0).abs() < 0.016, "{e_true} kPa: ratio {ratio}");
    }
}

#[test]
fn range_checks_against_the_reference() {
    for p in [
        PowerLaw::paper_experiment(),
        PowerLaw::paper_simulation(),
        law_with_covariance(),
    ] {
        // At and above the asymptote: no modulus exists.
        let a32 = p.a as f32;
        for f in [a32, f32_step(a32, 1), f32_step(a32, 100), 300.0, 1e6] {
            let f = if (f as f64) < p.a { f32_step(f, 1) } else { f };
            assert!(modulus_by_bisection(p.a, p.b, p.c, f as f64).is_none());
            assert_eq!(p.invert(Hz(f), Hz(0.1)), Err(Failure::AboveRange), "{f}");
        }
        // Just below the asymptote the modulus exists but is far above the span.
        let below = f32_step(a32, -1);
        let below = if below as f64 >= p.a {
            f32_step(below, -1)
        } else {
            below
        };
        let e = modulus_by_bisection(p.a, p.b, p.c, below as f64).unwrap();
        assert!(e > p.max_kpa);
        assert_eq!(p.invert(Hz(below), Hz(0.1)), Err(Failure::AboveRange));
        // The span's ends: the f32 frequencies within 20 ulps of f(max_kpa) and f(min_kpa) are
        // classified by the reference modulus (one f32 ulp there moves E by ~6e-6 relative,
        // far beyond any rounding, so every case is unambiguous).
        for (end, beyond) in [
            (p.max_kpa, Failure::AboveRange),
            (p.min_kpa, Failure::BelowRange),
        ] {
            let f_end = p.frequency(end) as f32;
            let (mut ok, mut out) = (0, 0);
            for n in -20..=20 {
                let f = f32_step(f_end, n);
                let e = modulus_by_bisection(p.a, p.b, p.c, f as f64).unwrap();
                let r = p.invert(Hz(f), Hz(0.1));
                if (p.min_kpa..=p.max_kpa).contains(&e) {
                    let m = r.unwrap_or_else(|x| panic!("{f} Hz = {e} kPa: {x:?}"));
                    assert!((m.value.0 as f64 / e - 1.0).abs() <= F32_ROUND + 1e-12);
                    ok += 1;
                } else {
                    assert_eq!(r, Err(beyond), "{f} Hz = {e} kPa");
                    out += 1;
                }
            }
            assert!(ok >= 15 && out >= 15, "{ok} in, {out} out at {end} kPa");
        }
        // Far below: softer than the span, down to frequencies with no modulus at all.
        for f in [100.0f32, 0.0, -5.0, -1e6] {
            assert_eq!(p.invert(Hz(f), Hz(0.1)), Err(Failure::BelowRange), "{f}");
        }
        // Bad input.
        for (f, s) in [
            (f32::NAN, 0.1),
            (f32::INFINITY, 0.1),
            (230.0, -0.1),
            (230.0, f32::NAN),
        ] {
            assert_eq!(p.invert(Hz(f), Hz(s)), Err(Failure::BadSettings));
        }
    }
}
