//! Fuzz target: the dataset CSV reader (`Dataset::read_csv`, `read_columns`) and the JSON sidecar
//! (`DatasetSidecar`, `dataset_runs`) and fit-file readers (`FittedModel::read`) of
//! `frictionless-dataset`, as `frictl train`, `fit`, `eval` and `predict` read them.
//!
//! Input: the CSV bytes, then (after the first 0xFF byte, which never occurs in UTF-8) the JSON
//! bytes. Every reader must return a value or an error naming the file, never panic.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use frictionless_dataset::fit_file::FittedModel;
use frictionless_dataset::{Dataset, DatasetSidecar};
use libfuzzer_sys::fuzz_target;

/// One scratch directory per fuzzing process (the readers take paths).
fn dir() -> &'static PathBuf {
    static D: OnceLock<PathBuf> = OnceLock::new();
    D.get_or_init(|| {
        let base = if std::path::Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let d = base.join(format!("frictionless-fuzz-dataset-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("scratch dir");
        d
    })
}

fuzz_target!(|data: &[u8]| {
    let (csv, json) = match data.iter().position(|&b| b == 0xFF) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let csv_path = dir().join("ds.csv");
    std::fs::write(&csv_path, csv).expect("write scratch CSV");
    if let Ok(ds) = Dataset::read_csv(&csv_path) {
        let n = ds.time_s.len();
        assert!(
            ds.sdot_rad_s.len() == n && ds.valid.len() == n && ds.tau_f_label_nm.len() == n,
            "every column has one value per row"
        );
    }
    let _ = frictionless_dataset::read_columns(&csv_path);
    if let Ok(side) = serde_json::from_slice::<DatasetSidecar>(json) {
        // The runs come from the sidecar when it lists them, else from the data's own chunk column
        // (never from the sidecar's claimed chunk count).
        let empty = frictionless_dataset::Dataset::default();
        let _ = frictionless_dataset::dataset_runs(&csv_path, Some(&side), &empty);
    }
    let fit_path = dir().join("fit.json");
    std::fs::write(&fit_path, json).expect("write scratch JSON");
    let _ = FittedModel::read(&fit_path);
});
