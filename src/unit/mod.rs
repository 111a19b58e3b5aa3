//! The unit's data: its calibration (power law, contact law), its profile and the flash store.
//! May import the leaves, the engine and the estimators; nothing above (reading, instrument,
//! board).

pub mod calibration;
pub mod contact_law;
pub mod profile;
pub mod q_model;
pub mod store;
