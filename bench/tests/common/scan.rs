//! What the scan tests share (`scan.rs`, `scan_loss.rs`): the scene they scan under and how far
//! a lump found lies from the truth.

use hal_sim::{NoiseScene, Scene};
use probe_bench::cmd::scan::ScanSpec;

/// The probe in free air under the bench's noise: the base scene the scans press from.
pub fn bench_scene() -> Scene {
    Scene::free_air().with_noise(NoiseScene::Bench)
}

/// Distance from `(x, y)` (mm) to the centre of `spec`'s inclusion, mm.
pub fn centre_error(spec: &ScanSpec, x: f64, y: f64) -> f64 {
    let (tx, ty) = spec.phantom.inclusion.centre_m();
    (x - tx * 1e3).hypot(y - ty * 1e3)
}
