//! Linker setup of the firmware images (nothing happens for host builds): the top linker script
//! and the memory map of the board.
//!
//! * STM32 image (feature `stm32`): `-Tlink.x` (cortex-m-rt) with the root `memory.x`, the
//!   STM32G474RE map, as the embedded Rust convention has it. `link.x` `INCLUDE`s `memory.x`;
//!   the linker finds it in its working directory (the package root), and the copy written into
//!   `OUT_DIR` (on the link search path) serves a link run from anywhere else.
//! * QEMU image (feature `qemu`): `-Tmps2-an386.x`, the mps2-an386 map (`memory/mps2-an386.x`),
//!   which `INCLUDE`s `link.x` after its regions. The linker (rust-lld, and flip-link around it)
//!   looks for an `INCLUDE`d script in its working directory before the search path, so
//!   `link.x`'s `INCLUDE memory.x` would find the root `memory.x` whatever `OUT_DIR` holds:
//!   `--remap-inputs` makes it read an empty script (`no-memory.x`) instead. The map is the
//!   first script of the link, so flip-link, which takes the first `RAM` region among the scripts
//!   it finds, flips this one. `device.x` is written here too: the default handlers of the
//!   mps2-an386 interrupt lines named in `src/board/qemu.rs` (the STM32 PAC brings its own).
//!
//! [`link_plan`] is the choice; `tests/memory_map.rs` checks it, the maps and the store's place,
//! `scripts/ci-firmware` the section addresses of the linked images.

use std::env;
use std::fs;
use std::path::{Path, PathBuf};

/// How a firmware image is linked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkPlan {
    /// The memory map (relative to the package root).
    pub map: &'static str,
    /// Its name in `OUT_DIR`.
    pub name: &'static str,
    /// The top linker script (`-T`).
    pub script: &'static str,
    /// `memory.x` (the root STM32 map) remapped to an empty script.
    pub remap_memory_x: bool,
    /// `device.x` written here (no PAC provides it).
    pub device_x: bool,
}

/// The STM32G474RE map (the root `memory.x`).
pub const STM32_MAP: &str = "memory.x";
/// The QEMU mps2-an386 map.
pub const QEMU_MAP: &str = "memory/mps2-an386.x";

/// The link of the image with these board features; `Ok(None)` for neither (the portable
/// library alone, e.g. a `--lib` check for the target: nothing to link).
pub fn link_plan(stm32: bool, qemu: bool) -> Result<Option<LinkPlan>, &'static str> {
    match (stm32, qemu) {
        (true, false) => Ok(Some(LinkPlan {
            map: STM32_MAP,
            name: "memory.x",
            script: "link.x",
            remap_memory_x: false,
            device_x: false,
        })),
        (false, true) => Ok(Some(LinkPlan {
            map: QEMU_MAP,
            name: "mps2-an386.x",
            script: "mps2-an386.x",
            remap_memory_x: true,
            device_x: true,
        })),
        (true, true) => Err("features `stm32` and `qemu` are exclusive"),
        (false, false) => Ok(None),
    }
}

/// The empty script `link.x`'s `INCLUDE memory.x` reads in the QEMU link.
const NO_MEMORY_X: &str = "/* The QEMU image's map is mps2-an386.x (build.rs): link.x's `INCLUDE memory.x` reads\n * this empty script instead of the root memory.x, the STM32 map. */\n";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={STM32_MAP}");
    println!("cargo:rerun-if-changed={QEMU_MAP}");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let plan = link_plan(
        env::var_os("CARGO_FEATURE_STM32").is_some(),
        env::var_os("CARGO_FEATURE_QEMU").is_some(),
    );
    let plan = match plan {
        Ok(Some(plan)) => plan,
        Ok(None) => return,
        Err(e) => panic!("{e}"),
    };
    fs::copy(plan.map, out.join(plan.name)).expect("copy the memory map");
    // Binaries only: the firmware images (probe, cost); the library is not linked.
    println!("cargo:rustc-link-arg-bins=-T{}", plan.script);
    // Both images log with defmt.
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    if plan.remap_memory_x {
        let empty = out.join("no-memory.x");
        fs::write(&empty, NO_MEMORY_X).expect("write no-memory.x");
        // `memory.x` as found in the working directory, `*/memory.x` as found on the search
        // path (flip-link's second link runs in a temporary directory).
        for from in ["memory.x", "*/memory.x"] {
            println!(
                "cargo:rustc-link-arg-bins=--remap-inputs={from}={}",
                path_str(&empty)
            );
        }
    }
    if plan.device_x {
        // Default handlers of the interrupt lines the QEMU device module names.
        fs::write(
            out.join("device.x"),
            "PROVIDE(LPUART1 = DefaultHandler);\nPROVIDE(DMA1_CHANNEL1 = DefaultHandler);\nPROVIDE(SPI3 = DefaultHandler);\nPROVIDE(SPI2 = DefaultHandler);\n",
        )
        .expect("write device.x");
    }
    println!("cargo:rustc-link-search={}", out.display());
}

fn path_str(p: &Path) -> &str {
    p.to_str().expect("OUT_DIR is UTF-8")
}
