//! Parity of `frictionless::filter` with scipy (`butter`, `sosfilt`, `sosfilt_zi`, `sosfiltfilt`).
//!
//! Needs `FRICTIONLESS_REFS` (set by `tests/run.sh`, written by `tests/python/gen_scipy_refs.py`): the
//! tests are `#[ignore]`d, so a plain `cargo test` reports them as ignored; `tests/run.sh` runs them
//! with `--include-ignored`, and there an unset variable or a missing file fails.

use frictionless::filter::{Butterworth, sosfilt_zi};
use serde::Deserialize;

#[derive(Deserialize)]
struct Case {
    order: usize,
    cutoff_hz: f64,
    fs_hz: f64,
    sos: Vec<[f64; 6]>,
    x: Vec<f64>,
    sosfilt: Vec<f64>,
    sosfiltfilt: Vec<f64>,
    sosfilt_zi: Vec<[f64; 2]>,
}

#[derive(Deserialize)]
struct Refs {
    cases: Vec<Case>,
}

fn load() -> Refs {
    let dir = std::env::var_os("FRICTIONLESS_REFS").expect(
        "FRICTIONLESS_REFS is unset: run bash tests/run.sh (it writes the SciPy references)",
    );
    let path = std::path::Path::new(&dir).join("scipy_filters.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "FRICTIONLESS_REFS is set but {} is missing: {e}",
            path.display()
        )
    });
    serde_json::from_str(&text).expect("scipy_filters.json parses")
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
#[ignore = "needs FRICTIONLESS_REFS: bash tests/run.sh"]
fn butter_sos_equals_scipy() {
    let refs = load();
    assert!(!refs.cases.is_empty());
    for c in &refs.cases {
        let f = Butterworth::lowpass(c.order, c.cutoff_hz, c.fs_hz).unwrap();
        assert_eq!(f.sos.len(), c.sos.len(), "order {}", c.order);
        let d = max_abs_diff(f.sos.as_flattened(), c.sos.as_flattened());
        assert!(
            d < 1e-12,
            "order {} fc {}: sos differs by {d}",
            c.order,
            c.cutoff_hz
        );
        let zi = sosfilt_zi(&f.sos);
        let d = max_abs_diff(zi.as_flattened(), c.sosfilt_zi.as_flattened());
        assert!(d < 1e-10, "order {}: zi differs by {d}", c.order);
    }
}

#[test]
#[ignore = "needs FRICTIONLESS_REFS: bash tests/run.sh"]
fn sosfilt_and_sosfiltfilt_equal_scipy() {
    let refs = load();
    let mut worst = 0.0f64;
    for c in &refs.cases {
        let f = Butterworth::lowpass(c.order, c.cutoff_hz, c.fs_hz).unwrap();
        let d1 = max_abs_diff(&f.filter(&c.x), &c.sosfilt);
        let d2 = max_abs_diff(&f.filtfilt(&c.x).unwrap(), &c.sosfiltfilt);
        assert!(
            d1 < 1e-9,
            "order {} fc {}: sosfilt differs by {d1}",
            c.order,
            c.cutoff_hz
        );
        assert!(
            d2 < 1e-9,
            "order {} fc {}: sosfiltfilt differs by {d2}",
            c.order,
            c.cutoff_hz
        );
        worst = worst.max(d1).max(d2);
    }
    println!("worst |rust − scipy| over all cases: {worst:e}");
}
