//! The simulated probe's own commands: what the QEMU image's command script (from its boot
//! command line, or its built-in script) uses to put the probe on a scene — the bench's
//! `measure --qemu` and the QEMU tests pass their scene this way, and move the probe between
//! free air and phantoms in a session (air reference, calibration, readings).
//!
//! ```text
//! sim phantom B | sim modulus 300 | sim free-air      what the probe is on (30 mN preload)
//! sim preload 0.015                                    contact preload, N
//! sim loss 0.3                                         the tissue's loss tangent (after what it is on)
//! sim noise bench|paper|quiet|<A/sqrt(Hz)>             front-end noise
//! sim seed 7                                           noise stream (a fresh probe)
//! sim fault open|short|dac-stuck|adc-rail|none         an analog-chain fault (hal_sim::Fault)
//! sim boot-fault <code>|none                           a failed bring-up step (BootError code)
//! sim lift-off <t_s>                                   lifted off t_s after the scene starts
//! sim step <phantom>|free-air <t_s>                    what is under the tip changes t_s after it starts
//! sim press <fraction> <t_s>                           the preload steps to fraction of itself
//! ```
//!
//! The events (`lift-off`, `step`, `press`: hal-sim's `LiftOff`, `Step`, `ForceChange`) count
//! from the scene's start: the first batch after the next `sim` line puts the probe on its
//! scene (the next command starts 10 ms later). `sim phantom`, `modulus` and `free-air` clear
//! them. Each is a step, not a ramp: a ramp makes the simulated probe re-discretise its plant
//! every millisecond inside the QEMU image's sample interrupt, which then runs late (overruns;
//! the host's `probe-bench stream` has the ramps).
//!
//! A fault stays on whatever the probe is moved onto until `sim fault none`. A boot fault acts
//! only among the script's leading `sim` lines, which the board applies before it comes up:
//! the QEMU board then reports it as its boot error and, for one that leaves the STM32 without
//! its sample stream, does not start its stream either.
//!
//! Every other line is a probe command for the firmware's own parser, but `serve`: the script
//! ends there and the image serves the host link on its UART (`docs/protocol.md`) for ever
//! instead of exiting. The boot command line is a list of lines separated by `;`.

use crate::hal::FrontEndScale;
use crate::instrument::command::{parse, Command, CommandError, MAX_LINE};
use crate::instrument::link::Report;
use crate::instrument::tasks::CommandLink;
use hal_sim::events::{ForceChange, LiftOff, Step as TissueStep};
use hal_sim::{phantoms, Fault, NoiseScene, Scene};

/// What the simulated probe should become.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimState {
    /// What it is on, without noise and preload.
    pub base: Scene,
    /// Contact preload, N.
    pub preload_n: f64,
    /// Front-end noise.
    pub noise: NoiseScene,
    /// Noise stream.
    pub seed: u64,
    /// An analog-chain fault, or `None`.
    pub fault: Option<Fault>,
    /// A bring-up step the board is to report as failed (at boot only), or `None`.
    pub boot_fault: Option<crate::boot::BootError>,
    /// Lift-off, step and force change during the scene.
    pub events: SimEvents,
}

/// What happens during a scene (times from its start, s), kept small (the QEMU board copies
/// its state on the boot stack): resolved into hal-sim's events by [`SimState::scene`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimEvents {
    /// The probe is lifted off at this time (a step).
    pub lift_off_s: Option<f32>,
    /// What is under the tip changes at this time: a phantom's name, or `None` for free air.
    pub step: Option<(f32, Option<&'static str>)>,
    /// The contact force steps to this fraction of the preload at this time: (time, fraction).
    pub press: Option<(f32, f32)>,
}

impl SimState {
    /// The scene the probe is on.
    pub fn scene(&self) -> Scene {
        let mut s = self
            .base
            .with_noise(self.noise)
            .with_preload_n(self.preload_n);
        let e = &self.events;
        s.lift_off = e.lift_off_s.map(|at| LiftOff {
            at_s: at as f64,
            ramp_s: 0.0,
        });
        s.step = e.step.map(|(at, name)| TissueStep {
            at_s: at as f64,
            tissue: name.and_then(phantoms::by_name).map(|p| p.tissue()),
        });
        s.force_change = e.press.map(|(at, f)| ForceChange {
            at_s: at as f64,
            ramp_s: 0.0,
            to_fraction: f as f64,
        });
        match self.fault {
            Some(f) => f.apply(s),
            None => s,
        }
    }
}

/// Why a `sim` line is not understood.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimError {
    /// No such `sim` sub-command.
    Unknown,
    /// Its argument is missing, not a number, or out of range.
    BadArgument,
    /// No phantom of that name.
    UnknownPhantom,
}

impl SimError {
    /// One line for a human.
    pub fn message(self) -> &'static str {
        match self {
            SimError::Unknown => {
                "sim: phantom, modulus, free-air, preload, noise, seed, fault, boot-fault, lift-off, step or press"
            }
            SimError::BadArgument => "sim: argument missing or out of range",
            SimError::UnknownPhantom => "sim: unknown phantom",
        }
    }
}

fn number(w: Option<&str>, lo: f64, hi: f64) -> Result<f64, SimError> {
    let v: f64 = w
        .and_then(|w| w.parse().ok())
        .ok_or(SimError::BadArgument)?;
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(SimError::BadArgument)
    }
}

/// Apply `line` to `state` when it is a `sim` command: `Ok(true)` when it was one and applied,
/// `Ok(false)` when the line is not a `sim` command (a probe command), or why it is a bad one.
pub fn apply(line: &str, state: &mut SimState) -> Result<bool, SimError> {
    let mut words = line.split_whitespace();
    if words.next() != Some("sim") {
        return Ok(false);
    }
    let (what, arg) = (words.next(), words.next());
    // The two-argument lines: `step <what> <t_s>`, `press <fraction> <t_s>`.
    if matches!(what, Some("step" | "press")) {
        let at_s = number(words.next(), 0.0, 600.0)?;
        if words.next().is_some() {
            return Err(SimError::BadArgument);
        }
        if what == Some("step") {
            let name = match arg {
                Some("free-air") => None,
                a => Some(
                    a.and_then(phantoms::by_name)
                        .ok_or(SimError::UnknownPhantom)?
                        .name,
                ),
            };
            state.events.step = Some((at_s as f32, name));
        } else {
            state.events.press = Some((at_s as f32, number(arg, 0.01, 10.0)? as f32));
        }
        return Ok(true);
    }
    if words.next().is_some() {
        return Err(SimError::BadArgument);
    }
    if matches!(what, Some("phantom" | "modulus" | "free-air")) {
        state.events = SimEvents::default();
    }
    match what {
        Some("lift-off") => state.events.lift_off_s = Some(number(arg, 0.0, 600.0)? as f32),
        Some("phantom") => {
            let p = arg
                .and_then(phantoms::by_name)
                .ok_or(SimError::UnknownPhantom)?;
            state.base = Scene::on_phantom(&p);
        }
        Some("modulus") => state.base = Scene::on_modulus_kpa(number(arg, 1e-3, 1e6)?),
        Some("free-air") if arg.is_none() => state.base = Scene::free_air(),
        Some("preload") => state.preload_n = number(arg, 1e-4, 1.0)?,
        Some("loss") => state.base = state.base.with_loss_tangent(number(arg, 0.0, 2.0)?),
        Some("noise") => {
            state.noise = match arg {
                Some("bench") => NoiseScene::Bench,
                Some("paper") => NoiseScene::Paper,
                Some("quiet") => NoiseScene::Quiet,
                a => NoiseScene::Density(number(a, 0.0, 1e-3)?),
            }
        }
        Some("seed") => state.seed = number(arg, 0.0, 4e9)? as u64,
        Some("fault") => {
            state.fault = match arg {
                Some("none") => None,
                a => Some(a.and_then(Fault::from_name).ok_or(SimError::BadArgument)?),
            }
        }
        Some("boot-fault") => {
            state.boot_fault = match arg {
                Some("none") => None,
                a => Some(
                    a.and_then(crate::boot::BootError::from_code)
                        .ok_or(SimError::BadArgument)?,
                ),
            }
        }
        _ => return Err(SimError::Unknown),
    }
    Ok(true)
}

/// The lines of a script: separated by `;` or newlines, trimmed, empty ones left out.
pub fn lines(script: &str) -> impl Iterator<Item = &str> {
    script
        .split([';', '\n'])
        .map(str::trim)
        .filter(|l| !l.is_empty())
}

/// What one script line is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// A `sim` line, applied to the state: put the probe on its new scene.
    Sim,
    /// A probe command for the session.
    Command(Command),
    /// A bad `sim` line.
    BadSim(SimError),
    /// A line the firmware's parser refuses (as it would from the serial line).
    BadCommand(CommandError),
    /// `serve`: the script ends; the host link takes over.
    Serve,
}

/// The line that ends a script and hands the image to the host link.
pub const SERVE: &str = "serve";

/// One script line: a `sim` line applied to `state`, or a probe command parsed by the
/// firmware's own parser against `scale`.
pub fn step(line: &str, state: &mut SimState, scale: &FrontEndScale) -> Step {
    if line == SERVE {
        return Step::Serve;
    }
    match apply(line, state) {
        Ok(true) => Step::Sim,
        Err(e) => Step::BadSim(e),
        Ok(false) if line.len() > MAX_LINE => Step::BadCommand(CommandError::Oversized),
        Ok(false) => match parse(line.as_bytes(), scale) {
            Ok(c) => Step::Command(c),
            Err(e) => Step::BadCommand(e),
        },
    }
}

/// After a `sim` line the command task waits this long (ms) before the next line: two
/// batches, so that the sample interrupt has put the probe on its new scene and the next
/// command's reading starts after it (a hand presses, then asks), its force window not
/// straddling the change.
pub const SCENE_SETTLE_MS: u32 = 10;

/// What the command task does for the next line of a script (a [`Runner`]'s item).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Put the probe on [`Runner::sim`]'s scene, then wait [`SCENE_SETTLE_MS`].
    Sim,
    /// Send the command to the measurement task, wait for it to end and tell
    /// [`Runner::done`] how it did (false when it could not be sent).
    Send(Command),
    /// Report the refusal of a bad line (the run has failed already).
    Reject(&'static str),
    /// Serve the host link from now on (the script's last action).
    Serve,
}

/// The QEMU image's command script, line by line: `sim` lines move the simulated probe, the
/// others are parsed as host lines are and served one at a time. The run succeeds when the
/// power-on self-test and every request succeeded and no line was refused ([`Runner::ok`]).
pub struct Runner<I> {
    lines: I,
    sim: SimState,
    scale: FrontEndScale,
    ok: bool,
}

impl<'a, I: Iterator<Item = &'a str>> Runner<I> {
    /// A script's [`lines`] from the probe at `sim`, its commands parsed against `scale`.
    pub fn new(lines: I, sim: SimState, scale: FrontEndScale) -> Self {
        Self {
            lines,
            sim,
            scale,
            ok: true,
        }
    }

    fn reject(&mut self, message: &'static str) -> Action {
        self.ok = false;
        Action::Reject(message)
    }

    /// How a request (or the power-on self-test) ended.
    pub fn done(&mut self, ok: bool) {
        self.ok &= ok;
    }

    /// The probe as the `sim` lines so far have it.
    pub fn sim(&self) -> &SimState {
        &self.sim
    }

    /// True while everything has succeeded.
    pub fn ok(&self) -> bool {
        self.ok
    }
}

/// The actions of the script's lines, in order.
impl<'a, I: Iterator<Item = &'a str>> Iterator for Runner<I> {
    type Item = Action;

    fn next(&mut self) -> Option<Action> {
        let line = self.lines.next()?;
        Some(match step(line, &mut self.sim, &self.scale) {
            Step::Sim => Action::Sim,
            Step::Command(c) => Action::Send(c),
            Step::BadSim(e) => self.reject(e.message()),
            Step::BadCommand(e) => self.reject(e.message()),
            Step::Serve => Action::Serve,
        })
    }
}

/// The QEMU command task's links: the host link's ([`CommandLink`]) and the simulated probe.
#[allow(async_fn_in_trait)] // used with concrete types only, in one task
pub trait SimLink: CommandLink {
    /// Put the probe on `sim`'s scene (from the sample interrupt's next batch), then wait
    /// [`SCENE_SETTLE_MS`].
    async fn scene(&mut self, sim: &SimState);
}

/// How a script ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum End {
    /// Its lines ran out: the run succeeded iff this holds (the power-on self-test, every
    /// request and every line).
    Exit(bool),
    /// At `serve`: the host link takes over.
    Serve,
}

/// The QEMU command task's script from the probe at `sim`, its commands parsed against
/// `scale`: it first waits for the power-on self-test's outcome, then runs each line in turn,
/// waiting for each request to finish ([`Runner`]). At `serve`, `sim` is the probe as the
/// script's `sim` lines left it.
pub async fn run_script(
    link: &mut impl SimLink,
    script: &str,
    sim: &mut SimState,
    scale: FrontEndScale,
) -> End {
    let mut run = Runner::new(lines(script), *sim, scale);
    // After the power-on self-test (on the script's leading `sim` lines' scene).
    run.done(link.done().await.unwrap_or(false));
    while let Some(action) = run.next() {
        match action {
            Action::Sim => link.scene(run.sim()).await,
            Action::Send(c) => {
                let sent = link.request(c).await;
                run.done(sent && link.done().await.unwrap_or(false));
            }
            Action::Reject(message) => link.report(Report::Rejected(message)).await,
            Action::Serve => {
                *sim = *run.sim();
                return End::Serve;
            }
        }
    }
    End::Exit(run.ok())
}

/// A `sim` line from the host link ([`CommandLink::board_line`]), applied to `sim`: the probe
/// moved to its scene, or why the line is refused (the probe unmoved).
pub async fn sim_line(
    link: &mut impl SimLink,
    line: &str,
    sim: &mut SimState,
) -> Option<&'static str> {
    match apply(line, sim) {
        Ok(_) => {
            link.scene(sim).await;
            None
        }
        Err(e) => Some(e.message()),
    }
}

/// The host link's board lines on the simulated probe.
pub fn is_sim_line(line: &str) -> bool {
    line.starts_with("sim ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start() -> SimState {
        SimState {
            base: Scene::free_air(),
            preload_n: 0.03,
            noise: NoiseScene::Bench,
            seed: 1,
            fault: None,
            boot_fault: None,
            events: SimEvents::default(),
        }
    }

    #[test]
    fn serve_ends_the_script_and_hands_over_to_the_link() {
        let scale = FrontEndScale::PROBE;
        let run = Runner::new(lines("sim phantom B; serve; measure"), start(), scale);
        let actions: Vec<Action> = run.collect();
        assert_eq!(actions[..2], [Action::Sim, Action::Serve]);
        assert_eq!(
            step(" serve", &mut start(), &scale),
            Step::BadCommand(CommandError::UnknownCommand)
        );
        assert_eq!(step("serve", &mut start(), &scale), Step::Serve);
    }

    #[test]
    fn event_lines_set_the_scene_events_and_a_new_scene_clears_them() {
        let mut s = start();
        assert_eq!(apply("sim phantom C", &mut s), Ok(true));
        assert_eq!(apply("sim lift-off 1.5", &mut s), Ok(true));
        assert_eq!(apply("sim step D 0.5", &mut s), Ok(true));
        assert_eq!(apply("sim press 0.5 0.7", &mut s), Ok(true));
        let sc = s.scene();
        assert_eq!(sc.lift_off.map(|l| l.at_s), Some(1.5));
        assert_eq!(sc.step.map(|x| x.at_s), Some(0.5));
        assert_eq!(sc.step.and_then(|x| x.tissue), Some(phantoms::D.tissue()));
        assert_eq!(sc.force_change.map(|f| f.to_fraction), Some(0.5));
        assert_eq!(apply("sim step free-air 2", &mut s), Ok(true));
        assert_eq!(s.scene().step.map(|x| x.tissue), Some(None));
        for bad in [
            "sim lift-off",
            "sim lift-off -1",
            "sim step D",
            "sim step D 1 2",
            "sim press 0 1",
            "sim press x 1",
        ] {
            assert_eq!(apply(bad, &mut s), Err(SimError::BadArgument), "{bad}");
        }
        assert_eq!(apply("sim step Z 1", &mut s), Err(SimError::UnknownPhantom));
        assert_eq!(apply("sim phantom B", &mut s), Ok(true));
        assert_eq!(s.events, SimEvents::default());
    }

    #[test]
    fn a_boot_fault_line_names_a_boot_error() {
        use crate::boot::BootError;
        let mut s = start();
        assert_eq!(apply("sim boot-fault converter_hang", &mut s), Ok(true));
        assert_eq!(s.boot_fault, Some(BootError::ConverterHang));
        assert_eq!(
            apply("sim boot-fault melted", &mut s),
            Err(SimError::BadArgument)
        );
        assert_eq!(apply("sim boot-fault", &mut s), Err(SimError::BadArgument));
        assert_eq!(apply("sim boot-fault none", &mut s), Ok(true));
        assert_eq!(s.boot_fault, None);
    }

    #[test]
    fn sim_lines_set_the_scene_and_others_pass_through() {
        let mut s = start();
        assert_eq!(apply("measure", &mut s), Ok(false));
        assert_eq!(apply("sim phantom C", &mut s), Ok(true));
        assert_eq!(
            s.scene().resonance_hz(),
            Scene::on_phantom(&phantoms::C).resonance_hz()
        );
        assert_eq!(apply("sim preload 0.015", &mut s), Ok(true));
        assert_eq!(
            s.scene(),
            Scene::on_phantom(&phantoms::C)
                .with_noise(NoiseScene::Bench)
                .with_preload_n(0.015)
        );
        assert_eq!(apply("sim noise 2e-9", &mut s), Ok(true));
        assert_eq!(s.noise, NoiseScene::Density(2e-9));
        assert_eq!(apply("sim seed 42", &mut s), Ok(true));
        assert_eq!(s.seed, 42);
        assert_eq!(apply("sim free-air", &mut s), Ok(true));
        assert!(s.scene().tissue.is_none());
        // A fault stays on the next scene until `sim fault none`.
        for f in Fault::ALL {
            assert_eq!(
                apply(&std::format!("sim fault {}", f.name()), &mut s),
                Ok(true)
            );
            assert_eq!(
                s.scene(),
                f.apply(
                    Scene::free_air()
                        .with_noise(NoiseScene::Density(2e-9))
                        .with_preload_n(0.015)
                )
            );
        }
        assert_eq!(apply("sim phantom B", &mut s), Ok(true));
        assert_eq!(
            s.scene().stuck_adc.map(|a| a.code),
            Some(hal_sim::frontend::MAX_CODE)
        );
        assert_eq!(apply("sim fault none", &mut s), Ok(true));
        assert_eq!(s.fault, None);
    }

    #[test]
    fn a_script_steps_through_sim_lines_and_commands() {
        let scale = crate::board::sim::scale_of(&hal_sim::FrontEnd::default());
        let mut s = start();
        let got: std::vec::Vec<Step> = lines(" sim phantom B ;measure\n;; method nope ;sim x")
            .map(|l| step(l, &mut s, &scale))
            .collect();
        assert_eq!(
            got,
            [
                Step::Sim,
                Step::Command(Command::Measure),
                Step::BadCommand(CommandError::UnknownMethod),
                Step::BadSim(SimError::Unknown),
            ]
        );
        assert_eq!(s.base, Scene::on_phantom(&phantoms::B));
    }

    #[test]
    fn sim_phantom_finds_a_named_tissue_with_its_loss() {
        let scale = crate::board::sim::scale_of(&hal_sim::FrontEnd::default());
        let mut s = start();
        assert_eq!(
            step("sim phantom carcinoma-like", &mut s, &scale),
            Step::Sim
        );
        assert_eq!(s.base, Scene::on_phantom(&phantoms::CARCINOMA_LIKE));
        assert_eq!(s.base.tissue.map(|t| t.loss_tangent), Some(0.30));
        // `sim loss` after it overrides the tissue's own loss.
        assert_eq!(step("sim loss 0", &mut s, &scale), Step::Sim);
        assert_eq!(s.base.tissue.map(|t| t.loss_tangent), Some(0.0));
    }

    /// Runs `script` as the QEMU image's command task does, every request ending `served`:
    /// the actions, with the scene each `sim` line put the probe on, and the run's outcome.
    fn run(script: &str, booted: bool, served: bool) -> (std::vec::Vec<Action>, bool, SimState) {
        let scale = crate::board::sim::scale_of(&hal_sim::FrontEnd::default());
        let mut r = Runner::new(lines(script), start(), scale);
        r.done(booted);
        let mut actions = std::vec::Vec::new();
        while let Some(a) = r.next() {
            if let Action::Send(_) = a {
                r.done(served);
            }
            actions.push(a);
        }
        (actions, r.ok(), *r.sim())
    }

    #[test]
    fn the_runner_moves_the_probe_sends_commands_and_succeeds_when_all_did() {
        let (actions, ok, sim) = run("sim phantom C; sim seed 3;measure;\nstatus", true, true);
        assert_eq!(
            actions,
            [
                Action::Sim,
                Action::Sim,
                Action::Send(Command::Measure),
                Action::Send(Command::Status),
            ]
        );
        assert!(ok);
        assert_eq!((sim.base, sim.seed), (Scene::on_phantom(&phantoms::C), 3));
        // An empty script succeeds on the boot's outcome alone.
        assert_eq!(run(" ; ", true, true), (std::vec![], true, start()));
        assert!(!run("", false, true).1, "a failed self-test fails the run");
    }

    #[test]
    fn the_runner_fails_on_a_bad_line_or_a_failed_request_and_goes_on() {
        let (actions, ok, sim) = run("sim teleport;measure;method nope;sim free-air", true, true);
        assert_eq!(
            actions,
            [
                Action::Reject(SimError::Unknown.message()),
                Action::Send(Command::Measure),
                Action::Reject(CommandError::UnknownMethod.message()),
                Action::Sim,
            ]
        );
        assert!(!ok);
        assert!(
            sim.scene().tissue.is_none(),
            "the lines after a bad one still run"
        );
        assert!(!run("measure;status", true, false).1);
        let long = std::format!("measure {}", "x".repeat(MAX_LINE));
        assert_eq!(
            run(&long, true, true).0,
            [Action::Reject(CommandError::Oversized.message())]
        );
    }

    #[test]
    fn bad_sim_lines_are_refused_without_change() {
        let mut s = start();
        for (line, e) in [
            ("sim", SimError::Unknown),
            ("sim teleport", SimError::Unknown),
            ("sim phantom Z", SimError::UnknownPhantom),
            ("sim modulus -3", SimError::BadArgument),
            ("sim modulus nan", SimError::BadArgument),
            ("sim preload 5", SimError::BadArgument),
            ("sim noise loud", SimError::BadArgument),
            ("sim seed 1 2", SimError::BadArgument),
            ("sim free-air now", SimError::Unknown),
            ("sim fault", SimError::BadArgument),
            ("sim fault melted", SimError::BadArgument),
        ] {
            assert_eq!(apply(line, &mut s), Err(e), "{line}");
            assert_eq!(s, start(), "{line}");
        }
    }

    /// The command task's links as a script sees them: completions to hand out, what the
    /// task did, in order.
    #[derive(Default)]
    struct Script {
        done: std::collections::VecDeque<bool>,
        closed: bool,
        log: std::vec::Vec<std::string::String>,
    }

    impl CommandLink for Script {
        async fn byte(&mut self) -> Option<u8> {
            None
        }
        async fn request(&mut self, c: Command) -> bool {
            self.log.push(std::format!("request {c:?}"));
            !self.closed
        }
        fn has_room(&self) -> bool {
            true
        }
        fn try_request(&mut self, _: Command) -> bool {
            true
        }
        async fn done(&mut self) -> Option<bool> {
            self.done.pop_front()
        }
        fn try_done(&mut self) -> Option<bool> {
            None
        }
        async fn report(&mut self, r: Report) {
            self.log.push(std::format!("{r:?}"));
        }
    }

    impl SimLink for Script {
        async fn scene(&mut self, sim: &SimState) {
            self.log.push(std::format!("scene {}", sim.preload_n));
        }
    }

    fn script(link: &mut Script, text: &str) -> (End, SimState) {
        let mut sim = start();
        let end = run_script(link, text, &mut sim, FrontEndScale::PROBE);
        (crate::reading::driver::block_on(end), sim)
    }

    #[test]
    fn a_script_waits_for_the_selftest_and_each_request() {
        let mut link = Script {
            done: [true, true, true].into(),
            ..Default::default()
        };
        let (end, _) = script(&mut link, "sim preload 0.02; status; measure");
        assert_eq!(end, End::Exit(true));
        assert_eq!(
            link.log,
            ["scene 0.02", "request Status", "request Measure"]
        );
        assert!(link.done.is_empty(), "the self-test's and two requests'");

        // A failed self-test, a bad line (reported, the run goes on), then `serve` with the
        // probe as the lines left it.
        let mut link = Script {
            done: [false].into(),
            ..Default::default()
        };
        let (end, sim) = script(&mut link, "sim seed 9; sim nonsense; serve; measure");
        assert_eq!(end, End::Serve);
        assert_eq!(sim.seed, 9);
        assert_eq!(link.log.len(), 2);
        assert!(link.log[1].starts_with("Rejected(\"sim: phantom"));
    }

    #[test]
    fn a_request_that_cannot_be_sent_fails_the_run_without_a_wait() {
        let mut link = Script {
            done: [true, true].into(),
            closed: true,
            ..Default::default()
        };
        assert_eq!(script(&mut link, "status").0, End::Exit(false));
        assert_eq!(link.done, [true], "no completion waited for");
    }

    #[test]
    fn a_sim_line_from_the_host_moves_the_probe_or_is_refused() {
        let mut link = Script::default();
        let mut sim = start();
        assert!(is_sim_line("sim preload 0.01") && !is_sim_line("simulate"));
        use crate::reading::driver::block_on as block;
        assert_eq!(
            block(sim_line(&mut link, "sim preload 0.01", &mut sim)),
            None
        );
        assert_eq!(
            block(sim_line(&mut link, "sim preload 9", &mut sim)),
            Some(SimError::BadArgument.message())
        );
        assert_eq!(sim.preload_n, 0.01);
        assert_eq!(link.log, ["scene 0.01"]);
    }
}
