// Windows of arbitrary content for the continuous tracker's tests: included (`include!`) by
// the unit tests of src/instrument/continuous/mod.rs and by tests/stream.rs, which import
// `ChannelSums`, `LockInSums`, `ReferenceSums`, `PointPlan` and `PointRaw` from the crate.

/// A small xorshift generator of 64-bit words from `x` (not zero).
fn xorshift(mut x: u64) -> impl FnMut() -> u64 {
    move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    }
}

/// Window `window` of `plan`, ending at `end_sample`, its demodulator sums drawn from `next`:
/// each sum a word shifted right by a drawn amount (the sums of squares not negative), up to
/// 399 reference samples; the current channel's rail hits drawn too (one window in three) when
/// `rail_hits`, else none.
fn arbitrary_window(
    next: &mut impl FnMut() -> u64,
    plan: PointPlan,
    window: u16,
    end_sample: u64,
    rail_hits: bool,
) -> PointRaw {
    let mut r = || (next() as i64) >> (next() % 64);
    let ch = |r: &mut dyn FnMut() -> i64| ChannelSums {
        xc: r(),
        xs: r(),
        x: r(),
        xx: r().abs(),
    };
    let sums = LockInSums {
        current: ch(&mut r),
        monitor: ch(&mut r),
        reference: ReferenceSums {
            cc: r(),
            ss: r(),
            cs: r(),
            c: r(),
            s: r(),
            n: (next() % 400) as u32,
        },
        current_rail_hits: if rail_hits {
            next().is_multiple_of(3) as u32
        } else {
            0
        },
        monitor_rail_hits: 0,
    };
    PointRaw {
        plan,
        sums,
        end_sample,
        window,
        since_load: 0,
        start_phase: 0,
        quiet_before: 0,
    }
}
