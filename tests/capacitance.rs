//! With the static capacitance dominant (motional current a tenth of the capacitive one), the
//! conductance estimate still finds the motional resonance while the |Z| minimum is pulled
//! away from it. Reference: the scene's closed-form resonance sqrt(k/m)/2pi.

use hal_sim::{NoiseScene, Scene};
use pzt_probe::board::sim::read;
use pzt_probe::engine::sweep::SweepSettings;
use pzt_probe::{Hz, Method, Seconds, Volts};

#[test]
fn conductance_is_unbiased_where_impedance_minimum_is_not() {
    let mut scene = Scene::on_modulus_kpa(300.0).with_noise(NoiseScene::Bench);
    let k = scene.kelvin();
    let f0 = scene.resonance_hz();
    // Motional peak conductance alpha^2/c; make w0 C0 ten times larger.
    let g_peak = scene.pzt.motional_peak_s(&k);
    scene.pzt.c0_f = 10.0 * g_peak / (2.0 * std::f64::consts::PI * f0);
    let y = scene.admittance(f0);
    assert!(
        (y.im / y.re - 10.0).abs() < 0.01,
        "capacitive/motional at resonance {}",
        y.im / y.re
    );
    // Only resonances are compared: no unit profile is needed.
    let cal = pzt_probe::unit::profile::UnitProfile::fallback();
    // 2 V keeps the larger capacitive current inside the ADC range.
    let sweep = |m: Method| SweepSettings {
        drive: Volts(2.0),
        ..m.default_sweep()
    };
    let g = read(
        &scene,
        11,
        Method::SweepG,
        &sweep(Method::SweepG),
        &cal,
        |_| {},
    )
    .unwrap();
    let fg = g.resonance.expect("sweep-G resonance").0 as f64;
    assert!(
        (fg - f0).abs() < 0.3,
        "conductance estimate {fg:.3} vs {f0:.3} Hz"
    );

    let paper_settings = SweepSettings {
        start: Hz(200.0),
        stop: Hz(300.0),
        step: Hz(1.0),
        settle: Seconds(0.05),
        integrate: Seconds(0.05),
        drive: Volts(2.0),
    };
    let p = read(&scene, 11, Method::Paper, &paper_settings, &cal, |_| {}).unwrap();
    let fp = p.resonance.expect("|Z| minimum").0 as f64;
    // The |Z| minimum of C0 || motional branch sits between the series and parallel
    // resonances; with C0 dominant it is pulled several hertz off the motional resonance.
    println!("true {f0:.3} Hz, sweep-G {fg:.3} Hz, |Z| min {fp:.3} Hz");
    assert!(
        (fp - f0).abs() > 1.0,
        "|Z| minimum {fp:.3} should be visibly biased from {f0:.3}"
    );
}
