//! RNEA speed on the project's 15-DoF leg + torso model (`config/urdf/virtual_leg.urdf`): target
//! ≤ 5 µs per evaluation (10⁶ in ≤ 5 s), no allocation per call. Also the single-joint gravity
//! closed form and table the 20 kHz simulator calls, and CRBA for reference.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frictionless_dynamics::{BaseState, Workspace, virtual_leg};
use nalgebra::DMatrix;

fn bench(c: &mut Criterion) {
    let robot = virtual_leg().expect("virtual leg parses");
    let n = robot.dof();
    let mut ws = Workspace::new(&robot);
    let q: Vec<f64> = (0..n).map(|i| 0.1 * i as f64 - 0.6).collect();
    let qd: Vec<f64> = (0..n).map(|i| 0.3 - 0.05 * i as f64).collect();
    let qdd: Vec<f64> = (0..n).map(|i| 1.0 - 0.1 * i as f64).collect();
    let mut tau = vec![0.0; n];

    c.bench_function("rnea_fixed_15dof", |b| {
        b.iter(|| {
            robot
                .rnea(
                    &mut ws,
                    black_box(&q),
                    black_box(&qd),
                    black_box(&qdd),
                    &mut tau,
                )
                .unwrap();
            black_box(&tau);
        })
    });
    let base = BaseState::from_arrays(
        [0.0, 0.0, 1.0],
        [0.1, 0.0, 0.0, 1.0],
        [0.1, 0.0, 0.0, 0.0, 0.2, 0.0],
        [0.0; 6],
    )
    .unwrap();
    c.bench_function("rnea_floating_15dof", |b| {
        b.iter(|| {
            let w = robot
                .rnea_floating(
                    &mut ws,
                    black_box(&base),
                    black_box(&q),
                    &qd,
                    &qdd,
                    &[],
                    &mut tau,
                )
                .unwrap();
            black_box((&tau, w));
        })
    });
    let mut m = DMatrix::zeros(n, n);
    c.bench_function("crba_15dof", |b| {
        b.iter(|| {
            robot.mass_matrix(&mut ws, black_box(&q), &mut m).unwrap();
            black_box(&m);
        })
    });
    let view = robot.single_joint_view("l_knee", &q).unwrap();
    let table = view.table(-1.9, 0.2, 2101).unwrap();
    let mut s = -1.0;
    c.bench_function("single_joint_gravity_closed_form", |b| {
        b.iter(|| {
            s = if s > 0.1 { -1.8 } else { s + 1e-4 };
            black_box(view.gravity_nm(black_box(s)))
        })
    });
    c.bench_function("single_joint_gravity_table", |b| {
        b.iter(|| {
            s = if s > 0.1 { -1.8 } else { s + 1e-4 };
            black_box(table.gravity_nm(black_box(s)))
        })
    });
    // The project's budget (≤ 5 s), measured directly: 10⁶ fixed-base RNEA evaluations in one batch.
    let t0 = std::time::Instant::now();
    for i in 0..1_000_000u32 {
        let mut qq = [0.0; 32];
        qq[..n].copy_from_slice(&q);
        qq[0] += f64::from(i & 7) * 1e-3;
        robot.rnea(&mut ws, &qq[..n], &qd, &qdd, &mut tau).unwrap();
        black_box(&tau);
    }
    println!(
        "10^6 rnea_fixed_15dof evaluations: {:.3} s (budget 5 s)",
        t0.elapsed().as_secs_f64()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
