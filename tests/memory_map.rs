//! The firmware images' memory maps and build.rs's choice between them (host only, no build of
//! an image; `scripts/ci-firmware` checks the section addresses of the linked images).
//!
//! * build.rs links the STM32 image with the root `memory.x` through `link.x`, the QEMU images
//!   with `memory/mps2-an386.x` as their top script and `memory.x` remapped away.
//! * `memory.x` is the STM32G474RE map with FLASH on bank 1 (256 KiB at 0x0800_0000) and the
//!   96 KiB of SRAM1 + SRAM2; the calibration store (`STORE_BASE` of
//!   `src/board/stm32g474/store.rs`, with the footprint `Store` gives it on the chip's 2 KiB
//!   pages) lies outside FLASH, inside bank 2, and agrees with the map's
//!   `_pzt_store_start`/`_pzt_store_end`.
//! * `memory/mps2-an386.x` puts FLASH at 0 (QEMU loads the image there, the vector table must be
//!   at 0) and RAM in SSRAM2/3, and includes `link.x` after its regions.

#[allow(dead_code)]
#[path = "../build.rs"]
mod build_script;

use build_script::{link_plan, LinkPlan, QEMU_MAP, STM32_MAP};
use hal_sim::flash::SimFlash;
use pzt_probe::unit::store::Store;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn read(path: &str) -> String {
    std::fs::read_to_string(format!("{ROOT}/{path}")).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// A linker script without its comments.
fn strip_comments(s: &str) -> String {
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find("/*") {
        out.push_str(&rest[..i]);
        let end = rest[i..].find("*/").expect("unterminated comment") + i + 2;
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// A number of a linker script: hex or decimal, with an optional K or M suffix.
fn number(s: &str) -> u64 {
    let s = s.trim();
    let (digits, scale) = match s.strip_suffix('K') {
        Some(d) => (d, 1024),
        None => match s.strip_suffix('M') {
            Some(d) => (d, 1024 * 1024),
            None => (s, 1),
        },
    };
    let digits = digits.trim();
    let v = match digits.strip_prefix("0x") {
        Some(h) => u64::from_str_radix(h, 16),
        None => digits.parse(),
    };
    v.unwrap_or_else(|_| panic!("not a number: {s}")) * scale
}

/// The regions of the script's MEMORY command: (name, origin, length).
fn regions(script: &str) -> Vec<(String, u64, u64)> {
    let s = strip_comments(script);
    let start = s.find("MEMORY").expect("no MEMORY command");
    let body = &s[start..];
    let body = &body[body.find('{').unwrap() + 1..body.find('}').unwrap()];
    body.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(|l| {
            let (name, rest) = l.split_once(':').expect("region line");
            let (origin, length) = rest.split_once(',').expect("ORIGIN, LENGTH");
            let origin = origin.trim().strip_prefix("ORIGIN").unwrap().trim();
            let length = length.trim().strip_prefix("LENGTH").unwrap().trim();
            (
                name.trim().to_string(),
                number(origin.strip_prefix('=').unwrap()),
                number(length.strip_prefix('=').unwrap()),
            )
        })
        .collect()
}

fn region(script: &str, name: &str) -> (u64, u64) {
    regions(script)
        .into_iter()
        .find(|r| r.0 == name)
        .map(|r| (r.1, r.2))
        .unwrap_or_else(|| panic!("no region {name}"))
}

/// The value of `symbol = value;` in a linker script.
fn symbol(script: &str, symbol: &str) -> u64 {
    let s = strip_comments(script);
    let line = s
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with(symbol) && l.contains('='))
        .unwrap_or_else(|| panic!("no symbol {symbol}"));
    number(line.split_once('=').unwrap().1.trim_end_matches(';'))
}

const FLASH_BASE: u64 = 0x0800_0000;
const BANK: u64 = 256 * 1024;
const PAGE: usize = 2048;

#[test]
fn build_rs_links_each_image_with_its_own_map() {
    assert_eq!(
        link_plan(true, false),
        Ok(Some(LinkPlan {
            map: "memory.x",
            name: "memory.x",
            script: "link.x",
            remap_memory_x: false,
            device_x: false,
        }))
    );
    assert_eq!(
        link_plan(false, true),
        Ok(Some(LinkPlan {
            map: "memory/mps2-an386.x",
            name: "mps2-an386.x",
            script: "mps2-an386.x",
            remap_memory_x: true,
            device_x: true,
        }))
    );
    assert!(link_plan(true, true).is_err());
    assert_eq!(link_plan(false, false), Ok(None));
    // The QEMU map is its own top script: its regions first, then cortex-m-rt's sections.
    let qemu = strip_comments(&read(QEMU_MAP));
    let memory = qemu.find("MEMORY").unwrap();
    let include = qemu
        .find("INCLUDE link.x")
        .expect("mps2-an386.x includes link.x");
    assert!(memory < include);
    // The STM32 map is what link.x includes: regions only, no INCLUDE of its own.
    assert!(!strip_comments(&read(STM32_MAP)).contains("INCLUDE"));
}

#[test]
fn stm32_map_is_bank_1_and_sram1_sram2() {
    let map = read(STM32_MAP);
    assert_eq!(region(&map, "FLASH"), (FLASH_BASE, BANK));
    assert_eq!(region(&map, "RAM"), (0x2000_0000, 96 * 1024));
    assert_eq!(regions(&map).len(), 2);
}

#[test]
fn qemu_map_loads_at_zero() {
    let map = read(QEMU_MAP);
    assert_eq!(region(&map, "FLASH"), (0, 1024 * 1024));
    assert_eq!(region(&map, "RAM"), (0x2000_0000, 1024 * 1024));
    assert_eq!(regions(&map).len(), 2);
}

#[test]
fn store_is_outside_the_image_and_agrees_with_the_map() {
    // STORE_BASE of the STM32 board (that module builds only for the target).
    let board = read("src/board/stm32g474/store.rs");
    let line = board
        .lines()
        .find(|l| l.starts_with("pub const STORE_BASE: u32 ="))
        .expect("STORE_BASE in src/board/stm32g474/store.rs");
    let base = number(
        &line
            .split_once('=')
            .unwrap()
            .1
            .trim()
            .trim_end_matches(';')
            .replace('_', ""),
    );
    // The store's footprint on the chip's geometry: 512 KiB, 2 KiB pages, 8-byte words.
    let mut flash = Box::new(SimFlash::<{ 512 * 1024 }, PAGE, 8>::new());
    let store = Store::new(&mut *flash, base as u32).expect("the store fits the chip's flash");
    let start = FLASH_BASE + base;
    let end = start + u64::from(store.footprint());

    let map = read(STM32_MAP);
    let (flash, len) = region(&map, "FLASH");
    assert!(flash + len <= start, "FLASH overlaps the store");
    assert!(start >= FLASH_BASE + BANK, "the store is not in bank 2");
    assert!(
        end <= FLASH_BASE + 2 * BANK,
        "the store runs past the flash"
    );
    assert_eq!(symbol(&map, "_pzt_store_start"), start);
    assert_eq!(symbol(&map, "_pzt_store_end"), end);
}
