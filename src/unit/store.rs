//! The profile store: the unit's [`UnitProfile`] (calibration curve, contact condition, air
//! reference), kept in NOR flash
//! with integrity, over the `embedded-storage` [`NorFlash`] traits.
//!
//! # Layout and protocol
//!
//! Two slots, each a whole number of erase sectors, hold one [`UnitProfile`] each. A record is
//! [`RECORD_LEN`] bytes, little endian:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"PZTC"` |
//! | 4 | 2 | format version ([`FORMAT_VERSION`]) |
//! | 6 | 2 | record length ([`RECORD_LEN`]) |
//! | 8 | 4 | sequence number |
//! | 12 | 1 | flags (bit 0: air reference present, bit 1: Q model present, bit 2: contact law present, bit 3: load cell present, bit 4: the Q model's contact-damping curve present) |
//! | 13 | 1 | calibration source (0 paper-simulation, 1 paper-experiment, 2 fitted) |
//! | 14 | 1 | the resonance the curve maps (0 motional, 1 impedance dip) |
//! | 15 | 1 | zero |
//! | 16 | 24 | `a`, `b`, `c` (f64) |
//! | 40 | 72 | covariance of `(a, b, c)`, row major (f64) |
//! | 112 | 16 | `min_kpa`, `max_kpa` (f64) |
//! | 128 | 8 | `model_sigma_hz` (f64) |
//! | 136 | 8 | air reference: free resonance Hz, free Q (f32) |
//! | 144 | 8 | air reference: static capacitance F, static conductance S (f32) |
//! | 152 | 16 | Q model `q0`, `q1` (f64) |
//! | 168 | 8 | contact law: free resonance, Hz (f64) |
//! | 176 | 24 | contact law: `ln Ks`, `ln A`, `ln B` (f64) |
//! | 200 | 72 | contact law: their covariance, row major (f64) |
//! | 272 | 24 | contact law: `model_sigma_hz`, `min_kpa`, `max_kpa` (f64) |
//! | 296 | 8 | contact law: its reference force, N (f64) |
//! | 304 | 8 | Q model `q2` (per `ln F`, f64) |
//! | 312 | 8 | load cell: newtons per count (f32), tare counts (i32) |
//! | 320 | 8 | force window: `min`, `max`, N (f32) |
//! | 328 | 8 | Q model `sigma_rel` (f64) |
//! | 336 | 24 | Q model's contact-damping curve: `probe_per_s`, `contact_per_s`, `sigma_rel` (f64) |
//! | 360 | 20 | zero |
//! | 380 | 4 | CRC-32 (IEEE) of bytes 0..380 |
//!
//! [`Store::save`] writes the slot that does **not** hold the newest valid record (erase, program,
//! read back and compare), with the sequence number one above the newest. The newest valid record
//! is therefore never touched: a reset or power loss at any point of a save leaves it readable,
//! and [`Store::load`] returns either it or, once the save completed, the new one. The CRC is the
//! last field programmed, so a partly programmed record fails its check.
//!
//! A record of the previous format ([`PREVIOUS_FORMAT_VERSION`]) is the same layout with bit 4
//! clear and bytes 336–380 zero: it loads, its Q model without the contact-damping curve (the
//! empirical curve reads the loss until the unit is calibrated again). Older formats are
//! refused (the slot is [`SlotState::Corrupt`]).
//!
//! [`Store::load`] picks the valid record with the highest sequence number (compared with
//! wrap-around). When neither slot holds a valid record (empty, corrupt or unreadable) it falls
//! back to the paper's published calibration ([`PowerLaw::paper_experiment`]) with no air
//! reference, and says so in [`Loaded::source`] so the caller can log a warning and raise a
//! status flag. Nothing here panics, whatever the flash contains.

use crate::loadcell::{ForceWindow, LoadCellCal, LoadCellCounts};
use crate::unit::calibration::{PowerLaw, Source};
use crate::unit::contact_law::{self, ContactLaw};
pub use crate::unit::profile::{AirReference, UnitProfile};
use crate::unit::q_model::{DampingModel, QModel};
use crate::units::{Farads, Hz, Newtons, Siemens};
use embedded_storage::nor_flash::NorFlash;
/// The record's CRC: CRC-32/ISO-HDLC (IEEE 802.3; zlib's), the one the host link's frames carry.
pub use probe_proto::crc32;

/// Bytes of one record (a multiple of every common program word: 1, 2, 4, 8, 16, 32).
pub const RECORD_LEN: usize = 384;
/// Format version written into every record (4: the contact law; 5: the contact force — the
/// law's reference force, the Q model's force term, the load cell, the force window; 6: the Q
/// model's scatter; 7: the Q model's contact-damping curve).
pub const FORMAT_VERSION: u16 = 7;
/// The format before [`FORMAT_VERSION`], still read (module documentation).
pub const PREVIOUS_FORMAT_VERSION: u16 = 6;
const MAGIC: [u8; 4] = *b"PZTC";
const CRC_AT: usize = RECORD_LEN - 4;
const FLAG_AIR: u8 = 1;
const FLAG_Q_MODEL: u8 = 2;
const FLAG_CONTACT: u8 = 4;
const FLAG_LOAD_CELL: u8 = 8;
const FLAG_Q_DAMPING: u8 = 16;

/// State of one slot as found by a scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SlotState {
    /// A valid record with this sequence number.
    Valid(u32),
    /// Erased: never written, or erased and not yet programmed.
    Empty,
    /// Something is there but it is not a valid record (torn write, bit flip, foreign data).
    Corrupt,
    /// The flash reported an error reading the slot.
    Unreadable,
}

/// Where a loaded record came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadSource {
    /// From flash: slot index, its sequence number, and the state of the other slot.
    Stored {
        /// Slot the record was read from (0 or 1).
        slot: u8,
        /// Its sequence number.
        seq: u32,
        /// State of the other slot.
        other: SlotState,
    },
    /// No valid record: the paper's calibration is in use. The states of both slots say why.
    Fallback {
        /// State of slot 0 and slot 1.
        slots: [SlotState; 2],
    },
}

/// The result of [`Store::load`]: always a usable record, and where it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Loaded {
    /// The record to use.
    pub record: UnitProfile,
    /// Where it came from.
    pub source: LoadSource,
}

impl Loaded {
    /// True when the paper's calibration is in use because no valid record exists.
    pub fn is_fallback(&self) -> bool {
        matches!(self.source, LoadSource::Fallback { .. })
    }

    /// True when a slot was found corrupt or unreadable (worth a warning even when a valid
    /// record was loaded from the other slot).
    pub fn damage_seen(&self) -> bool {
        let bad = |s: SlotState| matches!(s, SlotState::Corrupt | SlotState::Unreadable);
        match self.source {
            LoadSource::Stored { other, .. } => bad(other),
            LoadSource::Fallback { slots } => bad(slots[0]) || bad(slots[1]),
        }
    }
}

/// A completed save.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Saved {
    /// Slot written.
    pub slot: u8,
    /// Sequence number written.
    pub seq: u32,
}

/// Why the store could not be set up or a save failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The slots do not fit the flash, or its program/read size does not divide [`RECORD_LEN`],
    /// or the base is not sector aligned.
    Geometry,
    /// The record is not valid (see [`UnitProfile::is_valid`]); nothing was written.
    InvalidRecord,
    /// The flash failed to erase the target slot.
    Erase,
    /// The flash failed to program the record.
    Program,
    /// The read-back differs from what was programmed (or could not be read).
    Verify,
}

/// The two-slot record store over a NOR flash.
#[derive(Debug)]
pub struct Store<F> {
    flash: F,
    slots: [u32; 2],
    slot_len: u32,
}

impl<F: NorFlash> Store<F> {
    /// A store whose two slots start at `base` (offset within `flash`), each the smallest whole
    /// number of erase sectors that holds a record.
    pub fn new(flash: F, base: u32) -> Result<Self, StoreError> {
        let erase = F::ERASE_SIZE.max(1);
        let sectors = RECORD_LEN.div_ceil(erase);
        let slot_len = sectors.checked_mul(erase).ok_or(StoreError::Geometry)?;
        let end = (base as usize)
            .checked_add(slot_len.checked_mul(2).ok_or(StoreError::Geometry)?)
            .ok_or(StoreError::Geometry)?;
        let aligned = |n: usize| n != 0 && RECORD_LEN.is_multiple_of(n);
        if !(base as usize).is_multiple_of(erase)
            || end > flash.capacity()
            || !aligned(F::WRITE_SIZE)
            || !aligned(F::READ_SIZE)
            || u32::try_from(end).is_err()
        {
            return Err(StoreError::Geometry);
        }
        let slot_len = slot_len as u32;
        Ok(Self {
            flash,
            slots: [base, base + slot_len],
            slot_len,
        })
    }

    /// Bytes of flash the store occupies (both slots).
    pub fn footprint(&self) -> u32 {
        2 * self.slot_len
    }

    /// The flash, e.g. for fault injection in tests.
    pub fn flash_mut(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Give the flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    fn scan(&mut self, slot: usize) -> (SlotState, Option<UnitProfile>) {
        let mut buf = [0u8; RECORD_LEN];
        let Some(&at) = self.slots.get(slot) else {
            return (SlotState::Unreadable, None);
        };
        if self.flash.read(at, &mut buf).is_err() {
            return (SlotState::Unreadable, None);
        }
        if buf.iter().all(|&b| b == 0xFF) {
            return (SlotState::Empty, None);
        }
        match decode(&buf) {
            Some((seq, r)) => (SlotState::Valid(seq), Some(r)),
            None => (SlotState::Corrupt, None),
        }
    }

    fn newest(states: &[SlotState; 2]) -> Option<(usize, u32)> {
        match (states[0], states[1]) {
            (SlotState::Valid(a), SlotState::Valid(b)) => {
                if newer(b, a) {
                    Some((1, b))
                } else {
                    Some((0, a))
                }
            }
            (SlotState::Valid(a), _) => Some((0, a)),
            (_, SlotState::Valid(b)) => Some((1, b)),
            _ => None,
        }
    }

    /// Read the newest valid record, or fall back to the paper's calibration.
    pub fn load(&mut self) -> Loaded {
        let (s0, r0) = self.scan(0);
        let (s1, r1) = self.scan(1);
        let states = [s0, s1];
        match Self::newest(&states) {
            Some((0, seq)) => Loaded {
                record: r0.unwrap_or_else(UnitProfile::fallback),
                source: LoadSource::Stored {
                    slot: 0,
                    seq,
                    other: s1,
                },
            },
            Some((_, seq)) => Loaded {
                record: r1.unwrap_or_else(UnitProfile::fallback),
                source: LoadSource::Stored {
                    slot: 1,
                    seq,
                    other: s0,
                },
            },
            None => Loaded {
                record: UnitProfile::fallback(),
                source: LoadSource::Fallback { slots: states },
            },
        }
    }

    /// Store `record` as the new newest record, in the slot not holding the current newest.
    pub fn save(&mut self, record: &UnitProfile) -> Result<Saved, StoreError> {
        if !record.is_valid() {
            return Err(StoreError::InvalidRecord);
        }
        let states = [self.scan(0).0, self.scan(1).0];
        let (slot, seq) = match Self::newest(&states) {
            Some((newest, seq)) => (1 - newest, seq.wrapping_add(1)),
            None => (0, 1),
        };
        let at = self.slots[slot & 1];
        let buf = encode(record, seq);
        self.flash
            .erase(at, at + self.slot_len)
            .map_err(|_| StoreError::Erase)?;
        self.flash
            .write(at, &buf)
            .map_err(|_| StoreError::Program)?;
        let mut back = [0u8; RECORD_LEN];
        self.flash
            .read(at, &mut back)
            .map_err(|_| StoreError::Verify)?;
        if back != buf {
            return Err(StoreError::Verify);
        }
        Ok(Saved {
            slot: slot as u8,
            seq,
        })
    }
}

/// True when sequence number `a` is newer than `b` (serial-number arithmetic).
fn newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

struct Writer {
    buf: [u8; RECORD_LEN],
    at: usize,
}

impl Writer {
    fn put(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if let Some(d) = self.buf.get_mut(self.at) {
                *d = b;
            }
            self.at += 1;
        }
    }
}

struct Reader<'a> {
    buf: &'a [u8; RECORD_LEN],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        for o in out.iter_mut() {
            *o = self.buf.get(self.at).copied().unwrap_or(0);
            self.at += 1;
        }
        out
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
}

fn source_code(s: Source) -> u8 {
    match s {
        Source::PaperSimulation => 0,
        Source::PaperExperiment => 1,
        Source::Fitted => 2,
    }
}

fn source_of(b: u8) -> Option<Source> {
    match b {
        0 => Some(Source::PaperSimulation),
        1 => Some(Source::PaperExperiment),
        2 => Some(Source::Fitted),
        _ => None,
    }
}

/// Serialise `record` with sequence number `seq` (layout in the module documentation).
pub fn encode(record: &UnitProfile, seq: u32) -> [u8; RECORD_LEN] {
    let mut w = Writer {
        buf: [0u8; RECORD_LEN],
        at: 0,
    };
    let c = &record.calibration;
    let damping = record.q_model.and_then(|m| m.damping);
    w.put(&MAGIC);
    w.put(&FORMAT_VERSION.to_le_bytes());
    w.put(&(RECORD_LEN as u16).to_le_bytes());
    w.put(&seq.to_le_bytes());
    w.put(&[
        if record.air.is_some() { FLAG_AIR } else { 0 }
            | if record.q_model.is_some() {
                FLAG_Q_MODEL
            } else {
                0
            }
            | if record.contact.is_some() {
                FLAG_CONTACT
            } else {
                0
            }
            | if record.load_cell.is_some() {
                FLAG_LOAD_CELL
            } else {
                0
            }
            | if damping.is_some() { FLAG_Q_DAMPING } else { 0 },
        source_code(c.source),
        match record.resonance {
            crate::estimate::Resonance::Motional => 0,
            crate::estimate::Resonance::ImpedanceDip => 1,
        },
        0,
    ]);
    for v in [c.a, c.b, c.c] {
        w.put(&v.to_le_bytes());
    }
    for v in c.cov.iter().flatten() {
        w.put(&v.to_le_bytes());
    }
    w.put(&c.min_kpa.to_le_bytes());
    w.put(&c.max_kpa.to_le_bytes());
    w.put(&c.model_sigma_hz.to_le_bytes());
    let (f, q, c0, g0) = record.air.map_or((0.0, 0.0, 0.0, 0.0), |a| {
        (
            a.free_resonance.0,
            a.free_q,
            a.static_capacitance.0,
            a.static_conductance.0,
        )
    });
    for v in [f, q, c0, g0] {
        w.put(&v.to_le_bytes());
    }
    let (q0, q1) = record.q_model.map_or((0.0, 0.0), |m| (m.q0, m.q1));
    w.put(&q0.to_le_bytes());
    w.put(&q1.to_le_bytes());
    let law = record
        .contact
        .map_or([0.0; contact_law::VALUES], |c| c.to_values());
    for v in law {
        w.put(&v.to_le_bytes());
    }
    w.put(&record.q_model.map_or(0.0, |m| m.q2).to_le_bytes());
    let (npc, tare) = record
        .load_cell
        .map_or((0.0f32, 0i32), |c| (c.newtons_per_count, c.tare.0));
    w.put(&npc.to_le_bytes());
    w.put(&tare.to_le_bytes());
    w.put(&record.force_window.min.0.to_le_bytes());
    w.put(&record.force_window.max.0.to_le_bytes());
    w.put(&record.q_model.map_or(0.0, |m| m.sigma_rel).to_le_bytes());
    let d = damping.map_or([0.0; 3], |d| [d.probe_per_s, d.contact_per_s, d.sigma_rel]);
    for v in d {
        w.put(&v.to_le_bytes());
    }
    let crc = crc32(w.buf.get(..CRC_AT).unwrap_or(&[]));
    w.at = CRC_AT;
    w.put(&crc.to_le_bytes());
    w.buf
}

/// Parse and check a record: magic, version ([`FORMAT_VERSION`] or
/// [`PREVIOUS_FORMAT_VERSION`]), length, CRC and content validity. Returns the sequence number
/// and the record.
pub fn decode(buf: &[u8; RECORD_LEN]) -> Option<(u32, UnitProfile)> {
    let mut r = Reader { buf, at: 0 };
    if r.take::<4>() != MAGIC {
        return None;
    }
    let version = u16::from_le_bytes(r.take());
    if !(version == FORMAT_VERSION || version == PREVIOUS_FORMAT_VERSION)
        || u16::from_le_bytes(r.take()) as usize != RECORD_LEN
    {
        return None;
    }
    let stored_crc = u32::from_le_bytes([
        buf[CRC_AT],
        buf[CRC_AT + 1],
        buf[CRC_AT + 2],
        buf[CRC_AT + 3],
    ]);
    if crc32(buf.get(..CRC_AT)?) != stored_crc {
        return None;
    }
    let seq = u32::from_le_bytes(r.take());
    let [flags, source, resonance, _] = r.take::<4>();
    let resonance = match resonance {
        0 => crate::estimate::Resonance::Motional,
        1 => crate::estimate::Resonance::ImpedanceDip,
        _ => return None,
    };
    let source = source_of(source)?;
    let (a, b, c) = (r.f64(), r.f64(), r.f64());
    let mut cov = [[0.0f64; 3]; 3];
    for v in cov.iter_mut().flatten() {
        *v = r.f64();
    }
    let (min_kpa, max_kpa) = (r.f64(), r.f64());
    let model_sigma_hz = r.f64();
    let (f, q, c0, g0) = (r.f32(), r.f32(), r.f32(), r.f32());
    let air = (flags & FLAG_AIR != 0).then_some(AirReference {
        free_resonance: Hz(f),
        free_q: q,
        static_capacitance: Farads(c0),
        static_conductance: Siemens(g0),
    });
    let (q0, q1) = (r.f64(), r.f64());
    let mut law = [0.0; contact_law::VALUES];
    for v in law.iter_mut() {
        *v = r.f64();
    }
    let contact = (flags & FLAG_CONTACT != 0).then(|| ContactLaw::from_values(&law));
    let q2 = r.f64();
    let (npc, tare) = (r.f32(), i32::from_le_bytes(r.take()));
    let load_cell = (flags & FLAG_LOAD_CELL != 0).then_some(LoadCellCal {
        newtons_per_count: npc,
        tare: LoadCellCounts(tare),
    });
    let force_window = ForceWindow {
        min: Newtons(r.f32()),
        max: Newtons(r.f32()),
    };
    let sigma_rel = r.f64();
    let (probe_per_s, contact_per_s, damping_sigma_rel) = (r.f64(), r.f64(), r.f64());
    // The previous format has no such curve (bit 4 clear, its bytes zero).
    if version == PREVIOUS_FORMAT_VERSION && flags & FLAG_Q_DAMPING != 0 {
        return None;
    }
    let damping = (flags & FLAG_Q_DAMPING != 0).then_some(DampingModel {
        probe_per_s,
        contact_per_s,
        sigma_rel: damping_sigma_rel,
    });
    let q_model = (flags & FLAG_Q_MODEL != 0).then_some(QModel {
        q0,
        q1,
        q2,
        sigma_rel,
        damping,
    });
    if damping.is_some() && q_model.is_none() {
        return None;
    }
    let record = UnitProfile {
        calibration: PowerLaw {
            a,
            b,
            c,
            cov,
            model_sigma_hz,
            min_kpa,
            max_kpa,
            source,
        },
        resonance,
        q_model,
        air,
        contact,
        load_cell,
        force_window,
    };
    record.is_valid().then_some((seq, record))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CRC-32/ISO-HDLC bit by bit (reflected polynomial 0xEDB88320, start and final XOR all
    /// ones: zlib's `crc32`), the reference the table-driven `probe_proto::crc32` is held to.
    fn crc32_bitwise(data: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in data {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0xEDB8_8320
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    #[test]
    fn a_records_crc_field_is_zlibs_crc_of_its_bytes() {
        // The catalogue's check value of CRC-32/ISO-HDLC, then the fallback profile as
        // sequence 1: its CRC field is zlib's CRC of the bytes before it, so records in flash
        // written by any earlier build keep verifying.
        assert_eq!(crc32_bitwise(b"123456789"), 0xCBF4_3926);
        let buf = encode(&UnitProfile::fallback(), 1);
        assert_eq!(buf[CRC_AT..], crc32_bitwise(&buf[..CRC_AT]).to_le_bytes());
        assert!(decode(&buf).is_some());
    }

    #[test]
    fn round_trip() {
        let mut cal = PowerLaw::paper_simulation();
        cal.cov[1][2] = 0.25;
        cal.source = Source::Fitted;
        let rec = UnitProfile {
            calibration: cal,
            resonance: crate::estimate::Resonance::ImpedanceDip,
            q_model: Some(QModel {
                q0: 2.5,
                q1: 1.25,
                q2: -4.5,
                sigma_rel: 0.0375,
                damping: Some(DampingModel {
                    probe_per_s: 36.5,
                    contact_per_s: 336.0,
                    sigma_rel: 0.0021,
                }),
            }),
            air: Some(AirReference {
                free_resonance: Hz(232.3),
                free_q: 41.5,
                static_capacitance: Farads(210e-12),
                static_conductance: Siemens(1e-9),
            }),
            contact: Some(ContactLaw {
                free_hz: 232.3,
                p: [13.44, 9.26, 4.88],
                cov: [[1e-4, 2e-5, 0.0], [2e-5, 3e-4, -1e-5], [0.0, -1e-5, 5e-4]],
                model_sigma_hz: 0.004,
                min_kpa: 140.0,
                max_kpa: 2700.0,
                force_n: 0.03,
            }),
            load_cell: Some(LoadCellCal {
                newtons_per_count: 2.8e-7,
                tare: LoadCellCounts(-7123),
            }),
            force_window: ForceWindow {
                min: Newtons(0.015),
                max: Newtons(0.06),
            },
        };
        let buf = encode(&rec, 7);
        assert_eq!(decode(&buf), Some((7, rec)));
        let no_air = UnitProfile::fallback();
        assert_eq!(decode(&encode(&no_air, u32::MAX)), Some((u32::MAX, no_air)));
    }

    /// A record of the previous format (6: no contact-damping curve, bit 4 clear, its bytes
    /// zero) loads with the empirical Q model alone; one that claims the curve, and any older
    /// format, is refused.
    #[test]
    fn the_previous_format_loads_without_the_damping_curve() {
        let unit = crate::board::sim_factory::profile().expect("the factory profile");
        assert!(unit.q_model.is_some_and(|m| m.damping.is_some()));
        let with_version = |version: u16, flags: u8| {
            let mut buf = encode(&unit, 3);
            buf[4..6].copy_from_slice(&version.to_le_bytes());
            buf[12] = flags;
            buf[336..CRC_AT].fill(0);
            let crc = crc32(&buf[..CRC_AT]);
            buf[CRC_AT..].copy_from_slice(&crc.to_le_bytes());
            buf
        };
        let flags = encode(&unit, 3)[12];
        let old = with_version(PREVIOUS_FORMAT_VERSION, flags & !FLAG_Q_DAMPING);
        let mut expect = unit;
        if let Some(m) = expect.q_model.as_mut() {
            m.damping = None;
        }
        assert_eq!(decode(&old), Some((3, expect)));
        assert_eq!(decode(&with_version(PREVIOUS_FORMAT_VERSION, flags)), None);
        assert_eq!(
            decode(&with_version(
                PREVIOUS_FORMAT_VERSION - 1,
                flags & !FLAG_Q_DAMPING
            )),
            None
        );
    }

    #[test]
    fn serial_numbers_wrap() {
        assert!(newer(1, 0));
        assert!(newer(0, u32::MAX));
        assert!(!newer(u32::MAX, 0));
        assert!(!newer(5, 5));
    }
}
