//! Simulator speed: one simulated second (1000 samples × 20 physics steps) of each preset, on the fast
//! path (the default) and on the reference path (libm and the link every physics step).
//! Real-time factor = 1 s / reported time (target ≥ 1000×, i.e. ≤ 1 ms per iteration).
//!
//! Also the dataset writer: 1000 simulated samples through [`frictl::acquire::log::CsvLog`] into
//! memory (the CSV formatting cost of one simulated second of `frictl acquire`).

use criterion::{Criterion, criterion_group, criterion_main};
use frictl::acquire::log::CsvLog;
use frictl::acquire::protocol::{LogRow, Mode};
use frictl::sim::{Plant, PlantParams};
use std::hint::black_box;

fn one_simulated_second(c: &mut Criterion) {
    for preset in ["knee", "ankle_roll"] {
        for reference in [false, true] {
            let params = PlantParams::preset(preset).expect("built-in preset");
            let mut plant = Plant::from_params(params, 1).expect("valid preset");
            plant.set_reference_math(reference);
            let mut k = 0u64;
            let name = if reference {
                format!("sim_1s_{preset}_reference")
            } else {
                format!("sim_1s_{preset}")
            };
            c.bench_function(&name, |b| {
                b.iter(|| {
                    let mut acc = 0.0;
                    for _ in 0..1000 {
                        // a 0.5 Hz current sine: sliding, reversals and stiction all happen
                        let i_ref = 0.6 * (k as f64 * 1e-3 * std::f64::consts::PI).sin();
                        k += 1;
                        acc += plant.step(black_box(i_ref), 0.0).truth.tau_f_nm;
                    }
                    black_box(acc)
                })
            });
        }
    }
}

fn csv_one_simulated_second(c: &mut Criterion) {
    let params = PlantParams::preset("ankle_roll").expect("built-in preset");
    let mut plant = Plant::from_params(params, 1).expect("valid preset");
    let rows: Vec<LogRow> = (0..1000)
        .map(|k| {
            let i_ref_a = 0.6 * (k as f64 * 1e-3 * std::f64::consts::PI).sin();
            let s = plant.step(i_ref_a, 0.0);
            LogRow {
                chunk: 7,
                active: true,
                mode: Mode::Current,
                meas: s.meas,
                i_ref_a,
                truth: Some(s.truth),
            }
        })
        .collect();
    let mut out = Vec::with_capacity(1 << 20);
    c.bench_function("csv_1s_ankle_roll_with_truth", |b| {
        b.iter(|| {
            out.clear();
            let mut log = CsvLog::new(&mut out, true).expect("in-memory log");
            for r in &rows {
                log.write(black_box(r)).expect("in-memory log");
            }
            log.finish().expect("in-memory log");
            black_box(out.len())
        })
    });
}

criterion_group!(benches, one_simulated_second, csv_one_simulated_second);
criterion_main!(benches);
