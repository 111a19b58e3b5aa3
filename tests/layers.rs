//! The crate's layers hold: no module of `src/` names (`crate::…`, or `super::…` resolving to
//! another top-level module) a module of a layer above its own. The layers, lowest first, are
//! those `src/lib.rs` and docs/architecture.md state; a top-level module not in the table
//! fails the test until it is given a layer. Test modules (`#[cfg(test)] mod tests`) are left
//! out: a test may reach up to build its fixtures.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Each top-level module of the crate and its layer (0 lowest).
const LAYERS: &[(&str, u8)] = &[
    ("units", 0),
    ("status", 0),
    ("counters", 0),
    ("stack", 0),
    ("boot", 0),
    ("hal", 0),
    ("linalg", 0),
    ("loadcell", 0),
    ("dsp", 0),
    ("engine", 1),
    ("estimate", 2),
    ("unit", 3),
    ("reading", 4),
    ("instrument", 5),
    ("board", 6),
];

fn layer(top: &str) -> Option<u8> {
    LAYERS.iter().find(|(m, _)| *m == top).map(|&(_, l)| l)
}

/// Every `.rs` file under `dir` except `src/bin` (the binaries sit above every layer).
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("read src/") {
        let p = e.expect("dir entry").path();
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n != "bin") {
                files(&p, out);
            }
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module path of a file below `src/` (`engine/mod.rs` → `[engine]`).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("under src");
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The code of a file without line comments and without its test module.
fn code(text: &str) -> String {
    let body = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => text,
    };
    body.lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The first path segment after each occurrence of `crate::` (the top-level module named).
fn crate_targets(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        let before = rest[..i].chars().last();
        rest = &rest[i + "crate::".len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // `pzt_probe_crate::` or similar: not this crate
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !name.is_empty() {
            out.push(name);
        }
    }
    out
}

/// The top-level modules `super::…` paths reach from `module` (only those that leave the
/// file's own top-level module matter).
fn super_targets(module: &[String], code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("super::") {
        let before = rest[..i].chars().last();
        rest = &rest[i..];
        let mut ups = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            ups += 1;
            rest = r;
        }
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        // From module a::b::c, `super::x` names a::b::x: the top level is left only when
        // the path climbs to the crate root.
        if ups >= module.len() && !name.is_empty() {
            out.push(name);
        }
    }
    out
}

#[test]
fn no_module_imports_from_a_layer_above_its_own() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut all = Vec::new();
    files(&src, &mut all);
    assert!(all.len() > 20, "src/ not found or nearly empty");
    let mut violations = BTreeMap::new();
    let mut unknown = Vec::new();
    for file in &all {
        let module = module_of(&src, file);
        let Some(top) = module.first() else {
            continue; // lib.rs declares the layers
        };
        let Some(own) = layer(top) else {
            unknown.push(top.clone());
            continue;
        };
        let text = std::fs::read_to_string(file).expect("read");
        let body = code(&text);
        for target in crate_targets(&body)
            .into_iter()
            .chain(super_targets(&module, &body))
        {
            // Root items (`crate::PowerLaw`, re-exported at lib.rs) are layer-checked at
            // their definition; only modules are named here.
            if let Some(l) = layer(&target) {
                if l > own {
                    violations
                        .entry(file.strip_prefix(&src).unwrap().display().to_string())
                        .or_insert_with(Vec::new)
                        .push(format!("{target} (layer {l} > {own})"));
                }
            }
        }
    }
    unknown.sort();
    unknown.dedup();
    assert!(
        unknown.is_empty(),
        "top-level modules without a layer in tests/layers.rs: {unknown:?}"
    );
    assert!(
        violations.is_empty(),
        "modules importing from a layer above their own: {violations:#?}"
    );
}

#[test]
fn the_layer_check_sees_a_violation() {
    // The parser itself: an upward path is found, a comment and a lookalike are not.
    let code = code("use crate::board::sim; // crate::instrument\nlet x = my_crate::reading;");
    assert_eq!(crate_targets(&code), vec!["board".to_string()]);
    let m = vec!["engine".to_string(), "sweep".to_string()];
    assert_eq!(
        super_targets(&m, "super::super::reading::X"),
        vec!["reading"]
    );
    assert!(super_targets(&m, "super::SampleEngine").is_empty());
}

#[test]
fn every_top_level_module_of_lib_rs_has_a_layer() {
    let lib = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("src/lib.rs"))
        .expect("read lib.rs");
    let mods: Vec<&str> = lib
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|l| l.trim_end_matches(';'))
        .collect();
    assert!(mods.len() >= LAYERS.len(), "lib.rs modules: {mods:?}");
    for m in mods {
        assert!(layer(m).is_some(), "`{m}` has no layer in tests/layers.rs");
    }
}

#[test]
fn the_protocol_crate_is_a_leaf() {
    // `proto/` depends on no crate of this workspace (the firmware, the simulator and the bench
    // use it, never the other way), so a client in any language needs only docs/protocol.md.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let manifest =
        std::fs::read_to_string(root.join("proto/Cargo.toml")).expect("proto/Cargo.toml");
    assert!(
        !manifest.contains("{ path ="),
        "proto/Cargo.toml names a path dependency"
    );
    let mut files = Vec::new();
    for e in std::fs::read_dir(root.join("proto/src")).expect("proto/src") {
        files.push(e.expect("dir entry").path());
    }
    for f in files {
        let text = std::fs::read_to_string(&f).expect("read");
        for krate in ["pzt_probe", "hal_sim", "probe_bench", "probe_rng"] {
            assert!(!text.contains(krate), "{} names {krate}", f.display());
        }
    }
}
