//! The host's blocking call of the one reading driver ([`crate::reading::driver::read`]) over any
//! [`SampleStream`]: for `probe-bench`, the tests and single-threaded images.

use crate::engine::sweep::SweepPoint;
use crate::engine::SampleEngine;
use crate::hal::{SampleStream, StreamError};
use crate::loadcell::ForceSource;
use crate::reading::driver::{block_on, read, Stop, SyncSource};
use crate::reading::{Method, Reading, Settings};
use crate::unit::profile::UnitProfile;

/// Why a run stopped early.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunError {
    /// The stream reported an error.
    Stream(StreamError),
    /// A point did not complete within its sample budget.
    Stalled,
}

/// One reading with `method` and `settings` on `stream`, calling `on_point` for every measured
/// admittance point, concluded with the unit's profile.
pub fn run_reading<S: SampleStream + ForceSource>(
    stream: &mut S,
    engine: &mut SampleEngine,
    method: Method,
    settings: &Settings,
    unit: &UnitProfile,
    mut on_point: impl FnMut(&SweepPoint),
) -> Result<Reading, RunError> {
    let mut src = SyncSource::new(stream, engine);
    let mut stalled = false;
    let r = block_on(read(
        &mut src,
        method,
        settings,
        unit,
        |_, p| on_point(p),
        |Stop::Stalled(_)| stalled = true,
    ));
    match (src.error, stalled) {
        (Some(e), _) => Err(RunError::Stream(e)),
        (None, true) => Err(RunError::Stalled),
        (None, false) => Ok(r),
    }
}
