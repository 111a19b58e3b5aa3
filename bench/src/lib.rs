//! Library side of `probe-bench`: scene and option parsing, calibration files, reading reports
//! and plots. The binary (`main.rs`) is the command line on top.

pub mod calfile;
pub mod capture;
pub mod cmd;
pub mod defmt_log;
pub mod gen;
pub mod plot;
pub mod report;
pub mod scene;
