// The fields of a decoded defmt log line (`defmt-print --log-format "{L} {s}"`: `LEVEL name
// k=v k=v ...`), for the tests that run a firmware image: included (`#[path]`) by
// tests/qemu_support/mod.rs (the QEMU image) and by emu/tests/image.rs (the STM32 image on the
// emulated board).

use std::collections::HashMap;

/// A decoded line `LEVEL name k=v k=v ...` as (name, map).
pub type Fields = (String, HashMap<String, String>);

/// `LEVEL name k=v k=v ...` → (name, map).
pub fn fields(line: &str) -> Option<Fields> {
    let mut words = line.split_whitespace();
    let _level = words.next()?;
    let name = words.next()?.to_owned();
    let map = words
        .filter_map(|w| w.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect();
    Some((name, map))
}

/// The number under `key` (panics when missing or not a number).
pub fn num(map: &HashMap<String, String>, key: &str) -> f64 {
    map.get(key)
        .unwrap_or_else(|| panic!("missing {key} in {map:?}"))
        .parse()
        .unwrap_or_else(|_| panic!("{key} is not a number"))
}

/// Every line named `name`, in order.
pub fn all<'a>(parsed: &'a [Fields], name: &str) -> Vec<&'a HashMap<String, String>> {
    parsed
        .iter()
        .filter(|(n, _)| n == name)
        .map(|(_, m)| m)
        .collect()
}

/// The first line named `name` (panics when there is none).
pub fn first(parsed: &[Fields], name: &str) -> HashMap<String, String> {
    parsed
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, m)| m.clone())
        .unwrap_or_else(|| panic!("no `{name}` line"))
}

/// The last line named `name` (panics when there is none).
pub fn last(parsed: &[Fields], name: &str) -> HashMap<String, String> {
    parsed
        .iter()
        .rev()
        .find(|(n, _)| n == name)
        .map(|(_, m)| m.clone())
        .unwrap_or_else(|| panic!("no `{name}` line"))
}
