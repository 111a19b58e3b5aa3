//! The simulated unit's profile for the bench's studies and commands: made once per method,
//! settings, noise and seeds through the core's own procedure
//! (`pzt_probe::board::sim::unit_profile`: the air reference, then A–E × repeats), and kept
//! for the rest of the process so that a command or a test suite that reads many scenes
//! calibrates once.

use anyhow::{anyhow, Result};
use hal_sim::NoiseScene;
use pzt_probe::board::sim as simboard;
use pzt_probe::reading::{Method, Settings};
use pzt_probe::unit::profile::UnitProfile;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

type Key = (String, String, u64, usize, u64);

/// The simulated unit's profile as a user gets it out of the box: calibrated with `method`'s
/// default settings at bench noise on A–E × 20 (noise seeds from 1000). `measure` and `analyze`
/// read with it; `auto`'s is the QEMU image's factory profile (`tests/factory_profile.rs`).
pub fn default_for(method: Method) -> Result<UnitProfile> {
    simulated(
        method,
        &method.default_settings(),
        NoiseScene::Bench,
        20,
        1000,
    )
}

/// The simulated unit's profile calibrated with `method` and `settings` under `noise` on A–E ×
/// `repeats` (noise seeds from `seed0`).
pub fn simulated(
    method: Method,
    settings: &Settings,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
) -> Result<UnitProfile> {
    static CACHE: OnceLock<Mutex<HashMap<Key, UnitProfile>>> = OnceLock::new();
    let key: Key = (
        method.name().to_owned(),
        format!("{settings:?}"),
        noise.density_a_rthz().to_bits(),
        repeats,
        seed0,
    );
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(p) = cache.lock().ok().and_then(|c| c.get(&key).copied()) {
        return Ok(p);
    }
    let p = simboard::unit_profile(method, *settings, noise, repeats, seed0)
        .map_err(|e| anyhow!("the simulated unit's profile failed: {e}"))?;
    if let Ok(mut c) = cache.lock() {
        c.insert(key, p);
    }
    Ok(p)
}
