//! Independent references the integration tests share (written here, not taken from the code
//! under test).

/// The modulus where the power law `a + b E^c` equals `f`, by bisection of `ln E` with
/// `f64::powf` between 1e-9 and 1e15 kPa down to adjacent doubles; `None` where `f` is outside
/// the curve's range (`f >= a` or below it at 1e-9 kPa). The curve rises monotonically in `E`
/// for `b < 0`, `c < 0`.
pub fn modulus_by_bisection(a: f64, b: f64, c: f64, f: f64) -> Option<f64> {
    let g = |e: f64| a + b * e.powf(c) - f;
    let (mut lo, mut hi) = (1e-9f64, 1e15f64);
    if !(g(lo) < 0.0 && g(hi) > 0.0) {
        return None;
    }
    for _ in 0..200 {
        let mid = (lo * hi).sqrt();
        if mid <= lo || mid >= hi {
            break;
        }
        if g(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// The modulus where the contact law (docs/physics.md) — the probe's free mode `f_free` with the
/// tissue's Hertz stiffness `A E^(2/3)` and co-moving mass `B/E` behind a coupling `Ks`, all per
/// modal mass — has the resonance `f`, by bisection of `ln E` between 1e-3 and 1e9 kPa with
/// `f64::powf`; `None` outside that range. Written from the mechanics, not from
/// `pzt_probe::unit::contact_law`.
#[allow(dead_code)] // tests/qemu.rs uses it; tests/ref_calibration.rs shares the module
pub fn modulus_by_contact_law(f_free: f64, ks: f64, a: f64, b: f64, f: f64) -> Option<f64> {
    let w = 2.0 * std::f64::consts::PI;
    let res = |e: f64| {
        let stiff = a * e.powf(2.0 / 3.0);
        let coupling = ks / (ks + stiff);
        let k = (w * f_free).powi(2) + coupling * stiff;
        let m = 1.0 + coupling * coupling * b / e;
        (k / m).sqrt() / w
    };
    let (mut lo, mut hi) = (1e-3f64, 1e9f64);
    if !(res(lo) < f && res(hi) > f) {
        return None;
    }
    for _ in 0..200 {
        let mid = (lo * hi).sqrt();
        if mid <= lo || mid >= hi {
            break;
        }
        if res(mid) < f {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}
