//! Scenes: what is under the probe, which physics layers are active, and how noisy the front end
//! is. "Model no more than a scene needs": each scene reports the layers it uses.

use crate::complex::C64;
use crate::events::{Drift, Knocks, LiftOff, Step};
use crate::frontend::{FrontEnd, Mains};
use crate::phantoms::Phantom;
use crate::pzt::Pzt;
use crate::tissue::{Contact, Kelvin, SecondMode, SensorMech, Tissue};

/// A physics layer (or optional effect within one) that a scene switches on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// Kelvin model of the probe (always present).
    Kelvin,
    /// Tissue contact (Hertz radius + appendix formulas); absent in free air.
    Contact,
    /// PZT static capacitance and force factor.
    Pzt,
    /// Dielectric leakage of the PZT.
    DielectricLoss,
    /// Converters, amplifiers and filters of the analog front end.
    FrontEnd,
    /// White current noise.
    Noise,
    /// Mains interference.
    Mains,
    /// A second mechanical mode of the probe (a second motional branch, two more plant states).
    SecondMode,
    /// Lift-off during the reading (the contact fades out and is lost).
    LiftOff,
    /// The contact force changes during the reading (the tip stays on the tissue).
    ForceChange,
    /// Thermal drift of the probe's own resonance during the reading.
    Drift,
    /// Random mechanical and electrical knocks.
    Knocks,
    /// A step in what is under the probe (other tissue, or a new contact after a lift-off).
    Step,
}

impl Layer {
    /// Short lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Layer::Kelvin => "kelvin",
            Layer::Contact => "contact",
            Layer::Pzt => "pzt",
            Layer::DielectricLoss => "dielectric-loss",
            Layer::FrontEnd => "front-end",
            Layer::Noise => "noise",
            Layer::Mains => "mains",
            Layer::SecondMode => "second-mode",
            Layer::LiftOff => "lift-off",
            Layer::ForceChange => "force-change",
            Layer::Drift => "drift",
            Layer::Knocks => "knocks",
            Layer::Step => "step",
        }
    }

    /// Number of layers (the size of the array [`Scene::layers`] fills).
    pub const COUNT: usize = 13;
}

/// Named front-end noise levels (white current noise density at the TIA input).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoiseScene {
    /// No random noise (quantisation only).
    Quiet,
    /// The `paper` scene: a front end like the prototype's (small current, no filtering).
    Paper,
    /// The `bench` scene: the paper scene's current noise density 20 dB lower.
    Bench,
    /// A custom density in A/sqrt(Hz).
    Density(f64),
}

/// Current noise density of the `paper` scene in A/sqrt(Hz). Fixed once, for every method; see
/// `docs/physics.md` for how it was set (the paper method is reliable only below ~500 kPa).
pub const PAPER_NOISE_A_RTHZ: f64 = 1.0e-9;
/// Current noise density of the `bench` scene: 20 dB below the paper scene.
pub const BENCH_NOISE_A_RTHZ: f64 = PAPER_NOISE_A_RTHZ / 10.0;

impl NoiseScene {
    /// Density in A/sqrt(Hz).
    pub fn density_a_rthz(self) -> f64 {
        match self {
            NoiseScene::Quiet => 0.0,
            NoiseScene::Paper => PAPER_NOISE_A_RTHZ,
            NoiseScene::Bench => BENCH_NOISE_A_RTHZ,
            NoiseScene::Density(d) => d,
        }
    }
}

/// The analog-chain faults a power-on self-test must catch, each put on top of any scene
/// ([`Fault::apply`]): the stability catalogue's `open-pzt`, `shorted-pzt` and `dac-stuck`, and
/// the QEMU image's `sim fault ...` lines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// The PZT disconnected: no static capacitance, no motional branch.
    OpenPzt,
    /// The PZT shorted through 1 kOhm (a thousand times the plate's 1.3 uS at 1 kHz).
    ShortedPzt,
    /// The DAC output stuck at mid-scale: no drive.
    StuckDac,
    /// The sense-current ADC channel stuck at its upper rail.
    AdcRail,
}

impl Fault {
    /// Every fault.
    pub const ALL: [Fault; 4] = [
        Fault::OpenPzt,
        Fault::ShortedPzt,
        Fault::StuckDac,
        Fault::AdcRail,
    ];

    /// Short name (`sim fault <name>`).
    pub fn name(self) -> &'static str {
        match self {
            Fault::OpenPzt => "open",
            Fault::ShortedPzt => "short",
            Fault::StuckDac => "dac-stuck",
            Fault::AdcRail => "adc-rail",
        }
    }

    /// The fault of a [`name`](Self::name).
    pub fn from_name(name: &str) -> Option<Fault> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }

    /// `scene` with this fault.
    pub fn apply(self, mut scene: Scene) -> Scene {
        match self {
            Fault::OpenPzt => {
                scene.pzt.c0_f = 0.0;
                scene.pzt.force_factor_n_v = 0.0;
            }
            Fault::ShortedPzt => scene.pzt.leakage_s = 1e-3,
            Fault::StuckDac => scene.stuck_dac = Some(crate::frontend::MID_CODE),
            Fault::AdcRail => {
                scene.stuck_adc = Some(crate::frontend::StuckAdc {
                    channel: crate::frontend::AdcChannel::Current,
                    code: crate::frontend::MAX_CODE,
                })
            }
        }
        scene
    }
}

/// The builder methods of the scene's optional parts: `with_x(x: T);` is
/// `pub fn with_x(mut self, x: T) -> Self`, which sets the field `x` to `Some(x)`.
macro_rules! with_some {
    ($($(#[$doc:meta])* $name:ident($field:ident: $ty:ty);)*) => {
        $(
            $(#[$doc])*
            pub fn $name(mut self, $field: $ty) -> Self {
                self.$field = Some($field);
                self
            }
        )*
    };
}

/// Everything the simulator needs to build a probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scene {
    /// Probe mechanics and the fitted contact constants.
    pub mech: SensorMech,
    /// PZT plate.
    pub pzt: Pzt,
    /// Analog front end.
    pub front_end: FrontEnd,
    /// Preload and tip geometry.
    pub contact: Contact,
    /// Tissue under the tip, or `None` in free air.
    pub tissue: Option<Tissue>,
    /// Fault: the DAC output stuck at this code whatever it is sent.
    pub stuck_dac: Option<u16>,
    /// Fault: an ADC channel stuck at one code.
    pub stuck_adc: Option<crate::frontend::StuckAdc>,
    /// A second mechanical mode of the probe, or `None`.
    pub second_mode: Option<SecondMode>,
    /// Lift-off during the reading, or `None`.
    pub lift_off: Option<LiftOff>,
    /// A change of the contact force during the reading, or `None`.
    pub force_change: Option<crate::events::ForceChange>,
    /// Thermal drift of the free resonance during the reading, or `None`.
    pub drift: Option<Drift>,
    /// Random knocks, or `None`.
    pub knocks: Option<Knocks>,
    /// The load cell beside the resonator (it carries the contact force), or `None`: a probe
    /// without one.
    pub load_cell: Option<crate::loadcell::LoadCell>,
    /// A step in what is under the probe, or `None`.
    pub step: Option<Step>,
}

impl Scene {
    /// The probe in free air, quiet front end and load cell (no random noise).
    pub fn free_air() -> Self {
        Self {
            mech: SensorMech::default(),
            pzt: Pzt::default(),
            front_end: FrontEnd::default(),
            contact: Contact::default(),
            tissue: None,
            stuck_dac: None,
            stuck_adc: None,
            second_mode: None,
            lift_off: None,
            force_change: None,
            drift: None,
            knocks: None,
            load_cell: Some(crate::loadcell::LoadCell {
                noise_n: 0.0,
                ..crate::loadcell::LoadCell::default()
            }),
            step: None,
        }
    }
    /// Pressed at 30 mN onto `tissue`.
    pub fn on_tissue(tissue: Tissue) -> Self {
        Self {
            tissue: Some(tissue),
            ..Self::free_air()
        }
    }
    /// Pressed at 30 mN onto tissue of `modulus_kpa` (nu = 0.49, rho = 1000).
    pub fn on_modulus_kpa(modulus_kpa: f64) -> Self {
        Self::on_tissue(Tissue::with_modulus_kpa(modulus_kpa))
    }
    /// Pressed at 30 mN onto a phantom.
    pub fn on_phantom(p: &Phantom) -> Self {
        Self::on_tissue(p.tissue())
    }
    /// With a named noise level: the front end's current noise, and the load cell's own
    /// conversion noise (none in the quiet scene, the cell's data-sheet level in any other).
    pub fn with_noise(mut self, noise: NoiseScene) -> Self {
        self.front_end.current_noise_a_rthz = noise.density_a_rthz();
        if let Some(c) = self.load_cell.as_mut() {
            c.noise_n = match noise {
                NoiseScene::Quiet => 0.0,
                _ => crate::loadcell::LoadCell::default().noise_n,
            };
        }
        self
    }
    /// With mains interference.
    pub fn with_mains(mut self, mains: Mains) -> Self {
        self.front_end.mains = Some(mains);
        self
    }
    /// With the preload in N.
    pub fn with_preload_n(mut self, preload_n: f64) -> Self {
        self.contact.preload_n = preload_n;
        self
    }
    /// A known weight of `weight_n` newtons resting on the tip instead of tissue, as a load
    /// cell's sensitivity is taken: the weight sits on a steel stud (the "tissue" rigid, 200 GPa),
    /// the contact force is the weight.
    pub fn weighing(self, weight_n: f64) -> Self {
        Self {
            tissue: Some(Tissue::with_modulus_kpa(2.0e8)),
            ..self
        }
        .with_preload_n(weight_n)
    }
    /// With the tissue's viscoelastic loss tangent (no effect in free air).
    pub fn with_loss_tangent(mut self, loss_tangent: f64) -> Self {
        if let Some(t) = self.tissue.as_mut() {
            t.loss_tangent = loss_tangent;
        }
        self
    }
    with_some! {
        /// With a second mechanical mode.
        with_second_mode(second_mode: SecondMode);
        /// Lifted off during the reading.
        with_lift_off(lift_off: LiftOff);
        /// With the contact force changing during the reading.
        with_force_change(force_change: crate::events::ForceChange);
        /// With the free resonance drifting during the reading.
        with_drift(drift: Drift);
        /// With a step in what is under the probe.
        with_step(step: Step);
        /// With random knocks.
        with_knocks(knocks: Knocks);
    }

    /// True when the physics change during the reading (lift-off, drift, a step); knocks
    /// change the state, not the physics.
    pub fn is_time_varying(&self) -> bool {
        self.lift_off.is_some()
            || self.drift.is_some()
            || self.force_change.is_some()
            || self.step.is_some()
    }

    /// The static physics at `t_s` seconds after the reading started: the drift applied to the
    /// free resonance, the lift-off to the preload (and the tissue gone once the tip is off),
    /// and from a step on its tissue at the scene's preload (a lift-off that started before
    /// the step is over; one that starts after it lifts the probe off the new tissue).
    /// The time-varying parts stay in the result, so `at(t).at(t2)` is not meaningful; ask the
    /// scene at `t = 0` for anything else.
    pub fn at(&self, t_s: f64) -> Scene {
        let mut s = *self;
        if let Some(d) = &self.drift {
            s.mech.free_resonance_hz += d.rate_hz_s * t_s;
        }
        if let Some(c) = &self.force_change {
            s.contact.preload_n *= c.preload_fraction(t_s);
        }
        let stepped = self.step.filter(|st| t_s >= st.at_s);
        if let Some(st) = stepped {
            s.tissue = st.tissue;
        }
        // A lift-off applies unless a step came after it started (a new contact).
        if let Some(l) = self
            .lift_off
            .filter(|l| stepped.is_none_or(|st| l.at_s > st.at_s))
        {
            match l.preload_fraction(t_s) {
                Some(f) => s.contact.preload_n *= f,
                None => s.tissue = None,
            }
        }
        s
    }

    /// The force the tip presses on the tissue, N: the preload while there is tissue under it,
    /// zero in free air (what the load cell carries; at `t` ask `at(t)`).
    pub fn contact_force_n(&self) -> f64 {
        if self.tissue.is_some() {
            self.contact.preload_n.max(0.0)
        } else {
            0.0
        }
    }

    /// The one-degree-of-freedom mechanics of this scene.
    pub fn kelvin(&self) -> Kelvin {
        match &self.tissue {
            Some(t) => self.mech.loaded(t, &self.contact),
            None => self.mech.free(),
        }
    }
    /// True resonance (undamped natural frequency of the loaded mode) in Hz.
    pub fn resonance_hz(&self) -> f64 {
        self.kelvin().natural_frequency_hz()
    }
    /// Quality factor of the loaded mode.
    pub fn q(&self) -> f64 {
        self.kelvin().q()
    }
    /// Closed-form PZT admittance (S) at `freq_hz` (with the second motional branch, if any).
    pub fn admittance(&self, freq_hz: f64) -> C64 {
        let y = self.pzt.admittance(&self.kelvin(), freq_hz);
        match &self.second_mode {
            Some(m) => {
                let branch = Pzt {
                    c0_f: 0.0,
                    force_factor_n_v: m.force_factor_n_v,
                    leakage_s: 0.0,
                };
                y + branch.admittance(&m.kelvin(), freq_hz)
            }
            None => y,
        }
    }

    /// The layers this scene uses, in order; returns the count written into `out`.
    pub fn layers(&self, out: &mut [Layer; Layer::COUNT]) -> usize {
        let used: [(Layer, bool); Layer::COUNT] = [
            (Layer::Kelvin, true),
            (Layer::Contact, self.tissue.is_some()),
            (Layer::Pzt, true),
            (Layer::DielectricLoss, self.pzt.leakage_s > 0.0),
            (Layer::FrontEnd, true),
            (Layer::Noise, self.front_end.current_noise_a_rthz > 0.0),
            (Layer::Mains, self.front_end.mains.is_some()),
            (Layer::SecondMode, self.second_mode.is_some()),
            (Layer::LiftOff, self.lift_off.is_some()),
            (Layer::ForceChange, self.force_change.is_some()),
            (Layer::Drift, self.drift.is_some()),
            (Layer::Knocks, self.knocks.is_some()),
            (Layer::Step, self.step.is_some()),
        ];
        let mut n = 0;
        for (layer, _) in used.into_iter().filter(|&(_, on)| on) {
            out[n] = layer;
            n += 1;
        }
        n
    }
}
