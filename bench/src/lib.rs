//! Library side of `probe-bench`: scene and option parsing, calibration files, reading reports
//! and plots. The binary (`main.rs`) is the command line on top.
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod accuracy;
pub mod calfile;
pub mod capture;
pub mod cmd;
pub mod defmt_log;
pub mod gen;
pub mod link;
pub mod pareto;
pub mod plot;
pub mod qemu;
pub mod report;
pub mod scene;
pub mod stability;
pub mod stm32;
pub mod stream;
pub mod unit;
