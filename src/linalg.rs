//! Small least-squares helpers shared by the demodulator, the estimators and the calibration
//! fit: a 3×3 inverse and a weighted three-parameter linear least-squares accumulator.

/// Inverse of a 3×3 matrix, or `None` if it is singular to working precision.
pub fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    let scale = m[0][0].abs() * m[1][1].abs() * m[2][2].abs();
    if !det.is_finite() || det == 0.0 || det.abs() <= scale * 1e-13 {
        return None;
    }
    let inv_det = 1.0 / det;
    Some([
        [
            c00 * inv_det,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv_det,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv_det,
        ],
        [
            c01 * inv_det,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv_det,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv_det,
        ],
        [
            c02 * inv_det,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv_det,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv_det,
        ],
    ])
}

/// Weighted linear least squares `y ≈ p · x` with three basis functions.
#[derive(Clone, Copy, Debug, Default)]
pub struct Lsq3 {
    ata: [[f64; 3]; 3],
    atb: [f64; 3],
    btb: f64,
    n: u32,
}

/// Result of [`Lsq3::solve`].
#[derive(Clone, Copy, Debug)]
pub struct Fit3 {
    /// Parameters.
    pub p: [f64; 3],
    /// Covariance of the parameters for the given weights (`(AᵀWA)⁻¹`), unscaled.
    pub cov: [[f64; 3]; 3],
    /// Weighted residual sum of squares (χ² when weights are `1/σ²`).
    pub chi2: f64,
    /// Number of observations.
    pub n: u32,
}

impl Fit3 {
    /// χ² per degree of freedom (1 when there are no degrees of freedom).
    pub fn reduced_chi2(&self) -> f64 {
        if self.n > 3 {
            self.chi2 / (self.n - 3) as f64
        } else {
            1.0
        }
    }
}

impl Lsq3 {
    /// Add observation `y` of basis values `x` with weight `w` (`1/σ²`). Non-finite input is
    /// ignored.
    pub fn add(&mut self, x: [f64; 3], y: f64, w: f64) {
        if !(w > 0.0) || !w.is_finite() || !y.is_finite() || x.iter().any(|v| !v.is_finite()) {
            return;
        }
        for i in 0..3 {
            for j in 0..3 {
                self.ata[i][j] += w * x[i] * x[j];
            }
            self.atb[i] += w * x[i] * y;
        }
        self.btb += w * y * y;
        self.n += 1;
    }

    /// Solve, or `None` when underdetermined or singular.
    pub fn solve(&self) -> Option<Fit3> {
        if self.n < 3 {
            return None;
        }
        let cov = inverse3(&self.ata)?;
        let mut p = [0.0; 3];
        for (i, pi) in p.iter_mut().enumerate() {
            *pi = cov[i][0] * self.atb[0] + cov[i][1] * self.atb[1] + cov[i][2] * self.atb[2];
        }
        let explained = p[0] * self.atb[0] + p[1] * self.atb[1] + p[2] * self.atb[2];
        Some(Fit3 {
            p,
            cov,
            chi2: (self.btb - explained).max(0.0),
            n: self.n,
        })
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    #[test]
    fn inverse_times_matrix_is_identity() {
        let m = [[4.0, 1.0, 2.0], [1.0, 3.0, 0.5], [2.0, 0.5, 5.0]];
        let inv = inverse3(&m).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let mut s = 0.0;
                for k in 0..3 {
                    s += m[i][k] * inv[k][j];
                }
                assert!((s - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        assert!(inverse3(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }

    #[test]
    fn quadratic_fit_recovers_coefficients() {
        let mut l = Lsq3::default();
        for i in 0..10 {
            let x = i as f64 * 0.3 - 1.0;
            l.add([1.0, x, x * x], 2.0 - 0.5 * x + 3.0 * x * x, 1.0);
        }
        let f = l.solve().unwrap();
        assert!((f.p[0] - 2.0).abs() < 1e-10);
        assert!((f.p[1] + 0.5).abs() < 1e-10);
        assert!((f.p[2] - 3.0).abs() < 1e-10);
        assert!(f.chi2 < 1e-18);
    }
}

/// Weighted straight-line fit `y ≈ a + b x`.
#[derive(Clone, Copy, Debug, Default)]
pub struct Line {
    sw: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    n: u32,
}

/// Result of [`Line::solve`].
#[derive(Clone, Copy, Debug)]
pub struct LineFit {
    /// Intercept.
    pub a: f64,
    /// Slope.
    pub b: f64,
    /// Variance of the slope for the given weights.
    pub var_b: f64,
    /// Weighted residual sum of squares.
    pub chi2: f64,
    /// Observations.
    pub n: u32,
}

impl Line {
    /// Add `(x, y)` with weight `w` (`1/σ²`); non-finite input is ignored.
    pub fn add(&mut self, x: f64, y: f64, w: f64) {
        if !(w > 0.0) || !w.is_finite() || !x.is_finite() || !y.is_finite() {
            return;
        }
        self.sw += w;
        self.sx += w * x;
        self.sy += w * y;
        self.sxx += w * x * x;
        self.sxy += w * x * y;
        self.syy += w * y * y;
        self.n += 1;
    }

    /// Solve, or `None` with fewer than two distinct abscissae.
    pub fn solve(&self) -> Option<LineFit> {
        if self.n < 2 {
            return None;
        }
        // Centre x for conditioning.
        let xm = self.sx / self.sw;
        let ym = self.sy / self.sw;
        let sxx = self.sxx - self.sw * xm * xm;
        let sxy = self.sxy - self.sw * xm * ym;
        let syy = self.syy - self.sw * ym * ym;
        if !(sxx > 0.0) {
            return None;
        }
        let b = sxy / sxx;
        let a = ym - b * xm;
        Some(LineFit {
            a,
            b,
            var_b: 1.0 / sxx,
            chi2: (syy - b * sxy).max(0.0),
            n: self.n,
        })
    }
}

/// When a Levenberg–Marquardt minimisation stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmStop {
    /// Most steps.
    pub iterations: usize,
    /// An accepted step that lowers χ² by less than this fraction of it is the last.
    pub rel_tol: f64,
    /// The damping at which a minimisation that cannot lower χ² gives up.
    pub max_lambda: f64,
}

impl LmStop {
    /// Stop after `iterations` steps, at a step that lowers χ² by less than `rel_tol` of it, or
    /// when the damping exceeds `max_lambda`.
    pub const fn new(iterations: usize, rel_tol: f64, max_lambda: f64) -> Self {
        Self {
            iterations,
            rel_tol,
            max_lambda,
        }
    }
}

/// Levenberg–Marquardt minimisation of `chi2` from `p`: each step solves the damped normal
/// equations `normal(p)` gives (`JᵀWJ`, `JᵀW r`, [`damped_solve`]); a step that lowers χ² is
/// taken and the damping divided by 3, one that does not (or a damped system that is not
/// positive definite) multiplies it by 10. `chi2` may answer `f64::INFINITY` for parameters
/// outside their domain. Returns the parameters and their χ².
pub fn levenberg_marquardt<const N: usize>(
    mut p: [f64; N],
    chi2: impl Fn(&[f64; N]) -> f64,
    normal: impl Fn(&[f64; N]) -> ([[f64; N]; N], [f64; N]),
    stop: LmStop,
) -> ([f64; N], f64) {
    let mut best = chi2(&p);
    let mut lambda = 1e-3;
    for _ in 0..stop.iterations {
        let (jtj, jtr) = normal(&p);
        if let Some(step) = damped_solve(&jtj, &jtr, lambda) {
            let trial: [f64; N] = core::array::from_fn(|a| p[a] + step[a]);
            let c = chi2(&trial);
            if c < best {
                let done = best - c <= stop.rel_tol * best.max(1e-300);
                best = c;
                p = trial;
                lambda = (lambda * 0.3).max(1e-12);
                if done {
                    break;
                }
                continue;
            }
        }
        lambda *= 10.0;
        if lambda > stop.max_lambda {
            break;
        }
    }
    (p, best)
}

/// Solve the (Levenberg–Marquardt damped) normal equations `(JᵀWJ + λ diag(JᵀWJ)) x = JᵀW r`
/// by [`spd_inverse`]; `lambda = 0` is the plain Gauss–Newton step. `None` when the damped
/// matrix is not positive definite.
pub fn damped_solve<const N: usize>(
    jtj: &[[f64; N]; N],
    jtr: &[f64; N],
    lambda: f64,
) -> Option<[f64; N]> {
    let mut m = *jtj;
    for (i, row) in m.iter_mut().enumerate() {
        row[i] *= 1.0 + lambda;
    }
    spd_solve(&m, jtr)
}

/// The float arithmetic shared by `f64` (software on the Cortex-M4F: the covariances, the
/// calibration fits) and `f32` (its FPU: hold's Levenberg–Marquardt steps, a reading's
/// contact-law inversion): the Cholesky factorisation and solve, and the contact law's
/// evaluation, each written once for both, with each type's elementary functions.
pub trait Real:
    Copy
    + PartialOrd
    + core::ops::Add<Output = Self>
    + core::ops::Sub<Output = Self>
    + core::ops::Mul<Output = Self>
    + core::ops::Div<Output = Self>
    + core::ops::Neg<Output = Self>
    + core::ops::SubAssign
{
    /// Zero.
    const ZERO: Self;
    /// One.
    const ONE: Self;
    /// The machine epsilon.
    const EPSILON: Self;
    /// The nearest value of the type.
    fn of(v: f64) -> Self;
    /// The value as `f64` (exact).
    fn wide(self) -> f64;
    /// The square root.
    fn sqrt(self) -> Self;
    /// The cube root.
    fn cbrt(self) -> Self;
    /// `e^self`.
    fn exp(self) -> Self;
    /// The natural logarithm.
    fn ln(self) -> Self;
    /// The absolute value.
    fn abs(self) -> Self;
    /// True when neither infinite nor NaN.
    fn finite(self) -> bool;
}

/// [`Real`] for a float type with its elementary functions.
macro_rules! real {
    ($t:ty, sqrt: $sqrt:path, cbrt: $cbrt:path, exp: $exp:path, ln: $ln:path, abs: $abs:path) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const EPSILON: Self = <$t>::EPSILON;
            fn of(v: f64) -> Self {
                v as $t
            }
            fn wide(self) -> f64 {
                self as f64
            }
            fn sqrt(self) -> Self {
                $sqrt(self)
            }
            fn cbrt(self) -> Self {
                $cbrt(self)
            }
            fn exp(self) -> Self {
                $exp(self)
            }
            fn ln(self) -> Self {
                $ln(self)
            }
            fn abs(self) -> Self {
                $abs(self)
            }
            fn finite(self) -> bool {
                self.is_finite()
            }
        }
    };
}

real!(f64, sqrt: libm::sqrt, cbrt: libm::cbrt, exp: libm::exp, ln: libm::log, abs: libm::fabs);
real!(
    f32,
    sqrt: crate::dsp::trig::sqrtf,
    cbrt: crate::dsp::trig::cbrtf,
    exp: libm::expf,
    ln: libm::logf,
    abs: libm::fabsf
);

/// The lower Cholesky factor `L` (`m = L Lᵀ`) of a symmetric positive-definite matrix (its lower
/// triangle is read) into `l`, and the reciprocals of its diagonal into `rd`; `None` if `m` is
/// not positive definite. (Into the caller's arrays: a returned pair is copied out.)
#[allow(clippy::needless_range_loop)] // triangular index arithmetic reads best as indices
fn cholesky<T: Real, const N: usize>(
    m: &[[T; N]; N],
    l: &mut [[T; N]; N],
    rd: &mut [T; N],
) -> Option<()> {
    for i in 0..N {
        // (`0..i + 1`: `0..=i` is an out-of-line iterator call at `opt-level = "z"`.)
        for j in 0..i + 1 {
            let mut s = m[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(s > T::ZERO) || !s.finite() {
                    return None;
                }
                l[i][i] = s.sqrt();
                rd[i] = T::ONE / l[i][i];
            } else {
                l[i][j] = s * rd[j];
            }
        }
    }
    Some(())
}

/// `x` with `m x = b` for a symmetric positive-definite `m` (its lower triangle is read), by
/// Cholesky factorisation and two triangular substitutions (a third of the work of
/// [`spd_inverse`] and a product: on the Cortex-M4F every `f64` operation is software); `None`
/// if `m` is not positive definite.
#[allow(clippy::needless_range_loop)] // triangular index arithmetic reads best as indices
pub fn spd_solve<T: Real, const N: usize>(m: &[[T; N]; N], b: &[T; N]) -> Option<[T; N]> {
    let (mut l, mut rd) = ([[T::ZERO; N]; N], [T::ZERO; N]);
    cholesky(m, &mut l, &mut rd)?;
    // L y = b, then Lᵀ x = y.
    let mut y = [T::ZERO; N];
    for i in 0..N {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s * rd[i];
    }
    let mut x = [T::ZERO; N];
    for i in (0..N).rev() {
        let mut s = y[i];
        for k in i + 1..N {
            s -= l[k][i] * x[k];
        }
        x[i] = s * rd[i];
    }
    x.iter().all(|v| v.finite()).then_some(x)
}

/// Inverse of a symmetric positive-definite matrix by Cholesky factorisation; `None` if `m` is
/// not positive definite.
#[allow(clippy::needless_range_loop)] // triangular index arithmetic reads best as indices
pub fn spd_inverse<const N: usize>(m: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let (mut l, mut rd) = ([[0.0; N]; N], [0.0; N]);
    cholesky(m, &mut l, &mut rd)?;
    // inverse = L^-T L^-1: invert L column by column.
    let mut linv = [[0.0; N]; N];
    for i in 0..N {
        linv[i][i] = rd[i];
        for j in 0..i {
            let mut s = 0.0;
            for k in j..i {
                s -= l[i][k] * linv[k][j];
            }
            linv[i][j] = s * rd[i];
        }
    }
    let mut inv = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut s = 0.0;
            for k in i..N {
                s += linv[k][i] * linv[k][j];
            }
            inv[i][j] = s;
            inv[j][i] = s;
        }
    }
    Some(inv)
}

#[cfg(test)]
mod more_tests {
    use super::*;

    #[test]
    fn line_fit_exact() {
        let mut l = Line::default();
        for i in 0..5 {
            l.add(i as f64, 3.0 - 2.0 * i as f64, 2.0);
        }
        let f = l.solve().unwrap();
        assert!((f.a - 3.0).abs() < 1e-12 && (f.b + 2.0).abs() < 1e-12);
        // var_b = 1 / (w Σ (x - x̄)^2) = 1 / (2 * 10)
        assert!((f.var_b - 0.05).abs() < 1e-12);
    }

    /// `spd_solve`'s `x` satisfies `m x = b` (checked by the product, in `f64`), and refuses a
    /// matrix that is not positive definite.
    #[test]
    fn spd_solve_solves() {
        let a: [[f64; 5]; 5] = core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                ((i * 7 + j * 3) % 5) as f64 - 1.5 + if i == j { 0.3 } else { 0.0 }
            })
        });
        // m = aᵀa + I: symmetric positive definite.
        let m: [[f64; 5]; 5] = core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                (0..5).map(|k| a[k][i] * a[k][j]).sum::<f64>() + if i == j { 1.0 } else { 0.0 }
            })
        });
        let b = [1.0, -2.0, 0.5, 3.0, -1.0];
        let x = spd_solve(&m, &b).unwrap();
        for i in 0..5 {
            let r: f64 = (0..5).map(|j| m[i][j] * x[j]).sum();
            assert!((r - b[i]).abs() < 1e-12, "{i}: {r} vs {}", b[i]);
        }
        let mut bad = m;
        bad[2][2] = -1.0;
        assert!(spd_solve(&bad, &b).is_none());
    }

    #[test]
    fn spd_inverse_matches_inverse3() {
        let m = [[4.0, 1.0, 2.0], [1.0, 3.0, 0.5], [2.0, 0.5, 5.0]];
        let a = spd_inverse(&m).unwrap();
        let b = inverse3(&m).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert!((a[i][j] - b[i][j]).abs() < 1e-12);
            }
        }
        assert!(spd_inverse(&[[1.0, 2.0], [2.0, 1.0]]).is_none());
    }
}
