//! Complex numbers for closed-form admittance (`num-complex`, `no_std` with `libm`).

/// Complex number `re + j*im` in f64.
pub type C64 = num_complex::Complex64;
