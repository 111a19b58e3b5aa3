//! The simulated unit's factory flash (`src/board/sim_factory.rs`, programmed by the QEMU board
//! at power-on) is the profile the unit's own procedure gives today: an air reference, then
//! A–E × 20 with the firmware's default method at bench noise. If an estimator or the
//! calibration changes, this fails until the record is regenerated with the command in the
//! file's header.

use hal_sim::NoiseScene;
use pzt_probe::board::{sim, sim_factory};
use pzt_probe::reading::DEFAULT_METHOD;
use pzt_probe::unit::store::encode;

#[test]
fn the_factory_record_is_the_units_profile_today() {
    let m = DEFAULT_METHOD;
    let p = sim::unit_profile(m, m.default_settings(), NoiseScene::Bench, 20, 1000)
        .expect("the simulated unit's profile");
    assert_eq!(
        encode(&p, 1),
        sim_factory::RECORD,
        "src/board/sim_factory.rs is stale: regenerate it (command in its header)"
    );
    assert_eq!(sim_factory::profile(), Some(p));
}
