//! Compute cost of one RT tick ([`frictiond::rt::compute`]: per joint model estimate + control law)
//! for 1, 15 (ergoCub legs + torso) and 32 joints of paper-size PINNs — the ankle-roll network of
//! the paper, `[Δθ ×20, ṡ ×20]` → 268 → 215 → 1 (the paper), random weights, stored as f32,
//! f16 and bf16 (the `.fwt` storage dtypes: 32 distinct f32 networks are 8.9 MB of weights, more
//! than this machine's caches; half precision halves the bytes streamed per tick) — and, for
//! reference, the same joint counts with the SCV model, back to back (hot caches; the 1 kHz-paced
//! cost with one or two RT threads and prefetching is `--bench tick_paced`). Results in
//! docs/performance.md; no asserts.
//! Run: `cargo bench -p frictiond --bench tick` (filter e.g. `-- 'tick/pinn.*/32'`).

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use frictiond::rt::{Freshness, compute};
use frictionless::mlp::StorageDtype;
use frictionless_shm_types::{MAX_JOINTS, MotorCurrentCommand};

#[path = "support/tick_params.rs"]
mod tick_params;
use tick_params::{H, inputs, params};

fn tick(c: &mut Criterion) {
    let fresh = Freshness {
        state_stale: false,
        request_stale: false,
    };
    let mut g = c.benchmark_group("tick");
    for (label, pinn) in [
        ("pinn_40x268x215_f32", Some(StorageDtype::F32)),
        ("pinn_40x268x215_f16", Some(StorageDtype::F16)),
        ("pinn_40x268x215_bf16", Some(StorageDtype::Bf16)),
        ("scv", None),
    ] {
        for n in [1usize, 15, 32] {
            let mut p = params(n, pinn, 1);
            let mut inp = inputs(n);
            let mut cmd = MotorCurrentCommand::zeroed();
            let mut tau_f = [0.0; MAX_JOINTS];
            let mut prev = 0u64;
            // Past warm-up, so every tick runs every network.
            for _ in 0..H + 1 {
                compute(&mut p, &inp, fresh, &mut prev, &mut cmd, &mut tau_f);
            }
            let mut k = 0u64;
            g.bench_with_input(BenchmarkId::new(label, n), &n, |b, &n| {
                b.iter(|| {
                    // A changing sample (as on the robot) so nothing is hoisted out of the loop.
                    k += 1;
                    inp.states.value.sdot_rad_s[n - 1] = 0.4 + (k % 100) as f64 * 1e-3;
                    compute(
                        &mut p,
                        black_box(&inp),
                        fresh,
                        &mut prev,
                        &mut cmd,
                        &mut tau_f,
                    );
                    black_box(&cmd);
                })
            });
        }
    }
    g.finish();
}

criterion_group!(benches, tick);
criterion_main!(benches);
