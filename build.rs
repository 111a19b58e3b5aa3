//! Linker setup of the firmware images (nothing happens for host builds).
//!
//! For `target_os = "none"` it copies the memory layout of the selected board into `OUT_DIR` as
//! `memory.x` (read by cortex-m-rt's `link.x`): `memory/stm32g474re.x` with feature `stm32`,
//! `memory/mps2-an386.x` with feature `qemu`. For QEMU it also writes `device.x`, the default
//! handlers of the mps2-an386 interrupt lines named in `src/board/qemu.rs` (the STM32 PAC brings
//! its own). The layouts live in `memory/` rather than a root `memory.x` so the linker, which
//! also searches the working directory, can never pick the wrong one.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory/stm32g474re.x");
    println!("cargo:rerun-if-changed=memory/mps2-an386.x");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let stm32 = env::var_os("CARGO_FEATURE_STM32").is_some();
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let layout = match (stm32, qemu) {
        (true, false) => "memory/stm32g474re.x",
        (false, true) => "memory/mps2-an386.x",
        (true, true) => panic!("features `stm32` and `qemu` are exclusive"),
        // The portable library alone (e.g. a `--lib` check for the target): nothing to link.
        (false, false) => return,
    };
    fs::copy(layout, out.join("memory.x")).expect("copy memory layout");
    if qemu {
        // Default handlers of the interrupt lines the QEMU device module names.
        fs::write(
            out.join("device.x"),
            "PROVIDE(LPUART = DefaultHandler);\nPROVIDE(DMA1_CH1 = DefaultHandler);\nPROVIDE(SPI3 = DefaultHandler);\n",
        )
        .expect("write device.x");
    }
    println!("cargo:rustc-link-search={}", out.display());
}
