//! Tests of the contact law: its slopes, χ² terms, validity and limits.
use super::*;

/// A law of the simulated probe's size (free resonance 232.3 Hz) over 100–3000 kPa, exact
/// (no covariance, no misfit), without a reference force.
fn law() -> ContactLaw {
    ContactLaw::exact(232.3, [13.44, 9.26, 4.88], (100.0, 3000.0), 0.0)
}

/// The analytic slopes against central differences of the law in E and in each constant.
/// Steps 1e-6: truncation below 1e-7 of the slope; rounding of the two ~260 Hz values
/// (an ulp, 5.7e-14 Hz, each) over the step 2e-6 is up to 6e-8 Hz per unit.
#[test]
fn slopes_match_central_differences() {
    let (free, p) = (232.3, [13.44, 9.26, 4.88]);
    let k = Constants::<f64>::of(free, &p, 1.0);
    for e in [120.0, 414.0, 2465.0, 20_000.0] {
        let y = libm::cbrt(e);
        let at = k.at_cube_root(y);
        assert!((at.f - frequency_of(free, &p, e, 1.0)).abs() < 1e-10);
        let h = 1e-6 * y;
        let num = (k.at_cube_root(y + h).f - k.at_cube_root(y - h).f) / (2.0 * h);
        assert!(
            (at.df_dy / num - 1.0).abs() < 1e-7,
            "{e}: {} vs {num}",
            at.df_dy
        );
        for i in 0..3 {
            let (mut up, mut dn) = (p, p);
            up[i] += 1e-6;
            dn[i] -= 1e-6;
            let num = (frequency_of(free, &up, e, 1.0) - frequency_of(free, &dn, e, 1.0)) / 2e-6;
            assert!(
                (at.df_dp[i] - num).abs() <= 1e-7 * num.abs() + 6e-8,
                "{e}, {i}: {} vs {num}",
                at.df_dp[i]
            );
        }
    }
}

/// χ² over the terms (one per modulus and force, with the constant `C`) is χ² over the
/// readings, and the normal equations are those of the readings' analytic Jacobian: on
/// readings with repeated and distinct (modulus, force) pairs, to rounding (1e-12 of the
/// sums, or of the sum of the magnitudes of `JᵀW r`'s terms, which cancel).
#[test]
#[allow(clippy::needless_range_loop)] // the normal equations' index arithmetic
fn terms_give_the_readings_chi2() {
    let (free, p, f0) = (232.3, [13.44, 9.26, 4.88], 0.03);
    let data: [RefPoint; 30] = core::array::from_fn(|i| {
        let e = [157.5, 414.0, 2465.0][i % 3];
        let force = if i < 15 {
            [0.03, 0.015][i % 2]
        } else {
            0.03 + 1e-4 * i as f64
        };
        RefPoint {
            modulus_kpa: e,
            resonance_hz: frequency_of(free, &p, e, force / f0) + 0.3 * ((i * 7) % 5) as f64,
            sigma_hz: 0.1 + 0.05 * (i % 4) as f64,
            force_n: force,
        }
    });
    let mut terms = Terms {
        t: [[0.0; 4]; crate::unit::calibration::MAX_REFERENCES],
        len: 0,
        c: 0.0,
        points: 0,
    };
    assert!(terms.fill(data.iter(), f0));
    assert_eq!(terms.points, 30);
    assert_eq!(terms.len, 6 + 15);
    for q in [p, [13.0, 9.0, 5.0], [14.0, 10.0, 4.0]] {
        let k = Constants::with(
            Constants::<f64>::of(free, &q, 1.0).k1,
            libm::exp(q[0]),
            libm::exp(q[1]),
            libm::exp(q[2]),
        );
        let (mut chi2, mut jtr, mut jtj) = (0.0, [0.0; 3], [[0.0; 3]; 3]);
        let mut jtr_abs = [0.0; 3];
        for d in &data {
            let ratio = force_ratio(f0, d.force_n);
            let y = libm::cbrt(d.modulus_kpa);
            let at = Constants::<f64>::of(free, &q, ratio).at_cube_root(y);
            let w = 1.0 / (d.sigma_hz * d.sigma_hz);
            let r = d.resonance_hz - at.f;
            chi2 += w * r * r;
            for a in 0..3 {
                jtr[a] += w * at.df_dp[a] * r;
                jtr_abs[a] += (w * at.df_dp[a] * r).abs();
                for b in 0..3 {
                    jtj[a][b] += w * at.df_dp[a] * at.df_dp[b];
                }
            }
        }
        let got = terms.chi2(&k);
        assert!((got - chi2).abs() <= 1e-12 * chi2, "{got} vs {chi2}");
        let (gjtj, gjtr) = terms.normal(&k);
        for a in 0..3 {
            assert!((gjtr[a] - jtr[a]).abs() <= 1e-12 * jtr_abs[a], "{a}");
            for b in 0..3 {
                assert!(
                    (gjtj[a][b] - jtj[a][b]).abs() <= 1e-12 * jtj[a][b].abs(),
                    "{a} {b}"
                );
            }
        }
    }
}

/// Every constant must be finite, the free resonance positive, the misfit not negative and
/// the span ordered above zero; a law that is not is no curve (`bad_settings`).
#[test]
fn an_invalid_law_reads_nothing() {
    let good = ContactLaw {
        cov: [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-4]],
        model_sigma_hz: 0.1,
        ..law()
    };
    assert!(good.is_valid());
    let f = Hz(good.frequency(400.0) as f32);
    assert!(good.invert(f, Hz(0.01), None).is_ok());
    let bad = [
        ContactLaw {
            free_hz: 0.0,
            ..good
        },
        ContactLaw {
            free_hz: f64::NAN,
            ..good
        },
        ContactLaw {
            p: [13.44, f64::INFINITY, 4.88],
            ..good
        },
        ContactLaw {
            cov: [[f64::NAN, 0.0, 0.0], [0.0; 3], [0.0; 3]],
            ..good
        },
        ContactLaw {
            model_sigma_hz: -0.1,
            ..good
        },
        ContactLaw {
            model_sigma_hz: f64::NAN,
            ..good
        },
        ContactLaw {
            min_kpa: 0.0,
            ..good
        },
        ContactLaw {
            max_kpa: 100.0,
            ..good
        },
        ContactLaw {
            force_n: -0.03,
            ..good
        },
        ContactLaw {
            force_n: f64::NAN,
            ..good
        },
    ];
    for (k, law) in bad.iter().enumerate() {
        assert!(!law.is_valid(), "{k}");
        assert_eq!(
            law.invert(f, Hz(0.01), None),
            Err(Failure::BadSettings),
            "{k}"
        );
    }
}

/// The law at its limits: the free resonance's square plus the coupling at `E → ∞`; below
/// the free resonance and falling towards 0 at small `E` (the co-moving mass dominates).
#[test]
fn limits() {
    let law = law();
    let rigid = libm::sqrt((2.0 * PI * 232.3f64).powi(2) + libm::exp(13.44)) / (2.0 * PI);
    assert!((law.rigid_hz() - rigid).abs() < 1e-9);
    assert!((law.frequency(1e12) - rigid).abs() < 1e-3);
    assert!(law.frequency(1e-3) < 1.0);
    // Rising: every decade from 1 kPa to 1 GPa.
    let mut prev = 0.0;
    for k in 0..7 {
        let f = law.frequency(libm::pow(10.0, k as f64));
        assert!(f > prev, "{f} at 1e{k} kPa");
        prev = f;
    }
    // Inversion is the inverse within the f32 rounding of the resonance (half an ulp of
    // 256 Hz, 7.6e-6 Hz) through the slope.
    for e in [150.0, 414.0, 2465.0] {
        let f = law.frequency(e) as f32;
        let m = law.invert(Hz(f), Hz(0.0), None).unwrap();
        let slope = (law.frequency(e * 1.0001) - law.frequency(e * 0.9999)) / (2e-4 * e);
        let tol = 2.0 * 7.6e-6 / slope;
        assert!((m.value.0 as f64 - e).abs() <= tol + 1e-6 * e, "{e}: {m:?}");
        // With a force and the free resonance moved: the pair as two inversions.
        let force = Some((0.03, 0.001));
        let law = ContactLaw {
            force_n: 0.025,
            ..law
        };
        let (a, b) = law.invert_moved(Hz(f), Hz(0.1), force, 0.4);
        let moved = ContactLaw {
            free_hz: law.free_hz + 0.4,
            ..law
        };
        let (a, b) = (a.unwrap(), b.unwrap().unwrap());
        let x = law.invert(Hz(f), Hz(0.1), force).unwrap();
        assert_eq!(a, x);
        // Started elsewhere, the two roots agree within the f32 law's resolution (a few ulps
        // of the resonance through the slope).
        let y = moved.invert(Hz(f), Hz(0.1), force).unwrap();
        assert!((b.0 - y.value.0).abs() as f64 <= 2.0 * tol, "{b:?} {y:?}");
        assert_eq!(law.invert_moved(Hz(f), Hz(0.1), force, 0.0).1, None);
    }
    assert_eq!(libm::cbrt(SEARCH_KPA.0), SEARCH_CUBE_ROOT.0);
    assert_eq!(libm::cbrt(SEARCH_KPA.1), SEARCH_CUBE_ROOT.1);
    assert_eq!(
        law.invert(Hz(rigid as f32 + 0.1), Hz(0.1), None),
        Err(Failure::AboveRange)
    );
    assert_eq!(
        law.invert(Hz(100.0), Hz(0.1), None),
        Err(Failure::BelowRange)
    );
    assert_eq!(
        law.invert(Hz(f32::NAN), Hz(0.1), None),
        Err(Failure::BadSettings)
    );
}

/// A reading's inversion runs in `f32` ([`ContactLaw::root`]): over the whole span, at the
/// reference force, at half and at twice it, every root solves the `f64` law
/// ([`ContactLaw::frequency_at`], a separate evaluation) to within 8 ulps of the resonance
/// (2.4e-4 Hz at 256 Hz: a thirtieth of the best σ a reading reports, about 0.007 Hz), and its
/// slope (the repeatability's `σ_f dE/df`) is the `f64` law's central difference to 1e-3.
#[test]
fn f32_roots_solve_the_f64_law_within_the_resonances_rounding() {
    let law = ContactLaw {
        force_n: 0.03,
        ..law()
    };
    let mut worst = 0.0f64;
    for force in [None, Some(0.015), Some(0.03), Some(0.06)] {
        let at = |e: f64| law.frequency_at(e, force.unwrap_or(law.force_n));
        for i in 0..=100 {
            let e = law.min_kpa * libm::pow(law.max_kpa / law.min_kpa, i as f64 / 100.0);
            let f = at(e) as f32;
            let Ok(m) = law.invert(Hz(f), Hz(0.01), force.map(|n| (n, 0.0))) else {
                // The span's very ends may round outside it.
                assert!(i == 0 || i == 100, "{e} kPa at {force:?}");
                continue;
            };
            let root = m.value.0 as f64;
            let ulp = (f32::from_bits(f.to_bits() + 1) - f) as f64;
            let residual = (at(root) - f as f64).abs();
            worst = worst.max(residual / ulp);
            assert!(residual <= 8.0 * ulp, "{e} kPa at {force:?}: {residual} Hz");
            let h = 1e-5 * root;
            let de_df = 2.0 * h / (at(root + h) - at(root - h));
            let want = 0.01 * de_df;
            let got = m.sigma_repeat.0 as f64;
            assert!(
                (got / want - 1.0).abs() < 1e-3,
                "{e} kPa: σ {got} vs {want}"
            );
        }
    }
    println!("worst residual {worst:.2} ulps");
    assert!(
        worst > 0.0,
        "the f32 roots are exact: the test sees nothing"
    );
}
