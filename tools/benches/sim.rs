//! Simulator speed: one simulated second (1000 samples × 20 physics steps) of each preset, on the fast
//! path (the default) and on the reference path (libm and the link every physics step).
//! Real-time factor = 1 s / reported time (target ≥ 1000×, i.e. ≤ 1 ms per iteration).

use criterion::{Criterion, criterion_group, criterion_main};
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

criterion_group!(benches, one_simulated_second);
criterion_main!(benches);
