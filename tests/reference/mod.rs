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
