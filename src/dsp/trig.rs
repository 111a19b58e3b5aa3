//! `sin` and `cos` of an `f32` argument in `f32` arithmetic alone, the square root on the FPU,
//! and the cube root in `f32` arithmetic alone.
//!
//! The `libm` crate's `sinf`, `cosf`, `sincosf` (musl's) reduce the argument and evaluate their
//! polynomials in `f64`, which the Cortex-M4F emulates in software: about 2 400 instructions a
//! call, the largest single cost of the hold fit's inner loop. [`sincos`] reduces by Cody–Waite
//! (`π/2` in three parts) and evaluates Cephes' single-precision minimax polynomials on
//! `|r| ≤ π/4`, all in `f32` (about 60 instructions on the FPU); its error is a few units in
//! the last place (below 2e-7 absolute for `|x| ≤ 1e3`, `tests`). IEEE `f32` arithmetic, no
//! fused operations: the same bits on the host and the target.

/// Largest `|x|` reduced here; beyond it (and for non-finite `x`) `libm::sincosf` answers.
const MAX_REDUCED: f32 = 8192.0;

/// `(sin x, cos x)`.
pub fn sincos(x: f32) -> (f32, f32) {
    if !(libm::fabsf(x) <= MAX_REDUCED) {
        return libm::sincosf(x);
    }
    // π/2 = P1 + P2 + P3, P1 and P2 with few enough bits that n·P1, n·P2 are exact for the
    // quadrants reduced here.
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_513e-4;
    const P3: f32 = 7.549_79e-8;
    let t = x * core::f32::consts::FRAC_2_PI;
    let n = (t + if t < 0.0 { -0.5 } else { 0.5 }) as i32;
    let nf = n as f32;
    let r = ((x - nf * P1) - nf * P2) - nf * P3;
    let z = r * r;
    let s = r + r * z * (-1.666_665_5e-1 + z * (8.332_161e-3 + z * -1.951_529_6e-4));
    let c = 1.0 - 0.5 * z + z * z * (4.166_664_6e-2 + z * (-1.388_731_6e-3 + z * 2.443_315_7e-5));
    match n & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// `√x`, correctly rounded: the FPU's `VSQRT.F32` on a hard-float Arm target (one instruction
/// where `libm::sqrtf`'s portable loop takes about 90), `libm::sqrtf` elsewhere — both are
/// IEEE-exact, so the same bits on the host and the target.
#[inline]
pub fn sqrtf(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        let r: u32;
        // SAFETY: VSQRT.F32 through s15, which the sequence saves in a core register first and
        // restores last (the `sreg` operand class needs the double-precision `vfp2` feature the
        // Cortex-M4F lacks); no memory, no flags.
        unsafe {
            core::arch::asm!(
                "vmov {save}, s15",
                "vmov s15, {x}",
                "vsqrt.f32 s15, s15",
                "vmov {r}, s15",
                "vmov s15, {save}",
                x = in(reg) x.to_bits(),
                r = lateout(reg) r,
                save = out(reg) _,
                options(pure, nomem, nostack)
            );
        }
        f32::from_bits(r)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// `√x` of an `f64` kept in `f32` (a standard uncertainty from its variance): [`sqrtf`] of `x`
/// rounded to `f32`, within one `f32` rounding of the exact root (the soft-float `f64` root it
/// replaces takes about 300 instructions on the Cortex-M4F). `+∞` for `x` beyond `f32`'s range,
/// NaN for a negative or NaN `x`.
#[inline]
pub fn sqrt32(x: f64) -> f32 {
    sqrtf(x as f32)
}

/// `∛x` in `f32` arithmetic alone (musl's `cbrtf`, which `libm::cbrtf` ports, refines in `f64`:
/// software on the Cortex-M4F). A first guess from the exponent's bits divided by three (the
/// classic constant of Kahan's and musl's `cbrtf`, within about 4 %), then three Newton steps
/// `y ← y − (y − x/y²)/3` (quadratic: 4 % → 2e-3 → 4e-6 → a few ulps; `y³` never formed, so no
/// overflow near `f32::MAX`): within 2 ulps of the
/// exact root for every positive normal `x` (`tests`). Its sign for negative `x`, `x` itself for
/// 0, ±∞ and NaN, and `libm::cbrtf` for subnormals.
pub fn cbrtf(x: f32) -> f32 {
    let a = libm::fabsf(x);
    if !(a >= f32::MIN_POSITIVE) || a == f32::INFINITY {
        return if a == 0.0 || !a.is_finite() {
            x
        } else {
            libm::cbrtf(x)
        };
    }
    let mut y = f32::from_bits(a.to_bits() / 3 + 709_958_130);
    for _ in 0..3 {
        y -= (y - a / (y * y)) * (1.0 / 3.0);
    }
    if x < 0.0 {
        -y
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within 2 ulps of the exact root (`f64`'s, rounded) over the normal range, sampled at
    /// 300 000 points across every binade, and the special values.
    #[test]
    fn cube_root_is_within_two_ulps() {
        let mut worst = 0u32;
        let mut bits = f32::MIN_POSITIVE.to_bits();
        while bits < f32::MAX.to_bits() {
            let x = f32::from_bits(bits);
            let want = (x as f64).cbrt() as f32;
            let got = cbrtf(x);
            worst = worst.max(got.to_bits().abs_diff(want.to_bits()));
            assert_eq!(cbrtf(-x), -got);
            bits += 7_001;
        }
        assert!(worst <= 2, "{worst} ulps");
        assert!(worst > 0, "the test sees no rounding");
        assert_eq!(cbrtf(0.0), 0.0);
        assert_eq!(cbrtf(f32::INFINITY), f32::INFINITY);
        assert!(cbrtf(f32::NAN).is_nan());
        assert_eq!(cbrtf(1e-40), libm::cbrtf(1e-40));
        assert_eq!(cbrtf(27.0), 3.0);
    }

    /// Against the `f64` sine and cosine over ±1000 rad (the hold fit's arguments stay within
    /// ±100), and the `libm` fallback beyond the reduced range.
    #[test]
    fn matches_f64_sine_and_cosine() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * 0.005_000_1;
            let (s, c) = sincos(x);
            let (se, ce) = ((x as f64).sin(), (x as f64).cos());
            worst = worst.max((s as f64 - se).abs()).max((c as f64 - ce).abs());
        }
        assert!(worst < 2e-7, "{worst:e}");
        assert_eq!(sincos(1e5), libm::sincosf(1e5));
        assert!(sincos(f32::NAN).0.is_nan());
        assert_eq!(sincos(0.0), (0.0, 1.0));
    }

    #[test]
    fn square_root_is_libm_s() {
        for x in [0.0f32, 1e-30, 0.25, 2.0, 3.7e9, f32::INFINITY] {
            assert_eq!(sqrtf(x), libm::sqrtf(x));
        }
        assert!(sqrtf(-1.0).is_nan());
    }

    /// [`sqrt32`] against the `f64` root rounded to `f32`: within one `f32` rounding (2⁻²³ of
    /// itself; the input's rounding moves the root by half of its own) over 1e-30 to 1e30, and
    /// the range's ends and a negative input as documented.
    #[test]
    fn root_kept_in_f32_is_within_one_rounding() {
        let mut rng = probe_rng::Rng::new(4271);
        let mut worst = 0.0f64;
        for _ in 0..20_000 {
            let x = 10f64.powf(60.0 * rng.uniform() - 30.0);
            let want = x.sqrt();
            worst = worst.max((sqrt32(x) as f64 / want - 1.0).abs());
        }
        assert!(worst <= f32::EPSILON as f64, "{worst:e}");
        assert_eq!(sqrt32(0.0), 0.0);
        assert_eq!(sqrt32(1e39), f32::INFINITY);
        assert!(sqrt32(-1.0).is_nan());
    }
}
