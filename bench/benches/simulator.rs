//! Criterion benchmark of the simulator: the full signal chain (DAC codes in, physics, ADC codes
//! out) for one second of probe time at 10 kHz, and one whole sweep-G reading through the
//! firmware core. Report: simulated probe seconds per host second = 1 s / (time per iteration).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hal_sim::{AdcPair, NoiseScene, Scene, SimProbe};
use pzt_probe::board::sim::read;
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::Method;

fn chain(c: &mut Criterion) {
    let scene = Scene::on_modulus_kpa(300.0).with_noise(NoiseScene::Bench);
    let mut g = c.benchmark_group("simulator");
    g.throughput(Throughput::Elements(10_000));
    g.bench_function("one probe second (10k samples, full chain + noise)", |b| {
        let mut probe = SimProbe::new(scene, 1);
        let dac: Vec<u16> = (0..10_000)
            .map(|k| (2048.0 + 1200.0 * (k as f64 * 0.146).sin()) as u16)
            .collect();
        let mut adc = vec![AdcPair::default(); 10_000];
        b.iter(|| probe.exchange(&dac, &mut adc));
    });
    g.finish();
    let method = Method::SweepG;
    let settings = method.default_sweep();
    // The reading's pipeline refuses without an air reference; the cost is the same.
    let unit = UnitProfile::fallback();
    c.bench_function(
        "sweep-g reading (6.1 probe seconds, sim + firmware core)",
        |b| b.iter(|| read(&scene, 3, method, &settings, &unit, |_| {}).unwrap()),
    );
}

criterion_group!(benches, chain);
criterion_main!(benches);
