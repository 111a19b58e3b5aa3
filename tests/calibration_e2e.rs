//! Calibrate the simulated unit on phantoms A–E (20 repeats each, as paper 003 did on its
//! prototype) and measure moduli it was not calibrated on.
//!
//! Reference: the moduli of the simulated tissues themselves (the scene's ground truth), not the
//! pipeline's own output.

use hal_sim::{NoiseScene, Scene};
use pzt_probe::board::sim::{read, unit_profile};
use pzt_probe::Method;

const REPEATS: usize = 20;
/// Readings per modulus for comparing reported and observed scatter: the standard deviation of
/// 20 readings is itself uncertain by 16 %, so the comparison uses 40.
const SCATTER_REPEATS: usize = 40;

fn stats(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

#[test]
fn calibrated_unit_reads_unseen_moduli() {
    let method = Method::SweepG;
    let settings = method.default_sweep();
    let unit =
        unit_profile(method, &settings, NoiseScene::Bench, REPEATS, 1000).expect("calibration");
    let cal = unit.calibration;
    println!("fitted: f = {:.3} + {:.1} E^{:.4}", cal.a, cal.b, cal.c);
    for (k, e_true) in [200.0f64, 350.0, 700.0, 1500.0].into_iter().enumerate() {
        let scene = Scene::on_modulus_kpa(e_true).with_noise(NoiseScene::Bench);
        let mut e = Vec::new();
        let mut s = Vec::new();
        let mut combined = Vec::new();
        for r in 0..SCATTER_REPEATS {
            let seed = 50_000 + (k * SCATTER_REPEATS + r) as u64;
            let reading = read(&scene, seed, method, &settings, &unit, |_| {}).unwrap();
            assert!(
                reading.status.is_ok(),
                "{e_true} kPa seed {seed}: {:?}",
                reading
            );
            e.push(reading.modulus.unwrap().0 as f64);
            s.push(reading.modulus_sigma_repeat.unwrap().0 as f64);
            assert!(reading.modulus_sigma.unwrap().0 >= reading.modulus_sigma_repeat.unwrap().0);
            combined.push(reading.modulus_sigma.unwrap().0 as f64);
        }
        // Mean and repeat scatter over the first 20 readings (as the paper did).
        let (mean, sd) = stats(&e[..REPEATS]);
        let (_, sd_all) = stats(&e);
        let reported = (s.iter().map(|x| x * x).sum::<f64>() / s.len() as f64).sqrt();
        let err = (mean - e_true) / e_true;
        println!(
            "{e_true:6.0} kPa: mean {mean:8.2} ({:+.3} %), sd {:.3} %, reported {:.3} %, ratio {:.2}",
            100.0 * err,
            100.0 * sd / e_true,
            100.0 * reported / e_true,
            reported / sd_all
        );
        assert!(
            err.abs() <= 0.02,
            "{e_true} kPa: mean error {:.2} %",
            100.0 * err
        );
        assert!(
            sd / e_true <= 0.02,
            "{e_true} kPa: repeat sd {:.2} %",
            100.0 * sd / e_true
        );
        // The combined uncertainty (repeatability + calibration, including the power law's
        // misfit between the phantoms) covers the error against the truth.
        let comb = combined.iter().sum::<f64>() / combined.len() as f64;
        println!(
            "          combined sigma {:.3} %, |error| / combined sigma {:.2}",
            100.0 * comb / e_true,
            (mean - e_true).abs() / comb
        );
        assert!(
            (mean - e_true).abs() <= 3.0 * comb,
            "{e_true} kPa: error {:.2} kPa vs combined sigma {comb:.2} kPa",
            mean - e_true
        );
        let ratio = reported / sd_all;
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{e_true} kPa: reported sigma {reported:.3} vs scatter {sd_all:.3} (ratio {ratio:.2})"
        );
    }
}
