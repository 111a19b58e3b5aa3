//! Bad settings are rejected with a clear error; no input panics the portable core.

use probe_rng::Rng;
use pzt_probe::board::sim::scale_of;
use pzt_probe::engine::sweep::{SettingsError, SweepPoint, SweepSettings};
use pzt_probe::estimate::{conductance, paper};
use pzt_probe::unit::calibration::RefPoint;
use pzt_probe::{Hz, Method, PowerLaw, Seconds, Volts};

fn base() -> SweepSettings {
    Method::SweepG.default_sweep()
}

#[test]
fn each_bad_setting_has_its_error() {
    let scale = scale_of(&hal_sim::FrontEnd::default());
    let check = |s: SweepSettings, e: SettingsError| {
        assert_eq!(s.validate(&scale).unwrap_err(), e, "{s:?}")
    };
    check(
        SweepSettings {
            stop: Hz(170.0),
            ..base()
        },
        SettingsError::EmptyBand,
    );
    check(
        SweepSettings {
            stop: Hz(100.0),
            ..base()
        },
        SettingsError::EmptyBand,
    );
    check(
        SweepSettings {
            step: Hz(0.0),
            ..base()
        },
        SettingsError::StepNotPositive,
    );
    check(
        SweepSettings {
            step: Hz(-1.0),
            ..base()
        },
        SettingsError::StepNotPositive,
    );
    check(
        SweepSettings {
            step: Hz(0.01),
            ..base()
        },
        SettingsError::TooManyPoints,
    );
    check(
        SweepSettings {
            step: Hz(100.0),
            ..base()
        },
        SettingsError::TooFewPoints,
    );
    check(
        SweepSettings {
            integrate: Seconds(0.004),
            ..base()
        },
        SettingsError::IntegrationShorterThanCycle,
    );
    check(
        SweepSettings {
            integrate: Seconds(0.0),
            ..base()
        },
        SettingsError::IntegrationShorterThanCycle,
    );
    check(
        SweepSettings {
            start: Hz(f32::NAN),
            ..base()
        },
        SettingsError::NotFinite,
    );
    check(
        SweepSettings {
            settle: Seconds(f32::INFINITY),
            ..base()
        },
        SettingsError::NotFinite,
    );
    check(
        SweepSettings {
            step: Hz(f32::NAN),
            ..base()
        },
        SettingsError::NotFinite,
    );
    check(
        SweepSettings {
            settle: Seconds(-0.1),
            ..base()
        },
        SettingsError::SettleNegative,
    );
    check(
        SweepSettings {
            start: Hz(0.0),
            ..base()
        },
        SettingsError::FrequencyNotPositive,
    );
    check(
        SweepSettings {
            stop: Hz(4500.0),
            ..base()
        },
        SettingsError::AboveNyquist,
    );
    check(
        SweepSettings {
            drive: Volts(0.0),
            ..base()
        },
        SettingsError::DriveOutOfRange,
    );
    check(
        SweepSettings {
            drive: Volts(50.0),
            ..base()
        },
        SettingsError::DriveOutOfRange,
    );
    check(
        SweepSettings {
            settle: Seconds(60.0),
            ..base()
        },
        SettingsError::TooLong,
    );
    for e in [
        SettingsError::EmptyBand,
        SettingsError::IntegrationShorterThanCycle,
    ] {
        assert!(!e.message().is_empty());
    }
    assert!(base().validate(&scale).is_ok());
}

fn wild(r: &mut Rng) -> f32 {
    match r.next_u64() % 8 {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => -f32::INFINITY,
        3 => 0.0,
        4 => -(r.uniform() as f32) * 1e3,
        5 => (r.uniform() as f32) * 1e9,
        6 => f32::from_bits(r.next_u64() as u32),
        _ => (r.uniform() as f32) * 400.0,
    }
}

#[test]
fn random_input_never_panics() {
    let scale = scale_of(&hal_sim::FrontEnd::default());
    let mut r = Rng::new(99);
    let cal = PowerLaw::paper_experiment();
    for _ in 0..20_000 {
        let s = SweepSettings {
            start: Hz(wild(&mut r)),
            stop: Hz(wild(&mut r)),
            step: Hz(wild(&mut r)),
            settle: Seconds(wild(&mut r)),
            integrate: Seconds(wild(&mut r)),
            drive: Volts(wild(&mut r)),
        };
        if let Ok(v) = s.validate(&scale) {
            for i in 0..v.len() {
                let p = v.plan(i, i as u16);
                assert!(p.cycles >= 1 && p.amplitude_codes <= 2047);
            }
        }
        let _ = cal.invert(Hz(wild(&mut r)), Hz(wild(&mut r)));
    }
    // Estimators on garbage points.
    for _ in 0..5_000 {
        let n = (r.next_u64() % 12) as usize;
        let pts: Vec<SweepPoint> = (0..n)
            .map(|_| SweepPoint {
                freq: Hz(wild(&mut r)),
                g_s: wild(&mut r),
                b_s: wild(&mut r),
                sigma_s: wild(&mut r),
                current_a: wild(&mut r),
                drive_v: wild(&mut r),
                clip_fraction: 0.0,
                residual_a: wild(&mut r),
            })
            .collect();
        if let Ok(e) = conductance::estimate(&pts) {
            assert!(e.resonance.0.is_finite() && e.sigma.0.is_finite());
        }
        if let Ok(e) = paper::estimate(&pts) {
            assert!(e.resonance.0.is_finite() && e.sigma.0.is_finite());
        }
    }
    // Calibration fit on garbage.
    for _ in 0..2_000 {
        let n = (r.next_u64() % 9) as usize;
        let d: Vec<RefPoint> = (0..n)
            .map(|_| RefPoint {
                modulus_kpa: wild(&mut r) as f64,
                resonance_hz: wild(&mut r) as f64,
                sigma_hz: wild(&mut r) as f64,
                force_n: wild(&mut r) as f64,
            })
            .collect();
        if let Ok(p) = PowerLaw::fit(&d) {
            assert!(p.is_valid());
        }
    }
}

/// The default strategy falls back to sweep-G when hold and fit miss the resonance, and says
/// so.
#[test]
fn auto_falls_back_and_names_the_method_used() {
    use hal_sim::{NoiseScene, Scene};
    use pzt_probe::board::sim::read;
    use pzt_probe::estimate::staged::StagedSettings;
    use pzt_probe::reading::Settings;
    // Only the method used and the resonance are checked: no unit profile is needed.
    let cal = pzt_probe::unit::profile::UnitProfile::fallback();
    let scene = Scene::on_modulus_kpa(1000.0).with_noise(NoiseScene::Bench);
    let f0 = scene.resonance_hz();
    // Default: its first stage, hold, finds it.
    let r = read(
        &scene,
        3,
        Method::Auto,
        Method::Auto.default_settings(),
        &cal,
        |_| {},
    )
    .unwrap();
    assert_eq!(r.method, Method::Hold);
    assert!((r.resonance.unwrap().0 as f64 - f0).abs() < 0.5);
    // A band that misses the resonance (170–200 Hz for 251 Hz): hold and fit say out of band,
    // the strategy sweeps 170–290 Hz with sweep-G and finds it.
    let narrow = StagedSettings {
        band_start: Hz(170.0),
        band_stop: Hz(200.0),
        ..StagedSettings::DEFAULT
    };
    let r = read(
        &scene,
        3,
        Method::Auto,
        Settings::Staged(narrow),
        &cal,
        |_| {},
    )
    .unwrap();
    assert_eq!(r.method, Method::SweepG, "{r:?}");
    assert!((r.resonance.unwrap().0 as f64 - f0).abs() < 0.1, "{r:?}");
    assert!(
        r.probe_time.0 > 6.0,
        "the probe time counts both methods: {r:?}"
    );
}
