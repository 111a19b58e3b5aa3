//! The STM32 image that `cargo fw` builds, run from reset on the emulated NUCLEO-G474RE with
//! hal-sim's probe at the pins; its defmt log read from RTT and decoded by `defmt-print`.
//!
//! Needs the `thumbv7em-none-eabihf` target, flip-link and defmt-print (scripts/setup); without
//! them the test fails naming what is missing (it never passes by skipping).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Stdio;

use stm32_emu::elf::Elf;
use stm32_emu::probe::HalSimProbe;
use stm32_emu::{rtt, Exit, Machine};

#[path = "../../tests/support/image_tools.rs"]
mod image_tools;
use image_tools::{cargo_firmware, defmt_print};

#[path = "../../tests/support/log_fields.rs"]
mod log_fields;
use log_fields::{all, fields, first, last, num};

const TARGET: &str = "thumbv7em-none-eabihf";

/// Build the STM32 image as `cargo fw` does, into the tests' own target directory.
fn build_image() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let target_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("stm32-image");
    let status = cargo_firmware(root, &target_dir, &["fw"]);
    assert!(
        status.success(),
        "`cargo fw` failed (scripts/setup installs the target and flip-link)"
    );
    target_dir.join(TARGET).join("fw").join("probe")
}

/// Decode RTT bytes with `defmt-print` against `elf`: `LEVEL message` lines.
fn decode(elf: &Path, bytes: &[u8]) -> Vec<String> {
    let mut p = defmt_print(elf)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start defmt-print (cargo install defmt-print --locked; scripts/setup)");
    p.stdin.take().unwrap().write_all(bytes).unwrap();
    let out = p.wait_with_output().expect("defmt-print");
    assert!(out.status.success(), "defmt-print failed");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(str::to_owned)
        .collect()
}

/// What happens to the board at a time: a line typed on the virtual COM port, the probe moved
/// (to the scene of that name, [`HalSimProbe::scene_named`]), the reset button, a fault injected into
/// the board (a peripheral's state set; at time 0, before the first instruction).
#[derive(Clone, Copy, Debug)]
enum Event {
    Send(&'static str),
    Scene(&'static str),
    Reset,
    Fault(fn(&mut Machine)),
}

/// The scene called `name` ([`HalSimProbe::scene_named`]: `B`, `B@8`, `free-air`, `weight:10`).
fn scene(name: &str) -> hal_sim::Scene {
    HalSimProbe::scene_named(name).unwrap_or_else(|| panic!("no scene {name}"))
}

/// A run of the image: the board as it ended and the decoded log.
struct Run {
    m: Machine,
    lines: Vec<String>,
}

impl Run {
    /// The log's lines as (name, fields).
    fn parsed(&self) -> Vec<log_fields::Fields> {
        self.lines.iter().filter_map(|l| fields(l)).collect()
    }

    /// The RM0440 rules the image broke.
    fn rules(&self) -> Vec<String> {
        let v = &self.m.board().periph.violations;
        v.iter().map(|v| v.rule.clone()).collect()
    }

    /// True when a `boot` line names the boot-step fault `fault`.
    fn booted_with(&self, fault: &str) -> bool {
        all(&self.parsed(), "boot")
            .iter()
            .any(|f| f.get("fault").map(String::as_str) == Some(fault))
    }
}

/// Run `elf` for `seconds` of emulated time with hal-sim's probe on `on` (noise seed 1) and
/// `events` (time s, event) applied in order, draining RTT every [`rtt::DRAIN_CYCLES`]; panics
/// when the board faults. Prints the wall time, the rules broken and the log but for the sweep
/// points.
fn run(elf: &Path, seconds: f64, on: hal_sim::Scene, events: &[(f64, Event)]) -> Run {
    let bytes = std::fs::read(elf).unwrap();
    let image = Elf::parse(&bytes).unwrap();
    let cb = image.symbol("_SEGGER_RTT").expect("_SEGGER_RTT");
    let mut m = Machine::new(&image).unwrap();
    m.board_mut().periph.wiring = Box::new(HalSimProbe::new(on, 1));
    let wall = std::time::Instant::now();
    let mut log = Vec::new();
    let mut pending = events.to_vec();
    while m.seconds() < seconds {
        while pending.first().is_some_and(|(t, _)| *t <= m.seconds()) {
            match pending.remove(0).1 {
                Event::Send(text) => {
                    m.send_command(text).expect("a command frame");
                }
                Event::Scene(name) => {
                    HalSimProbe::at_pins(&mut m).unwrap().set_scene(scene(name));
                }
                Event::Reset => m.system_reset(stm32_emu::periph::ResetCause::Pin).unwrap(),
                Event::Fault(set) => set(&mut m),
            }
        }
        let exit = m.run_until(m.cycles() + rtt::DRAIN_CYCLES);
        log.extend(rtt::drain(&mut m, cb).unwrap_or_default());
        if let Exit::Fault(f) = exit {
            panic!("the emulated board stopped at {:.6} s: {f}", m.seconds());
        }
    }
    println!(
        "{seconds} s emulated in {:.2} s wall",
        wall.elapsed().as_secs_f64()
    );
    for v in &m.board().periph.violations {
        println!("rule broken at cycle {}: {}", v.at, v.rule);
    }
    let lines = decode(elf, &log);
    for l in lines.iter().filter(|l| !l.contains(" point ")) {
        println!("{l}");
    }
    Run { m, lines }
}

/// The image built once, run on phantom B for `seconds` with `fault` injected at `fault_at` s
/// and then the command `send` (time s, line): a fault the bring-up or a session must survive.
fn run_faulted(
    seconds: f64,
    fault_at: f64,
    fault: fn(&mut Machine),
    send: Option<(f64, &'static str)>,
) -> Run {
    let elf = build_image();
    let mut events = vec![(fault_at, Event::Fault(fault))];
    events.extend(send.map(|(t, line)| (t, Event::Send(line))));
    run(&elf, seconds, scene("B"), &events)
}

#[test]
fn stm32_image_boots_and_passes_its_self_test_on_phantom_b() {
    let elf = build_image();
    let run = run(&elf, 3.0, scene("B"), &[(1.0, Event::Send("measure"))]);
    // RM0440's sequences (the emulator's rule checks), the range 1 boost switch among them:
    // none broken.
    let rules = run.rules();
    assert!(rules.is_empty(), "rules broken: {rules:?}");
    // The clocks the rates come from, after the switch (RM0440 RCC, TIM6, LPUART): HCLK
    // 170 MHz, TIM6's update every 17 000 of its cycles (10 kHz), LPUART1 at 115 200 Bd from
    // its kernel clock and BRR within 0.1 %.
    let periph = &run.m.board().periph;
    let hclk = periph.rcc.hclk();
    assert!((hclk - 170e6).abs() < 1.0, "HCLK {hclk} Hz");
    assert_eq!(periph.tim6.update_period_cycles(), 17_000);
    let baud = periph.lpuart.baud(periph.rcc.lpuart1_kernel_hz());
    assert!(
        (baud / 115_200.0 - 1.0).abs() < 1e-3,
        "LPUART1 at {baud} Bd"
    );
    let parsed = run.parsed();
    let boot = first(&parsed, "boot");
    assert_eq!(boot["board"], "stm32");
    assert_eq!(num(&boot, "fs_hz"), 10_000.0);
    assert!(!boot.contains_key("fault"), "boot fault: {boot:?}");
    // The power-on self-test on phantom B: passed, and its capacitance is the scene's
    // closed-form admittance at the test frequency (as tests/qemu_selftest.rs checks the
    // QEMU image), within 5 sigma and 0.2 %.
    let t = first(&parsed, "selftest");
    assert_eq!(t["result"], "passed", "{t:?}");
    let f = num(&t, "f_hz");
    let scene = hal_sim::Scene::on_phantom(&hal_sim::phantoms::B)
        .with_noise(hal_sim::NoiseScene::Bench)
        .with_preload_n(0.03);
    let truth_pf = scene.admittance(f).im / (2.0 * std::f64::consts::PI * f) * 1e12;
    let c = num(&t, "c_pf");
    let tol = 5.0 * num(&t, "c_sigma_pf") + 2e-3 * truth_pf;
    println!("self-test: C {c:.3} pF, closed form {truth_pf:.3} pF, tolerance {tol:.3} pF");
    assert!(
        (c - truth_pf).abs() <= tol,
        "{c} pF vs {truth_pf} pF ± {tol}"
    );
    // A reading (refused for want of an air reference, but run) and the image's own overrun
    // accounting: no batch late, no ring overrun, nothing dropped — the sample interrupt takes
    // a few thousand of a batch's 425 000 cycles.
    let r = first(&parsed, "reading");
    assert_eq!(r["status"], "no_air_reference", "{r:?}");
    let counters = last(&parsed, "counters");
    assert!(num(&counters, "batches") > 100.0, "{counters:?}");
    for k in ["late", "ring", "dropped"] {
        assert_eq!(num(&counters, k), 0.0, "{k}: {counters:?}");
    }
}

/// The user's path of the done-when: the air reference in free air, a calibration on
/// phantoms A–E, `calibrate fit`, `store`, the reset button, and the stored unit reads phantom
/// B. References: the phantoms' moduli (paper 003) the calibration was given, and hal-sim's
/// closed-form resonances of the scenes; the store must be the one read back after the reset.
#[test]
fn stm32_image_calibrates_stores_survives_a_reset_and_reads_phantom_b() {
    use Event::*;
    let elf = build_image();
    let events = [
        (1.0, Send("air")),
        (12.5, Scene("weight:10")),
        (12.7, Send("weigh 10")),
        (14.0, Scene("A")),
        (14.5, Send("calibrate add 157.5")),
        (16.0, Scene("B")),
        (16.5, Send("calibrate add 279")),
        (18.0, Scene("C")),
        (18.5, Send("calibrate add 414")),
        (20.0, Scene("D")),
        (20.5, Send("calibrate add 1146")),
        (22.0, Scene("E")),
        (22.5, Send("calibrate add 2465")),
        (24.0, Send("calibrate fit")),
        (27.0, Send("store")),
        (29.0, Scene("B")),
        (30.0, Reset),
        (34.0, Send("measure")),
    ];
    let run = run(&elf, 37.0, scene("free-air"), &events);
    let rules = run.rules();
    assert!(rules.is_empty(), "rules broken: {rules:?}");
    let parsed = run.parsed();
    let named = |n: &str| all(&parsed, n);

    // The air reference: the free probe's resonance (closed form) within 0.1 Hz. The air
    // sweep's fit reads a little above the undamped natural frequency on the host too
    // (`probe-bench measure` on the same scene: air 232.353 Hz against 232.300 Hz).
    let air = named("air");
    assert_eq!(air.len(), 1, "{air:?}");
    let f_air = HalSimProbe::bench_scene(None).resonance_hz();
    assert!(
        (num(air[0], "f_hz") - f_air).abs() < 0.1,
        "air {air:?}, closed form {f_air} Hz"
    );
    // Five references, a fitted curve, stored.
    assert_eq!(named("reference").len(), 5);
    assert_eq!(named("calibration").last().unwrap()["source"], "fitted");
    let saved = named("store");
    assert!(
        saved
            .iter()
            .any(|m| m.contains_key("seq") && m.get("slot").is_some()),
        "{saved:?}"
    );
    // Two boots; the second loads the stored unit from bank 2.
    assert_eq!(named("boot").len(), 2);
    assert!(
        run.lines
            .iter()
            .any(|l| l.contains("store loaded slot=0 seq=1")),
        "the store did not survive the reset"
    );
    // The reading of B after the reset: ok, its resonance at the closed form, its modulus
    // within 1 % of the phantom's 279 kPa.
    let r = last(&parsed, "reading");
    assert_eq!(r["status"], "ok", "{r:?}");
    let f_b = HalSimProbe::bench_scene(Some(&hal_sim::phantoms::B)).resonance_hz();
    let tol = 5.0 * num(&r, "f_sigma_hz") + 0.01;
    assert!(
        (num(&r, "f_hz") - f_b).abs() <= tol,
        "f {} Hz vs closed form {f_b} Hz ± {tol}",
        num(&r, "f_hz")
    );
    let e = num(&r, "e_kpa");
    assert!(
        (e / 279.0 - 1.0).abs() < 0.01,
        "B read {e} kPa, phantom 279 kPa"
    );
    assert_eq!(num(&last(&parsed, "counters"), "late"), 0.0);
    // The load cell, weighed with 10 g before the calibration, kept through the store and the
    // reset: the reading's contact force is the scene's.
    let cal = named("loadcell");
    assert!(cal.iter().any(|c| c["present"] == "true"), "{cal:?}");
    assert_force(&r, 0.030, 35.0);
}

/// The 10 g weight of the sessions' `weigh 10`, N (the heaviest load the cell carries).
const WEIGHT_N: f64 = 0.010 * hal_sim::loadcell::STANDARD_GRAVITY_M_S2;

/// The largest error of a contact force the unit reads at `t_s` emulated seconds, `scene_n`
/// newtons being the truth, by the terms of hal-sim's load cell (`hal_sim::loadcell::LoadCell`'s
/// default, the bench scenes' cell) and of the unit's calibration of it: the creep the reading
/// carries (at most `creep_fraction` of the heaviest load carried before it, the 10 g weight,
/// since creep relaxes with its time constant after a load leaves), the creep the weighing
/// carried into the sensitivity (at most `creep_fraction` of the force), the offset drift since
/// the tare (the air reference, after 1 s), 4 σ of the window's mean (the reading's own
/// `force_sigma_n`) and a count's rounding.
fn force_tolerance(scene_n: f64, t_s: f64, sigma_n: f64) -> f64 {
    let cell = hal_sim::loadcell::LoadCell::default();
    cell.creep_fraction * (WEIGHT_N.max(scene_n) + scene_n)
        + cell.drift_n_per_s * (t_s - 1.0)
        + 4.0 * sigma_n
        + 1.0 / cell.counts_per_n
}

/// The reading `r` (taken by `t_s` emulated seconds) reports the contact force `scene_n` within
/// [`force_tolerance`].
fn assert_force(r: &std::collections::HashMap<String, String>, scene_n: f64, t_s: f64) {
    let f = num(r, "force_n");
    let tol = force_tolerance(scene_n, t_s, num(r, "force_sigma_n"));
    println!(
        "force {:.3} mN, scene {:.3} mN, tolerance {:.3} mN",
        f * 1e3,
        scene_n * 1e3,
        tol * 1e3
    );
    assert!(
        (f - scene_n).abs() <= tol,
        "force {f} N, the scene's {scene_n} N ± {tol}: {r:?}"
    );
}

/// The load cell's HX711 on PB4/PB5 of the emulated board (issue 26): after the air reference
/// and `weigh 10` with 10 g on the tip, the unit reads the scene's contact force, and judges
/// the press by it as the firmware's force window (the `loadcell` line's `min_n`, `max_n`) and
/// no-contact threshold (3 mN, `NO_CONTACT_FORCE`) say: on B at 8 mN `too_light`, at 80 mN
/// `too_hard`, in free air `no_contact`, at 30 mN the press passes (the unit is not calibrated
/// on phantoms: `uncalibrated`). Without the weighing the unit has no load cell calibration.
#[test]
fn stm32_image_reads_the_contact_force_from_its_load_cell() {
    use Event::*;
    let elf = build_image();
    let presses: [(&str, f64, &str); 4] = [
        ("B@8", 0.008, "too_light"),
        ("B@80", 0.080, "too_hard"),
        ("free-air", 0.0, "no_contact"),
        ("B", 0.030, "uncalibrated"),
    ];
    let mut events = vec![
        (1.0, Send("measure")),
        (1.5, Send("air")),
        (13.0, Scene("weight:10")),
        (13.2, Send("weigh 10")),
    ];
    let at = |k: usize| 14.0 + 1.5 * k as f64;
    for (k, (name, _, _)) in presses.iter().enumerate() {
        events.push((at(k), Scene(name)));
        events.push((at(k) + 0.5, Send("measure")));
    }
    let run = run(&elf, at(presses.len()), scene("free-air"), &events);
    let parsed = run.parsed();
    let readings = all(&parsed, "reading");
    assert_eq!(readings.len(), 1 + presses.len(), "{:?}", run.lines);
    // Before the weighing the unit has no load cell: no force in the reading.
    assert_eq!(readings[0]["status"], "no_air_reference");
    assert!(
        readings[0].get("force_n").is_none_or(|f| f == "NaN"),
        "{:?}",
        readings[0]
    );
    let cal = all(&parsed, "loadcell");
    let cal = cal.last().expect("a loadcell line after `weigh`");
    assert_eq!(cal["present"], "true", "{cal:?}");
    let (min_n, max_n) = (num(cal, "min_n"), num(cal, "max_n"));
    for (k, (name, scene_n, status)) in presses.iter().enumerate() {
        let r = readings[1 + k];
        println!("{name}: {} at {} N", r["status"], r["force_n"]);
        assert_force(r, *scene_n, at(k) + 1.5);
        // The verdict the window gives the scene's force (an independent check of the status).
        let expected = if *scene_n < 0.003 {
            "no_contact"
        } else if *scene_n < min_n {
            "too_light"
        } else if *scene_n > max_n {
            "too_hard"
        } else {
            "uncalibrated"
        };
        assert_eq!(expected, *status, "the test's table");
        assert_eq!(r["status"], *status, "{name}: {r:?}");
    }
}

/// A fault the bring-up must survive (issue 26, point 6): ADC1 never becomes ready. embassy's
/// `Adc::new` waits for ADRDY without a bound; the independent watchdog (500 ms) resets the core
/// and the next boot, finding the boot-step marker in RAM a reset keeps, names the step and
/// runs without converters — no hang, no reset loop (`docs/firmware.md`, "Boot").
#[test]
fn stm32_image_survives_an_adc_that_never_becomes_ready() {
    let never_ready = |m: &mut Machine| m.board_mut().periph.adc[0].never_ready = true;
    let run = run_faulted(2.0, 0.0, never_ready, None);
    assert_eq!(run.m.resets, 1, "one watchdog reset, no loop");
    // (RCC_CSR's IWDGRSTF is not looked at here: the image reads and clears it with RMVF.)
    assert!(run.booted_with("converter_hang"), "{:?}", run.lines);
}

/// A fault the bring-up must survive: the HSE crystal never starts. The image waits for
/// HSERDY with a bound (100 ms at HSI16) and runs its PLL from HSI16 at the same 170 MHz
/// (`clock=hsi16-pll`): it boots and passes its self-test, and says why it runs on the RC
/// oscillator: `boot fault=hse_failure clock=hsi16-pll` in the log, and `status` names the boot
/// error.
#[test]
fn stm32_image_runs_from_hsi16_when_the_hse_never_starts() {
    let no_hse = |m: &mut Machine| m.board_mut().periph.rcc.hse_present = false;
    let run = run_faulted(2.0, 0.0, no_hse, Some((1.5, "status")));
    assert_eq!(run.m.resets, 0);
    // RM0440 RCC: the PLL from HSI16 (PLLSRC = 10) and SYSCLK from it at 170 MHz.
    let rcc = &run.m.board().periph.rcc;
    assert_eq!(rcc.pllcfgr & 3, 2, "PLL source HSI16");
    assert!((rcc.hclk() - 170e6).abs() < 1.0, "HCLK {} Hz", rcc.hclk());
    assert!(run.rules().is_empty(), "rules broken: {:?}", run.rules());
    let t = first(&run.parsed(), "selftest");
    assert_eq!(t["result"], "passed", "{t:?}");
    assert!(
        run.booted_with("hse_failure"),
        "no boot fault line: {:?}",
        run.lines
    );
    let parsed = run.parsed();
    let boot = all(&parsed, "boot");
    let fault = boot.iter().find(|f| f.contains_key("fault"));
    assert_eq!(
        fault.map(|f| f["clock"].as_str()),
        Some("hsi16-pll"),
        "{:?}",
        run.lines
    );
    let status = all(&parsed, "status");
    assert!(
        status
            .iter()
            .any(|f| f.get("boot").map(String::as_str) == Some("hse_failure")),
        "status does not name it: {:?}",
        run.lines
    );
}

/// A fault the bring-up must survive: a DMA transfer error on ADC1's channel (DMA1 CH1) while
/// the stream runs. RM0440 DMA: TEIF set, the channel disabled by the hardware. The image counts
/// it before embassy's handler (which would panic), stops TIM6, and a reading then stalls and
/// ends as `dma_error`, the count in the `counters` line — no panic, no hang.
#[test]
fn stm32_image_survives_a_dma_transfer_error() {
    let error = |m: &mut Machine| m.board_mut().periph.dma.error(0);
    let run = run_faulted(3.0, 1.0, error, Some((1.2, "measure")));
    assert_eq!(run.m.resets, 0, "no panic, no watchdog reset");
    // The channel is off (the hardware disabled it) and TIM6 stopped by the image.
    assert_eq!(run.m.board().periph.dma.ch[0].ccr & 1, 0);
    assert!(
        run.m.board().periph.tim6.next_event().is_none(),
        "TIM6 still running"
    );
    let parsed = run.parsed();
    let r = first(&parsed, "reading");
    assert_eq!(r["status"], "dma_error", "{r:?}");
    assert_eq!(num(&last(&parsed, "counters"), "dma_errors"), 1.0);
    assert!(
        run.lines.iter().any(|l| l.contains("stalled")),
        "no stalled line"
    );
}

/// A DMA transfer error on each other DMA1 channel the board uses (CH2 ADC2, CH3 DAC1, CH4
/// LPUART1 RX, CH6 LPUART1 TX): counted before embassy's handler (which panics on TEIF) on
/// every channel's vector, the stream stopped, the next reading `dma_error` — no panic, no
/// reset.
#[test]
fn stm32_image_ends_a_dma_error_on_any_of_its_channels_typed() {
    type Inject = fn(&mut Machine);
    let errors: [(&str, Inject); 4] = [
        ("CH2 ADC2", |m| m.board_mut().periph.dma.error(1)),
        ("CH3 DAC1", |m| m.board_mut().periph.dma.error(2)),
        ("CH4 LPUART1 RX", |m| m.board_mut().periph.dma.error(3)),
        ("CH6 LPUART1 TX", |m| m.board_mut().periph.dma.error(5)),
    ];
    for (name, error) in errors {
        println!("--- {name}");
        let run = run_faulted(2.5, 1.0, error, Some((1.2, "measure")));
        assert_eq!(run.m.resets, 0, "{name}: no panic, no watchdog reset");
        let parsed = run.parsed();
        let r = first(&parsed, "reading");
        assert_eq!(r["status"], "dma_error", "{name}: {r:?}");
        assert_eq!(num(&last(&parsed, "counters"), "dma_errors"), 1.0, "{name}");
        assert!(run.rules().is_empty(), "{name}: {:?}", run.rules());
    }
}

/// A fault the bring-up must survive: the flash stuck busy (BSY never clears) while the store
/// erases. embassy's blocking erase waits without a bound; the measurement task breaks its
/// liveness promise, the guard stops feeding the watchdog, the IWDG resets the core, and the
/// next boot names the step (`flash_hang`) and refuses the store instead of hanging again.
#[test]
fn stm32_image_survives_a_flash_stuck_busy() {
    let stuck = |m: &mut Machine| m.board_mut().periph.flash.stuck_busy = true;
    let run = run_faulted(6.0, 0.0, stuck, Some((1.0, "store")));
    assert_eq!(run.m.resets, 1, "one watchdog reset, no loop");
    assert!(run.booted_with("flash_hang"), "{:?}", run.lines);
}

/// Probe faults at power-on (hal-sim's fault scenes, as tests/qemu_selftest.rs runs them on the
/// QEMU image): each ends in its typed self-test fault on the emulated STM32 board, and a
/// reading is refused — the open PZT among them. The codes are the firmware's own
/// (`SelfTestFault` in src/instrument/selftest.rs), matched by name to hal-sim's faults.
#[test]
fn stm32_image_names_each_probe_fault_in_its_self_test() {
    let elf = build_image();
    for (fault, code) in [
        (hal_sim::Fault::OpenPzt, "open_pzt"),
        (hal_sim::Fault::ShortedPzt, "shorted_pzt"),
        (hal_sim::Fault::StuckDac, "no_drive"),
        (hal_sim::Fault::AdcRail, "adc_rail_current"),
    ] {
        println!("--- {}", fault.name());
        let on = fault.apply(scene("B"));
        let run = run(&elf, 2.5, on, &[(1.5, Event::Send("measure"))]);
        let parsed = run.parsed();
        let t = first(&parsed, "selftest");
        println!("{}: selftest {}", fault.name(), t["result"]);
        assert_eq!(t["result"], code, "{}: {:?}", fault.name(), run.lines);
        assert!(
            !all(&parsed, "reading").iter().any(|r| r["status"] == "ok"),
            "{}: a reading was taken on a faulty probe",
            fault.name()
        );
        assert!(
            run.lines
                .iter()
                .any(|l| l.contains("refused") || l.contains(code)),
            "{}",
            fault.name()
        );
    }
}
