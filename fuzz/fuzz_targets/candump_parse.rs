//! Fuzz target: arbitrary text into the `candump -L` log parser (`frictionless-canlog`, a small crate,
//! so the fuzz build does not pull frictl's dependencies).
//!
//! Never panics. Round trip: a line the parser accepts is formatted canonically by `format_entry`,
//! and that canonical line parses back to the same entry (so `frictl can record` output replays
//! exactly what was recorded). `parse_log` over the whole input must not panic either, and accepts
//! exactly when every non-blank line parses.
#![no_main]

use frictionless_canlog as canlog;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for (i, line) in text.lines().enumerate() {
        if let Ok(e) = canlog::parse_line(line, i + 1, "<fuzz>") {
            let canon = canlog::format_entry(&e);
            let again = canlog::parse_line(&canon, 1, "<canonical>").unwrap_or_else(|err| {
                panic!("canonical line `{canon}` of `{line}` refused: {err}")
            });
            assert_eq!(again, e, "`{line}` → `{canon}`");
            assert_eq!(canlog::format_entry(&again), canon);
        }
    }
    let all = canlog::parse_log(std::io::Cursor::new(data), "<fuzz>");
    let each_ok = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .all(|(i, l)| canlog::parse_line(l, i + 1, "<fuzz>").is_ok());
    assert_eq!(all.is_ok(), each_ok);
});
