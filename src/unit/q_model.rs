//! The unit's Q model: its quality factor against modulus (and contact force) on the reference
//! phantoms, the contact condition its calibration holds for. May import the leaves.

/// The unit's quality factor against modulus on the reference phantoms, `Q ≈ q0 + q1 ln E`:
/// the contact condition the calibration holds for. A reading whose Q strays from it by more
/// than [`QModel::TOLERANCE`] was not taken in that condition (a different preload changes the
/// contact area and with it the tissue damping) and its modulus cannot be trusted. With the
/// `serde` feature it is (de)serialized as its fields by these names, `q2` and `sigma_rel` 0
/// when absent (the `q_model` object of probe-bench's profile files).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct QModel {
    /// Intercept.
    pub q0: f64,
    /// Slope per unit of `ln(E / kPa)`.
    pub q1: f64,
    /// Slope per unit of `ln(F / N)` of the contact force (0 when the references were read at
    /// one force, or without a load cell).
    #[cfg_attr(feature = "serde", serde(default))]
    pub q2: f64,
    /// Relative scatter of the references' Q about the curve (the RMS of `Q/Q_model − 1` with
    /// the fitted terms' degrees of freedom taken off): how well the curve predicts the Q of
    /// a contact like the calibration's, the floor of a reading's loss uncertainty.
    #[cfg_attr(feature = "serde", serde(default))]
    pub sigma_rel: f64,
}

/// Least relative spread (max/min) of the references' contact forces for the Q model to fit a
/// force term: below it the forces are one force.
pub const FORCE_SPAN_RATIO: f64 = 1.25;

impl QModel {
    /// Largest relative deviation of Q from the curve that still counts as the calibrated
    /// condition. The reference readings scatter by well under 5 %; doubling the preload lowers
    /// Q by about 30 % in `hal-sim`, which the force term follows when the references span
    /// forces.
    pub const TOLERANCE: f64 = 0.2;

    /// Least-squares fit of `Q = q0 + q1 ln E + q2 ln F` to `(E kPa, F N, Q)` triples: with
    /// the force term when the forces (all measured, positive) span [`FORCE_SPAN_RATIO`], else
    /// `q2 = 0`. `None` with fewer than two distinct moduli or non-finite input.
    pub fn fit<I: IntoIterator<Item = (f64, f64, f64)>>(data: I) -> Option<QModel>
    where
        I::IntoIter: Clone,
    {
        let data = data.into_iter();
        let ok = |&(e, _, q): &(f64, f64, f64)| e > 0.0 && q > 0.0 && e.is_finite();
        let (mut fmin, mut fmax) = (f64::INFINITY, 0.0f64);
        for (_, f, _) in data.clone().filter(ok) {
            fmin = fmin.min(f);
            fmax = fmax.max(f);
        }
        let with_force = fmin > 0.0 && fmax.is_finite() && fmax >= FORCE_SPAN_RATIO * fmin;
        if with_force {
            let mut a = [[0.0; 3]; 3];
            let mut b = [0.0; 3];
            for (e, f, q) in data.clone().filter(ok) {
                let x = [1.0, libm::log(e), libm::log(f)];
                for i in 0..3 {
                    b[i] += x[i] * q;
                    for j in 0..3 {
                        a[i][j] += x[i] * x[j];
                    }
                }
            }
            let inv = crate::linalg::spd_inverse(&a)?;
            let c: [f64; 3] =
                core::array::from_fn(|i| (0..3).map(|j| inv[i][j] * b[j]).sum::<f64>());
            let m = QModel {
                q0: c[0],
                q1: c[1],
                q2: c[2],
                sigma_rel: 0.0,
            };
            return c
                .iter()
                .all(|v| v.is_finite())
                .then(|| m.with_scatter(data.filter(ok), 3));
        }
        let mut l = crate::linalg::Line::default();
        for (e, _, q) in data.clone().filter(ok) {
            l.add(libm::log(e), q, 1.0);
        }
        let f = l.solve()?;
        let m = QModel {
            q0: f.a,
            q1: f.b,
            q2: 0.0,
            sigma_rel: 0.0,
        };
        (f.a.is_finite() && f.b.is_finite()).then(|| m.with_scatter(data.filter(ok), 2))
    }

    /// The model with [`Self::sigma_rel`] from `data`, fitted with `terms` terms.
    fn with_scatter<I: Iterator<Item = (f64, f64, f64)>>(self, data: I, terms: usize) -> Self {
        let (mut n, mut ss) = (0usize, 0.0);
        for (e, f, q) in data {
            let expect = self.q_at(e, (f > 0.0).then_some(f));
            if expect > 0.0 {
                let r = q / expect - 1.0;
                ss += r * r;
                n += 1;
            }
        }
        let sigma_rel = libm::sqrt(ss / n.saturating_sub(terms).max(1) as f64);
        Self {
            sigma_rel: if sigma_rel.is_finite() {
                sigma_rel
            } else {
                0.0
            },
            ..self
        }
    }

    /// Expected Q at `e_kpa` and contact force `force_n` (ignored by a model without a force
    /// term).
    pub fn q_at(&self, e_kpa: f64, force_n: Option<f64>) -> f64 {
        let f = match force_n {
            Some(f) if self.q2 != 0.0 && f > 0.0 => self.q2 * libm::log(f),
            _ => 0.0,
        };
        self.q0 + self.q1 * libm::log(e_kpa) + f
    }

    /// True when `q` at `e_kpa` (and `force_n`) is within [`Self::TOLERANCE`] of the curve.
    pub fn holds(&self, e_kpa: f64, force_n: Option<f64>, q: f64) -> bool {
        let expect = self.q_at(e_kpa, force_n);
        expect > 0.0 && libm::fabs(q / expect - 1.0) <= Self::TOLERANCE
    }

    /// True when `q` at `e_kpa` (and `force_n`) stands more than [`Self::TOLERANCE`] above the
    /// curve: a contact narrower or looser than the calibration's (a tip touching on its edge
    /// radiates less into the tissue). Tissue loss only ever lowers Q, so unlike [`Self::holds`]
    /// no lossy tissue can trigger it.
    pub fn exceeded(&self, e_kpa: f64, force_n: Option<f64>, q: f64) -> bool {
        let expect = self.q_at(e_kpa, force_n);
        !(expect > 0.0) || q / expect - 1.0 > Self::TOLERANCE
    }

    /// True when every coefficient is finite and the scatter not negative.
    pub fn is_valid(&self) -> bool {
        self.q0.is_finite()
            && self.q1.is_finite()
            && self.q2.is_finite()
            && self.sigma_rel.is_finite()
            && self.sigma_rel >= 0.0
    }
}
