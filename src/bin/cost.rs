//! On-target cost of every estimation method: a QEMU-only image that counts the instructions
//! the Cortex-M4F build spends per sample and per reading.
//!
//! Built like the QEMU firmware image (`thumbv7em-none-eabihf`, profile `fw`, feature `qemu`,
//! so the same `opt-level = "z"` code generation as the STM32 image) and run on QEMU's
//! `mps2-an386` with `-icount shift=0,sleep=off`, where one guest instruction is one nanosecond
//! of virtual time: CMSDK timer 1 at 25 MHz then counts 40 instructions per tick
//! ([`board::stamp`], [`board::elapsed`]; ±40 per measured span). Run it with `cargo qemu-cost`;
//! `tests/qemu_cost.rs` runs it in CI and checks every figure against the budget.
//!
//! For every method of [`Method::ALL`] (with its default settings) and every modulus of
//! [`MODULI_KPA`], plus one reading of the `auto` strategy that has to fall back
//! ([`FALLBACK_KPA`]), it takes one reading of the simulated probe exactly as the firmware does:
//! the QEMU board's [`board::Stream`] plays each DAC batch through `hal-sim` and captures the
//! ADC batch with the firmware's two-batch latency, the [`SampleEngine`] demodulates and
//! generates, and the method's [`Procedure`] plans, accepts points and finishes. It counts,
//! separately,
//!
//! * **per sample**: the sample engine's work per batch (plan intake, `demodulate`,
//!   `generate`) — the sample interrupt's work without its channel hand-off — as mean and
//!   maximum over the reading's batches;
//! * **per reading**: every call of the measurement side, which runs at priority 1 in the
//!   firmware: `Procedure::new` (validation), `next_plan`, `accept` (point conversion, stage
//!   changes, intermediate fits), `is_complete` (for `auto` this runs the first stage's
//!   estimate) and `finish` (the estimator and the calibration mapping) — their sum, and the
//!   largest single call.
//!
//! The simulated plant (`hal-sim`'s exchange inside [`board::Stream::capture`]) is outside
//! every counted span. Nothing here runs in an interrupt: the image is one loop, so no other
//! work interleaves with a counted span.
//!
//! # Log lines (parsed by `tests/qemu_cost.rs`)
//!
//! ```text
//! budget core_hz=<u32> fs_hz=<f32> batch=<u32> budget_pct=<f32> unit=instructions
//! cost method=<str> e_kpa=<f32> status=<str> expect=<str> used=<str> e_read_kpa=<f32> probe_time_s=<f32> points=<u16> batches=<u32> engine_mean=<u32> engine_max=<u32> calls=<u32> reading=<u32> call_max=<u32> call_max_in=<str> sample_mean_pct=<f32> sample_max_pct=<f32> reading_pct=<f32> call_max_us=<f32>
//! fit case=<str> refs=<u16> ok=<bool> contact=<bool> instructions=<u64> ms=<f32> bound_ms=<f32>
//! exit ok=<bool>
//! ```
//!
//! `engine_mean`/`engine_max` are instructions per batch of `batch` samples; `reading` is the
//! sum over all measurement calls of the reading and `call_max` the largest one (in
//! `call_max_in`: `new`, `next_plan`, `accept`, `is_complete` or `finish`). The percentages are
//! of a `core_hz` core, counting one cycle per instruction: per sample at `fs_hz`, per reading
//! over the reading's probe time; `call_max_us` is the largest call in microseconds at
//! `core_hz`. `expect` is the status the reading must end in (`ok`, or the failure code of the
//! fallback case); the image exits with success iff every reading ended as expected.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg(all(target_os = "none", not(feature = "qemu")))]
compile_error!(
    "the cost image runs on QEMU only: build it with --no-default-features --features qemu"
);

#[cfg(all(target_os = "none", feature = "qemu"))]
use pzt_probe::board::qemu as board;

// The defmt logger, the panic handlers and the HardFault handler are the QEMU board's
// (`pzt_probe::board::qemu`): a panic or a fault ends the run with failure.

#[cfg(all(target_os = "none", feature = "qemu"))]
mod harness {
    //! The measuring loop.

    use crate::board;
    use core::cell::RefCell;
    use core::sync::atomic::{compiler_fence, Ordering};
    use hal_sim::{NoiseScene, Scene, SimProbe};
    use pzt_probe::engine::sweep::SweepPoint;
    use pzt_probe::engine::BATCH;
    use pzt_probe::engine::{PointPlan, PointRaw, Points, SampleEngine};
    use pzt_probe::hal::{FrontEndScale, StreamError};
    use pzt_probe::loadcell::{ForceLog, RawForce};
    use pzt_probe::reading::driver::{block_on, drive, BatchSource, Plans, PointSource};
    use pzt_probe::reading::{Measurement, Procedure};
    use pzt_probe::unit::profile::UnitProfile;
    use pzt_probe::{Failure, Method, Reading, Seconds, Status};

    /// Core clock the budget is stated for: the STM32G474 at 170 MHz.
    pub const CORE_HZ: u32 = 170_000_000;
    /// The budget: this share of the core, per sample and per reading (percent).
    pub const BUDGET_PCT: f32 = 2.0;
    /// Moduli every method reads (kPa): soft, middle and hard end of the calibrated range.
    pub const MODULI_KPA: [f32; 3] = [200.0, 500.0, 2500.0];
    /// A modulus below the band, where `auto`'s hold and fit find no resonance and it falls back to
    /// sweep-G (whose answer there is `out_of_band`): the strategy's most expensive path.
    pub const FALLBACK_KPA: f32 = 60.0;
    /// Noise stream of every reading (the QEMU firmware image uses the same).
    pub const SEED: u64 = 1;

    /// One reading to measure: method, modulus and the status it must end in.
    #[derive(Clone, Copy)]
    pub struct Case {
        /// The method, with its default settings.
        pub method: Method,
        /// Modulus of the simulated tissue (bench noise).
        pub e_kpa: f32,
        /// The status code the reading must end in.
        pub expect: &'static str,
    }

    /// Which measurement call a span was.
    #[derive(Clone, Copy, PartialEq, Eq)]
    pub enum Call {
        /// `Procedure::new`.
        New,
        /// `Plans::next_plan`.
        NextPlan,
        /// `Plans::accept`.
        Accept,
        /// `Plans::is_complete`.
        IsComplete,
        /// `Measurement::finish`.
        Finish,
    }

    impl Call {
        /// Name in the log.
        pub const fn name(self) -> &'static str {
            match self {
                Call::New => "new",
                Call::NextPlan => "next_plan",
                Call::Accept => "accept",
                Call::IsComplete => "is_complete",
                Call::Finish => "finish",
            }
        }
    }

    /// Instruction counts of one reading.
    pub struct Cost {
        /// Batches the engine ran.
        pub batches: u32,
        /// Sum of the engine's instructions over those batches.
        pub engine_sum: u64,
        /// Largest engine batch.
        pub engine_max: u32,
        /// Measurement calls.
        pub calls: u32,
        /// Sum of the measurement calls' instructions.
        pub reading: u64,
        /// Largest single measurement call.
        pub call_max: u32,
        /// Which call that was.
        pub call_max_in: Call,
        /// Instructions per kind of call, indexed by `Call as usize` (declaration order).
        pub split: [u64; 5],
        /// The simulated plant's instructions (the stream's exchange and the load cell): not the
        /// firmware's work, counted only to be left out of a stream's.
        pub plant: u64,
    }

    impl Cost {
        const fn new() -> Self {
            Self {
                batches: 0,
                engine_sum: 0,
                engine_max: 0,
                calls: 0,
                reading: 0,
                call_max: 0,
                call_max_in: Call::New,
                split: [0; 5],
                plant: 0,
            }
        }

        /// Run `f` as one measurement call of kind `call` and count it.
        fn call<R>(&mut self, call: Call, f: impl FnOnce() -> R) -> R {
            compiler_fence(Ordering::SeqCst);
            let t0 = board::stamp();
            compiler_fence(Ordering::SeqCst);
            let r = core::hint::black_box(f());
            compiler_fence(Ordering::SeqCst);
            let n = board::elapsed(t0);
            compiler_fence(Ordering::SeqCst);
            self.calls += 1;
            self.reading += n as u64;
            self.split[call as usize] += n as u64;
            if n > self.call_max {
                self.call_max = n;
                self.call_max_in = call;
            }
            r
        }

        fn batch(&mut self, n: u32) {
            self.batches += 1;
            self.engine_sum += n as u64;
            self.engine_max = self.engine_max.max(n);
        }

        fn engine_mean(&self) -> u32 {
            (self.engine_sum / self.batches.max(1) as u64) as u32
        }
    }

    /// Percent of a [`CORE_HZ`] core that `instructions` per sample take at `fs_hz`.
    fn per_sample_pct(instructions_per_batch: u32, fs_hz: f32) -> f32 {
        instructions_per_batch as f32 / BATCH as f32 * fs_hz / CORE_HZ as f32 * 100.0
    }

    /// A point did not arrive within its sample budget.
    struct Stalled;

    /// The sample interrupt's work against the simulated stream, batch by batch, with the
    /// engine's instructions counted (the plant's are not): plan intake, demodulation, DAC
    /// refill — the firmware's `sample` task.
    struct CostSource<'a> {
        stream: board::Stream,
        engine: SampleEngine,
        intake: Option<PointPlan>,
        cost: &'a RefCell<Cost>,
        /// The board's load cell, read after every batch as the firmware's load-cell task
        /// reads it (not counted: it is not the reading's work).
        load_cell: Option<board::LoadCell>,
        forces: ForceLog,
        /// A second window that closed in the batch of the one `next` returned.
        held: Option<PointRaw>,
    }

    impl BatchSource for CostSource<'_> {
        /// One batch: the plant plays the DAC batch and fills the ADC batch, the load cell is
        /// read (neither counted), then the engine's counted work — plan intake, demodulation,
        /// DAC refill.
        fn batch(&mut self) -> Result<Option<Points>, StreamError> {
            compiler_fence(Ordering::SeqCst);
            let p0 = board::stamp();
            compiler_fence(Ordering::SeqCst);
            let (adc, dac) = self.stream.capture();
            if let Some(Ok(Some(c))) = self.load_cell.as_mut().map(|hx| hx.read()) {
                self.forces.push(self.engine.samples(), c);
            }
            compiler_fence(Ordering::SeqCst);
            self.cost.borrow_mut().plant += board::elapsed(p0) as u64;
            compiler_fence(Ordering::SeqCst);
            let t0 = board::stamp();
            compiler_fence(Ordering::SeqCst);
            if let Some(p) = self.intake.take() {
                self.engine.load(p);
            }
            let points = self.engine.demodulate(adc);
            self.engine.generate(dac);
            compiler_fence(Ordering::SeqCst);
            self.cost.borrow_mut().batch(board::elapsed(t0));
            compiler_fence(Ordering::SeqCst);
            Ok(Some(points))
        }
        fn held(&mut self) -> &mut Option<PointRaw> {
            &mut self.held
        }
    }

    impl PointSource for CostSource<'_> {
        fn scale(&self) -> FrontEndScale {
            self.stream.scale()
        }
        fn now_sample(&self) -> u64 {
            self.engine.samples()
        }
        async fn load(&mut self, plan: PointPlan) -> bool {
            self.intake = Some(plan);
            true
        }
        // The driver's window wait, stop and idle over the counted batches.
        pzt_probe::batch_source_waits!(engine);
        fn contact_force(&mut self, from: u64, to: u64) -> Option<RawForce> {
            self.forces.over(from, to, self.scale().sample_rate.0)
        }
    }

    /// A measurement whose every call is counted.
    struct Counted<'a, M> {
        m: M,
        cost: &'a RefCell<Cost>,
    }

    impl<M: Measurement> Plans for Counted<'_, M> {
        fn next_plan(&mut self) -> Option<PointPlan> {
            let m = &mut self.m;
            self.cost
                .borrow_mut()
                .call(Call::NextPlan, || m.next_plan())
        }
        fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint> {
            let m = &mut self.m;
            self.cost.borrow_mut().call(Call::Accept, || m.accept(raw))
        }
        fn is_complete(&self) -> bool {
            self.cost
                .borrow_mut()
                .call(Call::IsComplete, || self.m.is_complete())
        }
    }

    impl<M: Measurement> Measurement for Counted<'_, M> {
        fn finish(&self, unit: &UnitProfile, force: Option<RawForce>) -> Reading {
            self.cost
                .borrow_mut()
                .call(Call::Finish, || self.m.finish(unit, force))
        }
    }

    /// One reading of `case` through the one reading driver ([`drive`]), counted into `cost`.
    fn read(case: &Case, unit: &UnitProfile, cost: &RefCell<Cost>) -> Result<Reading, Stalled> {
        let scene = Scene::on_modulus_kpa(case.e_kpa as f64).with_noise(NoiseScene::Bench);
        let mut src = CostSource {
            stream: board::Stream::new(SimProbe::new(scene, SEED)),
            engine: SampleEngine::new(),
            intake: None,
            held: None,
            cost,
            load_cell: board::load_cell(),
            forces: ForceLog::new(),
        };
        src.stream.prefill(&mut src.engine);
        let (method, settings) = (case.method, case.method.default_settings());
        let (scale, start) = (src.scale(), src.now_sample());
        let m = cost.borrow_mut().call(Call::New, || {
            Procedure::new(method, &settings, &scale, start, unit)
        });
        let Ok(m) = m else {
            return Ok(Reading::failed(
                method,
                Failure::BadSettings,
                Seconds(0.0),
                0,
            ));
        };
        let mut m = Counted { m, cost };
        let mut stalled = false;
        let r = block_on(drive(
            &mut src,
            &mut m,
            method,
            unit,
            |_, _| {},
            |_| stalled = true,
        ));
        if stalled {
            Err(Stalled)
        } else {
            Ok(r)
        }
    }

    fn nan_or(v: Option<f32>) -> f32 {
        v.unwrap_or(f32::NAN)
    }

    /// Measure one case and log its line; true when it ended as expected.
    fn measure(case: &Case, unit: &UnitProfile, fs: f32) -> bool {
        let cell = RefCell::new(Cost::new());
        let (reading, status) = match read(case, unit, &cell) {
            Ok(r) => (Some(r), r.status.code()),
            Err(Stalled) => (None, "stalled"),
        };
        let cost = cell.into_inner();
        let probe_time = reading.map_or(0.0, |r| r.probe_time.0);
        let reading_pct = if probe_time > 0.0 {
            cost.reading as f32 / (probe_time * CORE_HZ as f32) * 100.0
        } else {
            f32::NAN
        };
        defmt::info!(
            "cost method={=str} e_kpa={=f32} status={=str} expect={=str} used={=str} e_read_kpa={=f32} probe_time_s={=f32} points={=u16} batches={=u32} engine_mean={=u32} engine_max={=u32} calls={=u32} reading={=u32} call_max={=u32} call_max_in={=str} sample_mean_pct={=f32} sample_max_pct={=f32} reading_pct={=f32} call_max_us={=f32}",
            case.method.name(),
            case.e_kpa,
            status,
            case.expect,
            reading.map_or("none", |r| r.method.name()),
            nan_or(reading.and_then(|r| r.modulus.map(|v| v.0))),
            probe_time,
            reading.map_or(0, |r| r.points),
            cost.batches,
            cost.engine_mean(),
            cost.engine_max,
            cost.calls,
            cost.reading.min(u32::MAX as u64) as u32,
            cost.call_max,
            cost.call_max_in.name(),
            per_sample_pct(cost.engine_mean(), fs),
            per_sample_pct(cost.engine_max, fs),
            reading_pct,
            cost.call_max as f32 / (CORE_HZ as f32 / 1e6)
        );
        let [new, next_plan, accept, is_complete, finish] =
            cost.split.map(|n| n.min(u32::MAX as u64) as u32);
        defmt::info!(
            "split method={=str} e_kpa={=f32} new={=u32} next_plan={=u32} accept={=u32} is_complete={=u32} finish={=u32}",
            case.method.name(),
            case.e_kpa,
            new,
            next_plan,
            accept,
            is_complete,
            finish
        );
        status == case.expect
    }

    /// The continuous tracker's settings whose work the image measures: (name, segment s,
    /// segments a plan) — the default and the fast setting (`probe_bench::pareto::FAST_STREAM`).
    pub const STREAM_CASES: [(&str, f32, u8); 2] = [("default", 0.03, 1), ("fast", 0.012, 4)];
    /// Modulus and probe time of each measured stream.
    pub const STREAM_KPA: f32 = 500.0;
    /// Probe time of each measured stream, s (the acquisition, then tracking).
    pub const STREAM_SECONDS: f32 = 1.0;

    /// Stream [`STREAM_KPA`] with the tracker's setting `(name, segment, plan_segments)` through
    /// the firmware's loop (`continuous::run_with`) and log the measurement side's work from the
    /// first tracking reading to the last: everything but the engine's (counted per sample) and
    /// the plant's, as a share of a [`CORE_HZ`] core over that probe time. True when every
    /// tracking reading was ok.
    pub fn stream_cost(case: (&str, f32, u8), unit: &UnitProfile) -> bool {
        use pzt_probe::instrument::continuous::{run_with, TrackerConfig};
        let cell = RefCell::new(Cost::new());
        let scene = Scene::on_modulus_kpa(STREAM_KPA as f64).with_noise(NoiseScene::Bench);
        let mut src = CostSource {
            stream: board::Stream::new(SimProbe::new(scene, SEED)),
            engine: SampleEngine::new(),
            intake: None,
            held: None,
            cost: &cell,
            load_cell: board::load_cell(),
            forces: ForceLog::new(),
        };
        src.stream.prefill(&mut src.engine);
        let cfg = TrackerConfig {
            segment: Seconds(case.1),
            plan_segments: case.2,
            ..TrackerConfig::DEFAULT
        };
        let Ok(mut tracker) = cfg.validate(&src.scale(), unit) else {
            return false;
        };
        // At the first tracking reading and at the last: (stamp, engine + plant instructions,
        // probe time s).
        let mut first: Option<(u32, u64, f32)> = None;
        let mut last = (0u32, 0u64, 0.0f32);
        let (mut readings, mut ok) = (0u32, 0u32);
        block_on(run_with(&mut src, &mut tracker, unit, |s, r| {
            compiler_fence(Ordering::SeqCst);
            let now = board::stamp();
            let c = s.cost.borrow();
            let at = (now, c.engine_sum + c.plant, r.t_s.0);
            if r.seq > 0 {
                if first.is_none() {
                    first = Some(at);
                } else {
                    readings += 1;
                    ok += r.reading.status.is_ok() as u32;
                }
                last = at;
            }
            r.t_s.0 < STREAM_SECONDS
        }));
        let Some(first) = first else {
            return false;
        };
        // The timer counts down: instructions from `first` to `last`.
        let total = first.0.wrapping_sub(last.0) as u64 * board::INSTRUCTIONS_PER_TICK as u64;
        let work = total.saturating_sub(last.1 - first.1);
        let probe_time = last.2 - first.2;
        let work_pct = work as f32 / (probe_time * CORE_HZ as f32) * 100.0;
        defmt::info!(
            "stream setting={=str} e_kpa={=f32} readings={=u32} ok={=u32} probe_time_s={=f32} work={=u64} work_pct={=f32}",
            case.0,
            STREAM_KPA,
            readings,
            ok,
            probe_time,
            work,
            work_pct
        );
        readings > 0 && ok == readings
    }

    /// One `calibrate fit` to measure: how many references, and how they lie.
    #[derive(Clone, Copy)]
    pub struct FitCase {
        /// Name in the log line.
        pub name: &'static str,
        /// References, each on its own modulus.
        pub refs: usize,
        /// False: on the unit's own curve (±0.3 Hz); true: scattered, so that no curve fits
        /// and the Levenberg–Marquardt loops run to their iteration bounds.
        pub scattered: bool,
        /// True: every reading at its own force (the set force ±3 %, as a load cell measures
        /// it), so that no two readings share a modulus and a force.
        pub measured_forces: bool,
    }

    /// The `calibrate fit` cases: the QEMU session test's five moduli (twice each, as it adds
    /// them), the session's most references ([`pzt_probe::instrument::session::MAX_REFERENCES`]) on as
    /// many distinct moduli — every one held out in turn —, on the curve and scattered, and a
    /// unit's factory calibration: A–E × 20 (100 references, `probe-bench calibrate --repeats
    /// 20`) at the calibration's forces, set and measured.
    pub const FIT_CASES: [FitCase; 6] = [
        FitCase {
            name: "five-moduli",
            refs: 10,
            scattered: false,
            measured_forces: false,
        },
        FitCase {
            name: "sixteen-on-curve",
            refs: 16,
            scattered: false,
            measured_forces: false,
        },
        FitCase {
            name: "max-on-curve",
            refs: pzt_probe::instrument::session::MAX_REFERENCES,
            scattered: false,
            measured_forces: false,
        },
        FitCase {
            name: "max-scattered",
            refs: pzt_probe::instrument::session::MAX_REFERENCES,
            scattered: true,
            measured_forces: false,
        },
        FitCase {
            name: "factory-100",
            refs: 100,
            scattered: false,
            measured_forces: false,
        },
        FitCase {
            name: "factory-100-measured",
            refs: 100,
            scattered: false,
            measured_forces: true,
        },
    ];

    /// Measure one `calibrate fit` ([`pzt_probe::unit::profile::calibrate`] with the unit's air
    /// reference, as the session calls it) and log its line; true when it took at most half
    /// the watchdog promise made for it ([`pzt_probe::instrument::watchdog::fit_bound`]).
    pub fn fit_cost(case: &FitCase, unit: &UnitProfile) -> bool {
        use pzt_probe::unit::profile::{calibrate, Reference};
        let mut refs: heapless::Vec<Reference, { pzt_probe::unit::calibration::MAX_REFERENCES }> =
            heapless::Vec::new();
        let q_model = unit.q_model;
        for i in 0..case.refs {
            // 10 references: the session test's five moduli, two readings each; 100: A–E, 20
            // readings each; otherwise one reading per modulus, log-spaced over 100–3000 kPa.
            let e = if case.refs == 10 {
                [157.5, 279.0, 414.0, 1146.0, 2465.0][i / 2]
            } else if case.refs == 100 {
                [157.5, 279.0, 414.0, 1146.0, 2465.0][i / 20]
            } else {
                100.0 * libm::pow(30.0, i as f64 / (case.refs - 1) as f64)
            };
            // Pressed in turn at the calibration's forces (30, 15, 50 mN), as a unit with a load
            // cell is calibrated.
            let forces = pzt_probe::board::sim::CALIBRATION_FORCES;
            let force = forces[i % forces.len()]
                * if case.measured_forces {
                    1.0 + 0.03 * libm::sin(i as f64)
                } else {
                    1.0
                };
            let f = match unit.contact {
                Some(c) => c.frequency_at(e, force),
                None => unit.calibration.frequency(e),
            };
            // Alternately above and below the curve: by 0.3 Hz, and when scattered every third
            // reading by 30 Hz more.
            let up = if i % 2 == 0 { 1.0 } else { -1.0 };
            let off = if case.scattered && i % 3 == 0 {
                30.0
            } else {
                0.0
            };
            let _ = refs.push(Reference {
                modulus_kpa: e,
                resonance_hz: f + up * 0.3 + up * off,
                sigma_hz: 0.2,
                q: q_model.map_or(20.0, |q| q.q_at(e, Some(force), unit.contact.as_ref())),
                force_n: force,
            });
        }
        compiler_fence(Ordering::SeqCst);
        let t0 = board::stamp();
        let r = calibrate(&refs, unit.air.as_ref());
        let n = board::elapsed_long(t0);
        compiler_fence(Ordering::SeqCst);
        let ms = n as f32 / (CORE_HZ as f32 / 1e3);
        let bound = pzt_probe::instrument::watchdog::fit_bound(case.refs).0 as f32;
        defmt::info!(
            "fit case={=str} refs={=u16} ok={=bool} contact={=bool} instructions={=u64} ms={=f32} bound_ms={=f32}",
            case.name,
            case.refs as u16,
            r.is_ok(),
            r.as_ref().is_ok_and(|c| c.contact.is_some()),
            n,
            ms,
            bound
        );
        2.0 * ms <= bound
    }

    /// The image: every case in turn, then exit with success iff all ended as expected.
    #[cortex_m_rt::entry]
    fn main() -> ! {
        board::start_stamp_clock();
        let fs = board::scale().sample_rate.0;
        defmt::info!(
            "budget core_hz={=u32} fs_hz={=f32} batch={=u32} budget_pct={=f32} unit={=str}",
            CORE_HZ,
            fs,
            BATCH as u32,
            BUDGET_PCT,
            board::ELAPSED_UNIT
        );
        // The simulated unit's factory profile, as the QEMU image's store holds it.
        let Some(unit) = pzt_probe::board::sim_factory::profile() else {
            defmt::error!("factory record corrupt");
            board::exit(false)
        };
        let mut ok = true;
        for &e_kpa in MODULI_KPA.iter() {
            for method in Method::ALL {
                // The factory profile maps the motional resonance (it was calibrated with
                // auto): paper's |Z| dip is refused as uncalibrated, after the same work.
                let expect = if method.resonance() == unit.resonance {
                    Status::Ok
                } else {
                    Status::Failed(Failure::Uncalibrated)
                };
                let case = Case {
                    method,
                    e_kpa,
                    expect: expect.code(),
                };
                ok &= measure(&case, &unit, fs);
            }
        }
        let fallback = Case {
            method: Method::Auto,
            e_kpa: FALLBACK_KPA,
            expect: Status::Failed(Failure::OutOfBand).code(),
        };
        ok &= measure(&fallback, &unit, fs);
        for case in FIT_CASES.iter() {
            ok &= fit_cost(case, &unit);
        }
        for case in STREAM_CASES {
            ok &= stream_cost(case, &unit);
        }
        defmt::info!("exit ok={=bool}", ok);
        board::exit(ok)
    }
}
