//! The calibration store over the simulated NOR flash with fault injection: a power loss at any
//! point of a save leaves a valid record, corruption is detected, and the fallback is reported.

use hal_sim::flash::SimFlash;
use pzt_probe::unit::calibration::Source;
use pzt_probe::unit::q_model::QModel;
use pzt_probe::unit::store::{
    AirReference, LoadSource, SlotState, Store, StoreError, UnitProfile, RECORD_LEN,
};
use pzt_probe::{Farads, Hz, PowerLaw, Siemens};

/// 4 KiB of 2 KiB sectors, 8-byte program words: two slots of one sector each.
type Flash = SimFlash<4096, 2048, 8>;

fn record(n: u32) -> UnitProfile {
    let mut cal = PowerLaw::paper_experiment();
    cal.a += n as f64 * 0.125;
    cal.source = Source::Fitted;
    cal.cov[0][0] = 0.01 * n as f64;
    UnitProfile {
        calibration: cal,
        resonance: if n.is_multiple_of(2) {
            pzt_probe::estimate::Resonance::Motional
        } else {
            pzt_probe::estimate::Resonance::ImpedanceDip
        },
        q_model: Some(QModel {
            q0: 4.0 + n as f64,
            q1: 1.0,
            q2: -0.5 * n as f64,
            sigma_rel: 0.01 * n as f64,
            damping: None,
        }),
        air: Some(AirReference {
            free_resonance: Hz(232.0 + n as f32),
            free_q: 40.0 + n as f32,
            static_capacitance: Farads(200e-12 + n as f32 * 1e-12),
            static_conductance: Siemens(n as f32 * 1e-9),
        }),
        contact: None,
        load_cell: (!n.is_multiple_of(3)).then_some(pzt_probe::loadcell::LoadCellCal {
            newtons_per_count: 2.8e-7,
            tare: pzt_probe::loadcell::LoadCellCounts(7200 - n as i32),
        }),
        force_window: pzt_probe::loadcell::ForceWindow {
            min: pzt_probe::Newtons(0.010 + n as f32 * 1e-4),
            max: pzt_probe::Newtons(0.060),
        },
    }
}

fn store_with(flash: Flash) -> Store<Flash> {
    Store::new(flash, 0).expect("geometry fits")
}

/// A store that has seen `saves` completed saves of `record(1..=saves)`.
fn store_after(saves: u32) -> Store<Flash> {
    let mut s = store_with(Flash::new());
    for n in 1..=saves {
        s.save(&record(n)).expect("save");
    }
    s
}

#[test]
fn empty_flash_falls_back_and_says_so() {
    let mut s = store_with(Flash::new());
    let l = s.load();
    assert!(l.is_fallback());
    assert!(!l.damage_seen());
    assert_eq!(l.record, UnitProfile::fallback());
    assert_eq!(l.record.calibration, PowerLaw::paper_experiment());
    assert_eq!(
        l.source,
        LoadSource::Fallback {
            slots: [SlotState::Empty, SlotState::Empty]
        }
    );
}

#[test]
fn saves_alternate_slots_and_load_the_newest() {
    let mut s = store_with(Flash::new());
    for n in 1..=5u32 {
        let saved = s.save(&record(n)).unwrap();
        assert_eq!(saved.seq, n);
        assert_eq!(saved.slot as u32, (n - 1) % 2);
        let l = s.load();
        assert_eq!(l.record, record(n));
        assert!(!l.is_fallback());
        match l.source {
            LoadSource::Stored { slot, seq, other } => {
                assert_eq!((slot, seq), (saved.slot, n));
                let expect_other = if n == 1 {
                    SlotState::Empty
                } else {
                    SlotState::Valid(n - 1)
                };
                assert_eq!(other, expect_other);
            }
            other => panic!("unexpected {other:?}"),
        }
    }
}

#[test]
fn invalid_records_are_refused_without_touching_flash() {
    let mut s = store_after(1);
    let before = s.flash_mut().contents().to_vec();
    let mut bad = record(2);
    bad.calibration.b = 1.0; // not saturating
    assert_eq!(s.save(&bad), Err(StoreError::InvalidRecord));
    let mut bad = record(2);
    bad.air = Some(AirReference {
        free_resonance: Hz(f32::NAN),
        free_q: 3.0,
        static_capacitance: Farads(210e-12),
        static_conductance: Siemens(0.0),
    });
    assert_eq!(s.save(&bad), Err(StoreError::InvalidRecord));
    let mut bad = record(2);
    bad.calibration.cov[2][1] = f64::INFINITY;
    assert_eq!(s.save(&bad), Err(StoreError::InvalidRecord));
    assert_eq!(s.flash_mut().contents(), &before[..]);
    assert_eq!(s.load().record, record(1));
}

#[test]
fn bad_geometry_is_refused() {
    // Base not sector aligned.
    assert_eq!(
        Store::new(Flash::new(), 8).err(),
        Some(StoreError::Geometry)
    );
    // Two slots do not fit.
    assert_eq!(
        Store::new(Flash::new(), 2048).err(),
        Some(StoreError::Geometry)
    );
    // A program word that does not divide the record.
    assert_eq!(
        Store::new(SimFlash::<4096, 2048, 256>::new(), 0).err(),
        Some(StoreError::Geometry)
    );
    // Small sectors: a slot spans several.
    let s = Store::new(SimFlash::<1024, 128, 8>::new(), 0).unwrap();
    assert_eq!(s.footprint(), 2 * 384);
}

/// The heart of it: cut the power after every possible number of programmed bytes of a save,
/// for saves into either slot, then power up and load. The result must be the previous record
/// (or the new one once every byte is in), never the fallback, never a mixture. A byte whose
/// value is the erased one (0xFF) is "in" without being programmed: a cut that leaves only such
/// bytes out has written the whole record (the last byte of the CRC is 0xFF in one record of
/// 256), and the new record is what loads.
#[test]
fn power_loss_at_every_program_byte_keeps_a_valid_record() {
    for previous in 1..=3u32 {
        let full = pzt_probe::unit::store::encode(&record(previous + 1), previous + 1);
        for cut in 0..=RECORD_LEN {
            let mut s = store_after(previous);
            s.flash_mut().cut_power_after_program(cut);
            let res = s.save(&record(previous + 1));
            let mut flash = s.into_inner();
            flash.power_cycle();
            let mut s = store_with(flash);
            let l = s.load();
            assert!(!l.is_fallback(), "previous {previous} cut {cut}: fallback");
            let written = full[cut.min(RECORD_LEN)..].iter().all(|&b| b == 0xFF);
            if cut < RECORD_LEN && written {
                assert_eq!(res, Err(StoreError::Program), "cut {cut}");
                assert_eq!(
                    l.record,
                    record(previous + 1),
                    "previous {previous} cut {cut}"
                );
            } else if cut < RECORD_LEN {
                assert_eq!(res, Err(StoreError::Program), "cut {cut}");
                assert_eq!(l.record, record(previous), "previous {previous} cut {cut}");
                match l.source {
                    LoadSource::Stored { seq, other, .. } => {
                        assert_eq!(seq, previous);
                        // The torn slot is reported as damage unless nothing reached it.
                        let expect = if cut == 0 {
                            SlotState::Empty
                        } else {
                            SlotState::Corrupt
                        };
                        assert_eq!(other, expect, "previous {previous} cut {cut}");
                    }
                    other => panic!("unexpected {other:?}"),
                }
            } else {
                assert!(res.is_ok(), "cut {cut}: {res:?}");
                assert_eq!(l.record, record(previous + 1));
            }
            // And the store recovers: the next save completes and becomes the newest.
            let saved = s.save(&record(100)).expect("save after recovery");
            let newest = if cut < RECORD_LEN && !written {
                previous
            } else {
                previous + 1
            };
            assert_eq!(saved.seq, newest + 1);
            assert_eq!(s.load().record, record(100));
        }
    }
}

/// Cut the power during the erase of the target slot, at every byte.
#[test]
fn power_loss_at_every_erase_byte_keeps_a_valid_record() {
    for cut in 0..2048usize {
        let mut s = store_after(2);
        s.flash_mut().cut_power_after_erase(cut);
        assert_eq!(s.save(&record(3)), Err(StoreError::Erase));
        let mut flash = s.into_inner();
        flash.power_cycle();
        let mut s = store_with(flash);
        let l = s.load();
        assert_eq!(l.record, record(2), "cut {cut}");
        match l.source {
            LoadSource::Stored { seq, other, .. } => {
                assert_eq!(seq, 2);
                // Untouched: still the older record; partly erased: corrupt; record area fully
                // erased: empty.
                let expect = if cut == 0 {
                    SlotState::Valid(1)
                } else if cut >= RECORD_LEN {
                    SlotState::Empty
                } else {
                    SlotState::Corrupt
                };
                assert_eq!(other, expect, "cut {cut}");
            }
            other => panic!("unexpected {other:?}"),
        }
    }
}

/// A single bit flip anywhere in the newest record is detected; the older record is used and
/// the damage is reported.
#[test]
fn bit_flips_in_the_newest_record_are_detected() {
    for byte in 0..RECORD_LEN {
        for bit in 0..8u8 {
            let mut s = store_after(2); // newest (seq 2) in slot 1 at offset 2048
            s.flash_mut().flip_bit(2048 + byte, bit);
            let l = s.load();
            assert_eq!(l.record, record(1), "byte {byte} bit {bit}");
            assert!(l.damage_seen());
            assert_eq!(
                l.source,
                LoadSource::Stored {
                    slot: 0,
                    seq: 1,
                    other: SlotState::Corrupt
                }
            );
        }
    }
}

/// Both records damaged: the fallback is used and reported with the reason.
#[test]
fn both_records_corrupt_falls_back_with_damage_reported() {
    let mut s = store_after(2);
    s.flash_mut().flip_bit(20, 3);
    s.flash_mut().flip_bit(2048 + 150, 0);
    let l = s.load();
    assert!(l.is_fallback());
    assert!(l.damage_seen());
    assert_eq!(l.record, UnitProfile::fallback());
    assert_eq!(
        l.source,
        LoadSource::Fallback {
            slots: [SlotState::Corrupt, SlotState::Corrupt]
        }
    );
    // A save still works afterwards and replaces the fallback.
    s.save(&record(9)).unwrap();
    assert_eq!(s.load().record, record(9));
}

/// Random multi-bit damage (deterministic pseudo-random positions) is never accepted as a
/// record different from what was written.
#[test]
fn multi_bit_damage_never_yields_a_wrong_record() {
    let mut rng = probe_rng::Rng::new(0x9E37_79B9_7F4A_7C15);
    let mut next = || rng.next_u64();
    for _ in 0..2000 {
        let mut s = store_after(2);
        let flips = 2 + next() % 6;
        for _ in 0..flips {
            let off = (next() % (2 * 2048) as u64) as usize;
            s.flash_mut().flip_bit(off, (next() % 8) as u8);
        }
        let l = s.load();
        assert!(
            l.record == record(2) || l.record == record(1) || l.record == UnitProfile::fallback(),
            "{:?}",
            l
        );
    }
}

/// A foreign image in the slots (not erased, not a record) is corrupt, not a record.
#[test]
fn foreign_data_is_corrupt() {
    let mut s = store_with(Flash::new());
    use embedded_storage::nor_flash::NorFlash;
    s.flash_mut().write(0, &[0x12; 16]).unwrap();
    let l = s.load();
    assert!(l.is_fallback());
    assert_eq!(
        l.source,
        LoadSource::Fallback {
            slots: [SlotState::Corrupt, SlotState::Empty]
        }
    );
}

/// A flash that keeps failing: the load falls back and reports the slots unreadable.
#[test]
fn unreadable_flash_falls_back() {
    let mut s = store_after(1);
    s.flash_mut().cut_power_after_program(0);
    assert_eq!(s.save(&record(2)), Err(StoreError::Program));
    // Power is still off: reads fail.
    let l = s.load();
    assert!(l.is_fallback());
    assert!(l.damage_seen());
    assert_eq!(
        l.source,
        LoadSource::Fallback {
            slots: [SlotState::Unreadable, SlotState::Unreadable]
        }
    );
}
