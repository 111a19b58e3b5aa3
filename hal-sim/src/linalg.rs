//! Small dense matrices and the matrix exponential used to discretise the linear plant exactly.

/// Square matrix, row-major.
pub type Mat<const N: usize> = [[f64; N]; N];

/// Identity.
pub fn identity<const N: usize>() -> Mat<N> {
    let mut m = [[0.0; N]; N];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

/// Matrix product `a * b`.
pub fn mul<const N: usize>(a: &Mat<N>, b: &Mat<N>) -> Mat<N> {
    let mut c = [[0.0; N]; N];
    for i in 0..N {
        for k in 0..N {
            let aik = a[i][k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..N {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

/// Matrix-vector product.
pub fn mul_vec<const N: usize>(a: &Mat<N>, x: &[f64; N]) -> [f64; N] {
    let mut y = [0.0; N];
    for i in 0..N {
        let mut acc = 0.0;
        for j in 0..N {
            acc += a[i][j] * x[j];
        }
        y[i] = acc;
    }
    y
}

fn norm1<const N: usize>(a: &Mat<N>) -> f64 {
    let mut best = 0.0f64;
    for j in 0..N {
        let mut s = 0.0;
        for row in a.iter() {
            s += row[j].abs();
        }
        best = best.max(s);
    }
    best
}

/// Matrix exponential by scaling and squaring with an 18-term Taylor series.
///
/// The argument is scaled to a 1-norm below 1/8, where the truncated series is exact to f64
/// rounding (the first omitted term is below 1/8^18/18! ≈ 1e-32), then squared back.
pub fn expm<const N: usize>(a: &Mat<N>) -> Mat<N> {
    let norm = norm1(a);
    let mut squarings = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.125 && squarings < 60 {
        scale *= 0.5;
        squarings += 1;
    }
    let mut x = *a;
    for row in x.iter_mut() {
        for v in row.iter_mut() {
            *v *= scale;
        }
    }
    let mut result = identity::<N>();
    let mut term = identity::<N>();
    for k in 1..=18 {
        term = mul(&term, &x);
        let inv = 1.0 / k as f64;
        for row in term.iter_mut() {
            for v in row.iter_mut() {
                *v *= inv;
            }
        }
        for i in 0..N {
            for j in 0..N {
                result[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..squarings {
        result = mul(&result, &result);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expm_of_rotation_generator() {
        // exp([[0, -t], [t, 0]]) = [[cos t, -sin t], [sin t, cos t]]
        let t = 2.7;
        let e = expm(&[[0.0, -t], [t, 0.0]]);
        assert!((e[0][0] - libm::cos(t)).abs() < 1e-13);
        assert!((e[1][0] - libm::sin(t)).abs() < 1e-13);
    }

    #[test]
    fn expm_of_diagonal() {
        let e = expm(&[[-3.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 12.0]]);
        assert!((e[0][0] / libm::exp(-3.0) - 1.0).abs() < 1e-13);
        assert!((e[1][1] / libm::exp(0.5) - 1.0).abs() < 1e-13);
        assert!((e[2][2] / libm::exp(12.0) - 1.0).abs() < 1e-12);
        assert_eq!(e[0][1], 0.0);
    }
}
