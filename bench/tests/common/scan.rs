//! What the scan tests share (`scan.rs`, `scan_loss.rs`): the scene they scan under, how far
//! a lump found lies from the truth, and the command's JSON with its map.

use super::{bin, run_json};
use hal_sim::{NoiseScene, Scene};
use probe_bench::cmd::scan::ScanSpec;
use std::path::Path;

/// The probe in free air under the bench's noise: the base scene the scans press from.
pub fn bench_scene() -> Scene {
    Scene::free_air().with_noise(NoiseScene::Bench)
}

/// Distance from `(x, y)` (mm) to the centre of `spec`'s inclusion, mm.
pub fn centre_error(spec: &ScanSpec, x: f64, y: f64) -> f64 {
    let (tx, ty) = spec.phantom.inclusion.centre_m();
    (x - tx * 1e3).hypot(y - ty * 1e3)
}

/// `probe-bench scan --json ARGS --plot PLOT`, which must succeed: its JSON; the map is written
/// to `plot`.
pub fn scan_json(args: &[&str], plot: &Path) -> serde_json::Value {
    run_json(
        bin()
            .args(["scan", "--json"])
            .args(args)
            .arg("--plot")
            .arg(plot),
    )
}
