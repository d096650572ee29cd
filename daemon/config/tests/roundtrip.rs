//! Every shipped frictiond config (`config/*.toml`; `config/presets/` holds plant presets) parses, serialises with
//! `toml::to_string` and re-parses to an equal value.

use std::path::{Path, PathBuf};

fn shipped_configs() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let mut files = Vec::new();
    for e in std::fs::read_dir(&root).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            files.push(p);
        }
    }
    files.sort();
    files
}

#[test]
fn shipped_configs_round_trip_through_toml() {
    let files = shipped_configs();
    assert!(files.len() >= 5, "{files:?}");
    let mut with_buses = 0;
    for f in &files {
        let cfg = frictiond_config::load(f).unwrap_or_else(|e| panic!("{e}"));
        let text = toml::to_string(&cfg.raw).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        // Same path, so relative model paths resolve the same way.
        let again = frictiond_config::parse(f, &text)
            .unwrap_or_else(|e| panic!("{}: re-parse: {e}\n{text}", f.display()));
        assert_eq!(again.raw, cfg.raw, "{}\n{text}", f.display());
        assert_eq!(again.models, cfg.models, "{}", f.display());
        assert_eq!(again.buses, cfg.buses, "{}", f.display());
        with_buses += usize::from(!cfg.buses.is_empty());
    }
    assert!(
        with_buses >= 2,
        "the CAN configs are among the shipped ones"
    );
}

#[test]
fn serialised_defaults_keep_their_values() {
    let text = r#"
[backend]
kind = "shm"
[[joint]]
name = "j"
index = 0
gear_ratio = -100.0
kt = 0.1
max_curr = 2.0
friction_model = "cv"
kc = 1.0
ka = 10.0
kv = 0.5
"#;
    let p = Path::new("/nonexistent/t.toml");
    let cfg = frictiond_config::parse(p, text).unwrap();
    let out = toml::to_string(&cfg.raw).unwrap();
    // An infinite friction clip and absent options survive the trip.
    let again = frictiond_config::parse(p, &out).unwrap();
    assert!(
        again.raw.joint[0].max_output_friction.is_infinite(),
        "{out}"
    );
    assert_eq!(again.raw.joint[0].lpf, None);
    assert_eq!(
        again.raw.joint[0].friction_model,
        frictiond_config::ModelKind::Cv
    );
    assert_eq!(again.raw, cfg.raw);
}
