//! Fuzz target: arbitrary text as a frictiond TOML config, through the validation `frictiond --check`
//! runs: `frictiond_config::parse` (schema, every range, buses and drives, model-file checks), then,
//! for an accepted config, `frictiond_config::params::build` (estimators, filter design, laws).
//!
//! Both must return an error or a value, never panic. An accepted config must also re-validate after
//! a round trip through `toml::to_string` of its raw form (what `frictl` writes for frictiond).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Relative model paths resolve against a directory that does not exist: model files are
    // refused by the same check, never opened from the fuzzer's working directory.
    let path = Path::new("/nonexistent/frictiond-fuzz/frictiond.toml");
    let Ok(cfg) = frictiond_config::parse(path, text) else {
        return;
    };
    let _ = frictiond_config::params::build(&cfg, 0);
    let again = toml::to_string(&cfg.raw).expect("an accepted config serialises");
    frictiond_config::parse(path, &again)
        .expect("an accepted config re-validates after a round trip");
});
