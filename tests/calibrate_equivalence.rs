//! `profile::calibrate` against the values the implementation before the fast contact-law fit
//! gave (tests/data/calibrate_golden.txt, written by this test with `CALIBRATE_GOLDEN_WRITE=1`
//! at commit 0676ed5, the fit with a finite-difference Jacobian and a law evaluated per reading).
//!
//! Six reference sets: the cost image's 100-reference case (A–E × 20 at exactly 30/15/50 mN),
//! the same with measured forces (each reading's force off by up to ±4 %) and noise, 32 moduli
//! scattered by ±30 Hz, the session test's ten, readings off a power law (where the held-out
//! comparison keeps the power law) and readings without a force.
//!
//! Tolerances: the Q model and the spans are the same arithmetic: relative 1e-9. The power law
//! sums its normal equations per modulus instead of per reading (the same sums in another
//! order): its exponent is the golden-section minimum of χ²(c) = Σwf² − a Σwf − b Σwxf, a
//! difference of sums of ~1e8 whose rounding (~1e-8) the flat minimum turns into ~1e-7 of `c`
//! (and of `a`, `b`, which follow it): relative 1e-5 for `a`, `b`, `c`, the misfit, and 1e-4 for
//! the covariance; the curve itself (what a reading inverts) within 1e-4 Hz over the span (7
//! f32 ulps of a 260 Hz reading, 1/2000 of a reference's σ). That is the old implementation's
//! own noise: given the same readings in reverse order (`CALIBRATE_REVERSED=1`), it moved the
//! power law's misfit by 4e-5 of itself (set power-law-30); this implementation moves it by
//! 1.4e-6, `c` by 4e-6, the curve by 3e-5 Hz, the contact law's constants by 2e-8. The contact law's constants are
//! the minimum of the same χ², reached by another path (an analytic Jacobian where the old fit
//! took forward differences of step 1e-6, whose truncation error is about 1e-6 of each slope);
//! both stop when a step lowers χ² by less than 1e-12 of it, so the two minima agree to within
//! the flatness of χ² there: 1e-6 in `ln Ks`, `ln A`, `ln B`, and the misfit (a function of
//! the minimum's residuals) to 1e-6 relative. The covariance is `(JᵀWJ)⁻¹` with the two
//! Jacobians: relative 1e-4 (the forward differences' 1e-6 error per slope, amplified by the
//! conditioning of `JᵀWJ`). The held-out decision (contact law kept or not) must be the same.

use pzt_probe::unit::calibration::PowerLaw;
use pzt_probe::unit::contact_law::ContactLaw;
use pzt_probe::unit::profile::{calibrate, Calibration, Reference};
use pzt_probe::units::Hz;
use pzt_probe::AirReference;
use pzt_probe::Farads;
use pzt_probe::Siemens;

const FREE_HZ: f32 = 232.3;

fn truth() -> ContactLaw {
    ContactLaw::exact(FREE_HZ as f64, [13.44, 9.26, 4.88], (100.0, 3000.0), 0.030)
}

/// A small deterministic generator in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

const PHANTOMS: [f64; 5] = [157.5, 279.0, 414.0, 1146.0, 2465.0];
const FORCES: [f64; 3] = [0.030, 0.015, 0.050];

fn reference(e: f64, f: f64, sigma: f64, force: f64) -> Reference {
    Reference {
        modulus_kpa: e,
        resonance_hz: f,
        sigma_hz: sigma,
        q: 12.0 - 1.5 * libm::log(e / 400.0)
            + if force > 0.0 {
                2.0 * libm::log(force / 0.03)
            } else {
                0.0
            },
        force_n: force,
    }
}

fn sets() -> Vec<(&'static str, Vec<Reference>)> {
    let law = truth();
    let mut rng = Lcg(7);
    let mut out = Vec::new();
    // `per` references on each of A–E in turn, at the exact calibration forces in turn,
    // alternately 0.3 Hz above and below the law.
    let exact = |per: usize| -> Vec<Reference> {
        (0..PHANTOMS.len() * per)
            .map(|i| {
                let (e, force) = (PHANTOMS[i / per], FORCES[i % 3]);
                let w = if i % 2 == 0 { 0.3 } else { -0.3 };
                reference(e, law.frequency_at(e, force) + w, 0.2, force)
            })
            .collect()
    };
    // The cost image's 100-reference case: A–E × 20, exact calibration forces, ±0.3 Hz.
    out.push(("cost-100", exact(20)));
    // Measured forces and noise.
    out.push((
        "measured-100",
        (0..100)
            .map(|i| {
                let e = PHANTOMS[i / 20];
                let force = FORCES[i % 3] * (1.0 + 0.04 * rng.next());
                let f = law.frequency_at(e, force) + 0.4 * rng.next();
                reference(e, f, 0.15 + 0.1 * rng.next().abs(), force)
            })
            .collect(),
    ));
    // 32 moduli, every third reading 30 Hz off.
    out.push((
        "scattered-32",
        (0..32)
            .map(|i| {
                let e = 100.0 * libm::pow(30.0, i as f64 / 31.0);
                let force = FORCES[i % 3];
                let w = if i % 2 == 0 { 0.3 } else { -0.3 };
                let off = if i % 3 == 0 {
                    if i % 2 == 0 {
                        30.0
                    } else {
                        -30.0
                    }
                } else {
                    0.0
                };
                reference(e, law.frequency_at(e, force) + w + off, 0.2, force)
            })
            .collect(),
    ));
    // The session test's ten.
    out.push(("ten", exact(2)));
    // Off a power law at one force: the power law should be kept.
    let p = PowerLaw::paper_simulation();
    out.push((
        "power-law-30",
        (0..40)
            .map(|i| {
                let e = PHANTOMS[i % 5] * (1.0 + 0.3 * (i / 5) as f64);
                let force = 0.030 * (1.0 + 0.02 * rng.next());
                reference(e, p.frequency(e) + 0.05 * rng.next(), 0.05, force)
            })
            .collect(),
    ));
    // No force measured.
    out.push((
        "no-force",
        (0..25)
            .map(|i| {
                let e = PHANTOMS[i % 5];
                reference(e, law.frequency(e) + 0.3 * rng.next(), 0.2, 0.0)
            })
            .collect(),
    ));
    out
}

fn air() -> AirReference {
    AirReference {
        free_resonance: Hz(FREE_HZ),
        free_q: 40.0,
        static_capacitance: Farads(20e-9),
        static_conductance: Siemens(0.0),
    }
}

/// The numbers compared, each with its kind (for the tolerance): `s` same arithmetic, `p`
/// contact constants, `m` contact misfit, `c` contact covariance, `d` decision.
fn values(c: &Calibration) -> Vec<(char, f64)> {
    let mut v = Vec::new();
    let l = &c.law;
    for x in [l.a, l.b, l.c, l.model_sigma_hz, l.min_kpa, l.max_kpa] {
        v.push(('s', x));
    }
    for x in l.cov.iter().flatten() {
        v.push(('s', *x));
    }
    for x in [c.q_model.q0, c.q_model.q1, c.q_model.q2] {
        v.push(('s', x));
    }
    v.push(('d', c.contact.is_some() as u8 as f64));
    if let Some(k) = &c.contact {
        for x in k.p {
            v.push(('p', x));
        }
        v.push(('m', k.model_sigma_hz));
        for x in k.cov.iter().flatten() {
            v.push(('c', *x));
        }
        for x in [k.free_hz, k.min_kpa, k.max_kpa, k.force_n] {
            v.push(('s', x));
        }
    }
    v
}

fn close(kind: char, got: f64, want: f64) -> bool {
    let rel = |tol: f64| (got - want).abs() <= tol * want.abs().max(1e-300);
    match kind {
        's' => rel(1e-9) || (got - want).abs() < 1e-12,
        'p' => (got - want).abs() <= 1e-6,
        'a' => rel(1e-5),
        'm' => rel(1e-5),
        'c' => rel(1e-4),
        _ => got == want,
    }
}

#[test]
fn calibrate_agrees_with_the_implementation_before_the_fast_fit() {
    let golden_path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/calibrate_golden.txt"
    );
    let mut lines = Vec::new();
    let reversed = std::env::var_os("CALIBRATE_REVERSED").is_some();
    for (name, mut refs) in sets() {
        if reversed {
            refs.reverse();
        }
        let c = calibrate(&refs, Some(&air())).expect(name);
        let v = values(&c);
        let nums: Vec<String> = v.iter().map(|(k, x)| format!("{k}:{x:e}")).collect();
        lines.push(format!("{name} {}", nums.join(" ")));
    }
    if std::env::var_os("CALIBRATE_GOLDEN_WRITE").is_some() {
        std::fs::write(golden_path, lines.join("\n") + "\n").unwrap();
        return;
    }
    let golden = std::fs::read_to_string(golden_path).unwrap();
    let golden: Vec<&str> = golden.lines().collect();
    assert_eq!(golden.len(), lines.len());
    let mut worst: Vec<(String, f64)> = Vec::new();
    let mut worst_curve = 0.0f64;
    for (g, l) in golden.iter().zip(&lines) {
        let gw: Vec<&str> = g.split(' ').collect();
        let lw: Vec<&str> = l.split(' ').collect();
        assert_eq!(gw[0], lw[0]);
        assert_eq!(
            gw.len(),
            lw.len(),
            "{}: the decision differs\n{g}\n{l}",
            gw[0]
        );
        for (k, (a, b)) in gw[1..].iter().zip(&lw[1..]).enumerate() {
            let (kind, want) = a.split_once(':').unwrap();
            // The contact law's misfit is no longer the fit's in-sample RMS floored at the
            // power law's (the golden's rule) but its held-out RMS over the interior moduli
            // (the error budget, docs/accuracy.md, bench/tests/accuracy.rs): another quantity,
            // not the fit's output.
            if kind == "m" && k != 3 {
                continue;
            }
            // The power law's constants, misfit and covariance (values 0–2, 3, 6–14).
            let kind = match k {
                0..=2 => "a",
                3 => "m",
                6..=14 => "c",
                _ => kind,
            };
            let (_, got) = b.split_once(':').unwrap();
            let (want, got): (f64, f64) = (want.parse().unwrap(), got.parse().unwrap());
            let dev = if kind == "p" {
                (got - want).abs()
            } else {
                (got - want).abs() / want.abs().max(1e-300)
            };
            worst
                .iter_mut()
                .find(|w| w.0 == kind)
                .map(|w| w.1 = w.1.max(dev))
                .unwrap_or_else(|| worst.push((kind.to_string(), dev)));
            assert!(
                close(kind.chars().next().unwrap(), got, want),
                "{} value {k} ({kind}): {got:e} vs {want:e}",
                gw[0]
            );
        }
        // The power law's curve over the span.
        let abc = |w: &[&str]| -> Vec<f64> {
            w[1..4]
                .iter()
                .map(|x| x.split_once(':').unwrap().1.parse().unwrap())
                .collect()
        };
        let (old, new) = (abc(&gw), abc(&lw));
        for e in [100.0, 157.5, 414.0, 1146.0, 2465.0, 3000.0] {
            let f = |p: &[f64]| p[0] + p[1] * libm::pow(e, p[2]);
            let d = (f(&new) - f(&old)).abs();
            assert!(
                d <= 1e-4,
                "{}: the power law at {e} kPa moved {d:e} Hz",
                gw[0]
            );
            worst_curve = worst_curve.max(d);
        }
        println!("{}: agrees", gw[0]);
    }
    // The largest deviation of each kind (absolute for `p`, relative otherwise).
    println!("largest deviations: {worst:?}; the power law's curve: {worst_curve:e} Hz");
}
