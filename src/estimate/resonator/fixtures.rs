//! The tests' windows of the resonator, made independently of the fit's closed form: demodulated
//! from the closed-form envelope ([`synthetic`]) and from the envelope stepped in time
//! ([`stepped_two`]).

use super::HoldWindow;
use core::f64::consts::PI;
use num_complex::Complex64 as C64;

/// The window a whole-cycle lock-in makes of the real current `Re(y(t) v e^{jφ(t)})`, `y`
/// the admittance's envelope sampled at `steps + 1` points over the window, `φ` turning by
/// `2π cycles` from 0 (windows start at the reference's cycle boundary): the trapezoid
/// rule's `(2/L) ∫ s e^{−jφ} dt / v` — the mirror image included, by demodulating, not by
/// the fit's closed form.
pub(super) fn demodulate(y: &[C64], v: C64, cycles: f64) -> C64 {
    let steps = y.len() - 1;
    let mut acc = C64::new(0.0, 0.0);
    for (i, yi) in y.iter().enumerate() {
        let phi = 2.0 * PI * cycles * i as f64 / steps as f64;
        let rot = C64::new(0.0, phi).exp();
        let s = (yi * v * rot).re;
        let wgt = if i == 0 || i == steps { 0.5 } else { 1.0 };
        acc += rot.conj() * (2.0 * s * wgt);
    }
    acc / steps as f64 / v
}

/// Windows of four cycles of the closed-form switched-on BVD response (f64 reference,
/// computed here independently of the fit's window means), demodulated by [`demodulate`]
/// with a real drive phasor (`mirror` 1).
pub(super) fn synthetic(
    f0: f64,
    q: f64,
    g: f64,
    f_h: f64,
    z: C64,
    y_s: C64,
    n: usize,
) -> [HoldWindow; 24] {
    let mut out = [HoldWindow::default(); 24];
    let len = 4.0 / f_h;
    let s = PI * f0 / q;
    let fd = libm::sqrt(f0 * f0 - (s / (2.0 * PI)) * (s / (2.0 * PI)));
    let u = f_h / f0 - f0 / f_h;
    let ym = C64::new(g, 0.0) / C64::new(1.0, q * u);
    let steps = 2000;
    let mut y = [C64::new(0.0, 0.0); 2001];
    for (k, o) in out.iter_mut().enumerate().take(n) {
        let a = k as f64 * len;
        for (i, yi) in y.iter_mut().enumerate() {
            let t = a + len * i as f64 / steps as f64;
            let e = C64::new(-s * t, 2.0 * PI * (fd - f_h) * t).exp();
            *yi = ym + (z - ym) * e;
        }
        *o = HoldWindow {
            t0: 0.01 + a,
            len,
            y: y_s + demodulate(&y, C64::new(1.0, 0.0), 4.0),
            var: 1e-24,
            phase: [0, 0],
        };
    }
    out
}

/// Two segments by stepping the envelope's equation `dy/dt = λ_s (y − Y_m,s)` in time (RK4,
/// 200 steps a window), the state multiplied by `rho` at the switch, each window the real
/// current demodulated ([`demodulate`]; the drive phasors `1` and `1/rho`, so the second's
/// mirror is `mirror(1/rho)`): independent of the closed-form window means, their mirror
/// image and the carry's algebra. Windows start at the reference's cycle boundaries (the
/// drive's phase is continuous through the switch, as the engine's is).
#[allow(clippy::too_many_arguments)]
pub(super) fn stepped_two(
    f0: f64,
    q: f64,
    g: f64,
    z0: C64,
    (f1, f2): (f64, f64),
    (n1, n2): (usize, usize),
    t_switch: f64,
    rho: C64,
) -> ([HoldWindow; 8], [HoldWindow; 12]) {
    let root = (1.0 - 0.25 / (q * q)).sqrt();
    let drive = |f_h: f64| {
        let u = f_h / f0 - f0 / f_h;
        let ym = C64::new(g, 0.0) / C64::new(1.0, q * u);
        let lam = C64::new(-PI * f0 / q, 2.0 * PI * (f0 * root - f_h));
        (ym, lam)
    };
    let steps = 200;
    // Windows of two cycles from the first cycle boundary after `start` (the drive's phase
    // is `2π f1 t` before the switch and continuous after it); `y` is the state at `t`,
    // carried forward.
    let phase_at = |t: f64| {
        if t <= t_switch {
            f1 * t
        } else {
            f1 * t_switch + f2 * (t - t_switch)
        }
    };
    let run = |f_h: f64, start: f64, n: usize, t: &mut f64, y: &mut C64, out: &mut [HoldWindow]| {
        let (ym, lam) = drive(f_h);
        let v = if f_h == f1 && start < t_switch {
            C64::new(1.0, 0.0)
        } else {
            C64::new(1.0, 0.0) / rho
        };
        let start = if n > 0 {
            start + (1.0 - phase_at(start).fract()) / f_h
        } else {
            start
        };
        let dy = |y: C64| lam * (y - ym);
        let advance = |to: f64, t: &mut f64, y: &mut C64| {
            let h = (to - *t) / steps as f64;
            for _ in 0..steps {
                let k1 = dy(*y);
                let k2 = dy(*y + k1 * (0.5 * h));
                let k3 = dy(*y + k2 * (0.5 * h));
                let k4 = dy(*y + k3 * h);
                *y += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
            }
            *t = to;
        };
        advance(start, t, y);
        let len = 2.0 / f_h;
        let mut ys = [C64::new(0.0, 0.0); 201];
        for o in out.iter_mut().take(n) {
            let a = *t;
            ys[0] = *y;
            let h = len / steps as f64;
            for (i, yi) in ys.iter_mut().enumerate().skip(1) {
                advance(a + h * i as f64, t, y);
                *yi = *y;
            }
            *o = HoldWindow {
                t0: a,
                len,
                y: demodulate(&ys, v, 2.0),
                // 1e-4 of the motional peak: noise-free data weighted as a long
                // hold's.
                var: 2e-22,
                phase: [0, 0],
            };
        }
    };
    let (mut w1, mut w2) = ([HoldWindow::default(); 8], [HoldWindow::default(); 12]);
    let (mut t, mut y) = (0.004, z0);
    run(f1, 0.004, n1, &mut t, &mut y, &mut w1);
    run(f1, t_switch, 0, &mut t, &mut y, &mut w1[..0]);
    y *= rho;
    run(f2, t_switch + 0.0013, n2, &mut t, &mut y, &mut w2);
    (w1, w2)
}
