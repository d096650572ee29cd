//! Simulator speed: one simulated second (1000 samples × 20 physics steps) of each preset, on the fast
//! path (the default) and on the reference path (libm and the link every physics step).
//! Real-time factor = 1 s / reported time (target ≥ 1000×, i.e. ≤ 1 ms per iteration).
//!
//! `sim_protocol_ankle_roll`: the real acquisition excitation ([`frictionless_acquire::protocol::run`] with
//! the preset's `[protocol]`: re-centring, current sines, ramps, steps, closed-loop tracking) on the
//! simulator for a fixed simulated span (every k-th block of the schedule, printed at start), i.e.
//! the speeds `frictl acquire` really produces, controller and velocity filter included. Plant
//! construction is outside the timing. Real-time factor = span / reported time.
//!
//! Also the dataset writer: 1000 simulated samples through [`frictionless_acquire::log::CsvLog`] into
//! memory (the CSV formatting cost of one simulated second of `frictl acquire`).

use criterion::BatchSize;
use criterion::{Criterion, criterion_group, criterion_main};
use frictionless_acquire::config::ProtocolConfig;
use frictionless_acquire::log::CsvLog;
use frictionless_acquire::protocol::{
    self, ControllerModel, LogRow, Mode, SimJoint, schedule, schedule_duration_s,
};
use frictionless_sim::params::load_table;
use frictionless_sim::{Plant, PlantParams};
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

/// Simulated span of `sim_protocol_ankle_roll` (at least; whole blocks) [s].
const PROTOCOL_SPAN_S: f64 = 30.0;

fn protocol_ankle_roll(c: &mut Criterion) {
    let table = load_table("ankle_roll", None, &[]).expect("built-in preset");
    let params = PlantParams::from_table(&table).expect("valid preset");
    let cfg = ProtocolConfig::from_table(&table).expect("valid protocol");
    let all = schedule(&cfg);
    // every k-th block so the span samples sines, ramps, steps and tracking alike
    let total_s = schedule_duration_s(&all);
    let stride = ((total_s / PROTOCOL_SPAN_S).floor() as usize).max(1);
    let mut blocks = Vec::new();
    for b in all.iter().step_by(stride) {
        blocks.push(b.clone());
        if schedule_duration_s(&blocks) >= PROTOCOL_SPAN_S {
            break;
        }
    }
    let span_s = schedule_duration_s(&blocks);
    eprintln!(
        "sim_protocol_ankle_roll: {} of {} blocks (every {stride}th), {span_s:.3} simulated s \
         (whole schedule {total_s:.1} s)",
        blocks.len(),
        all.len()
    );
    let link = frictionless_sim::link::link_from_model(&params.link).expect("valid link");
    let model = ControllerModel::nominal(&params, link.as_ref());
    let mut group = c.benchmark_group("protocol");
    group.sample_size(10);
    group.bench_function("sim_protocol_ankle_roll", |b| {
        b.iter_batched(
            || SimJoint {
                plant: Plant::from_params(params.clone(), 1).expect("valid preset"),
                tau_ext_nm: 0.0,
            },
            |mut joint| {
                let mut acc = 0.0;
                let summary = protocol::run(&mut joint, &model, &cfg, &blocks, &mut |row| {
                    acc += row.i_ref_a;
                    Ok(())
                })
                .expect("simulated run");
                black_box((acc, summary.chunks))
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
}

criterion_group!(
    benches,
    one_simulated_second,
    protocol_ankle_roll,
    csv_one_simulated_second
);
criterion_main!(benches);
