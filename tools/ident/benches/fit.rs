//! Criterion bench: LM fit of CV and SCV on 10⁶ synthetic samples (the ≤ 1 s budget of `frictl fit`),
//! the label pipeline's zero-phase Butterworth + RTS smoother on 10⁶ samples, and the whole-body
//! label of a 15-joint 1 kHz log (every joint of the project's leg model moving and labelled in one
//! pass; 10 s of log per iteration: × 360 for an hour of log).

use criterion::{Criterion, criterion_group, criterion_main};
use frictionless::filter::Butterworth;
use frictionless::friction::{CvParams, ScvParams, StaticFriction, paper};
use frictionless_ident::fit::{FitOptions, fit};
use frictionless_ident::kalman::{KalmanConfig, smooth};

fn data<M: StaticFriction>(m: &M, n: usize) -> (Vec<f64>, Vec<f64>) {
    // Deterministic pseudo-random velocities and noise (LCG), no RNG crate needed in the bench.
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut u = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let v: Vec<f64> = (0..n).map(|_| (u() * 2.0 - 1.0) * 2.0).collect();
    let t = v
        .iter()
        .map(|&v| m.torque_nm(v) + (u() - 0.5) * 0.3)
        .collect();
    (v, t)
}

fn bench(c: &mut Criterion) {
    let n = 1_000_000;
    let mut g = c.benchmark_group("fit_1e6");
    g.sample_size(10);
    let (v, t) = data(&paper::CV_ANKLE_ROLL, n);
    g.bench_function("lm_cv", |b| {
        b.iter(|| fit::<CvParams>(&v, &t, &FitOptions::default()).unwrap())
    });
    let (v, t) = data(&paper::SCV_ANKLE_ROLL, n);
    g.bench_function("lm_scv", |b| {
        b.iter(|| fit::<ScvParams>(&v, &t, &FitOptions::default()).unwrap())
    });
    let bw = Butterworth::lowpass(5, 100.0, 1000.0).unwrap();
    g.bench_function("sosfiltfilt_5th", |b| b.iter(|| bw.filtfilt(&t).unwrap()));
    let s: Vec<f64> = (0..n).map(|k| (k as f64 * 1e-3).sin()).collect();
    g.bench_function("kalman_rts", |b| {
        b.iter(|| smooth(&KalmanConfig::knee(), 1e-3, &s).unwrap())
    });
    g.finish();
}

/// 10 s of a 15-joint 1 kHz log: every joint of `virtual_leg` moves (0.1–0.4 rad sines) and carries
/// a current; all 15 are labelled in one pass (one RNEA per sample).
fn whole_body(c: &mut Criterion) {
    use frictionless_dataset::LabelSource;
    use frictionless_ident::preprocess::{
        Dynamics, JointLabel, JointStates, PreprocessConfig, RunJoints, RunSignals, SignalsLabel,
        WholeBody, preprocess_joints,
    };
    let robot = frictionless_dynamics::virtual_leg().unwrap();
    let names: Vec<String> = robot.joint_names().map(str::to_string).collect();
    let n = 10_000;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
    let mut state = JointStates::with_names(names.clone(), &[], &[], n);
    let mut signals = Vec::new();
    for (j, q) in state.q.iter_mut().enumerate() {
        let (a, f) = (0.1 + 0.02 * j as f64, 0.3 + 0.05 * j as f64);
        *q = t
            .iter()
            .map(|t| a * (std::f64::consts::TAU * f * t).sin())
            .collect();
        signals.push(RunSignals {
            time_s: t.clone(),
            chunk: vec![0; n],
            s_rad: Some(q.clone()),
            current_a: Some(t.iter().map(|t| 0.3 * (5.0 * t).sin()).collect()),
            ..RunSignals::default()
        });
    }
    let joints: Vec<JointLabel> = names
        .iter()
        .map(|j| JointLabel {
            joint: j.clone(),
            label: SignalsLabel {
                source: LabelSource::Current,
                gear_ratio_signed: Some(100.0),
                kt_nm_per_a: Some(0.1),
            },
            cfg: PreprocessConfig::for_joint(j),
        })
        .collect();
    let body = WholeBody::new(robot, Default::default()).unwrap();
    let runs = [RunJoints {
        signals: signals.iter().collect(),
        state: Some(&state),
    }];
    let mut g = c.benchmark_group("whole_body_label_15_joints_1khz");
    g.sample_size(10);
    g.throughput(criterion::Throughput::Elements(n as u64));
    g.bench_function("10s_log_all_15_joints", |b| {
        b.iter(|| preprocess_joints(&runs, &joints, Dynamics::WholeBody(&body)).unwrap())
    });
    // The same log streamed: pushed in blocks of 1 000 rows, labelled in windows of 1 000 grid
    // samples plus the derived margins.
    g.bench_function("10s_log_all_15_joints_streamed", |b| {
        b.iter(|| {
            use frictionless_ident::stream::StreamLabeller;
            let mut sl = StreamLabeller::new(&joints, Dynamics::WholeBody(&body), 1000).unwrap();
            let mut rows = 0;
            for a in (0..n).step_by(1000) {
                let e = (a + 1000).min(n);
                let cut = |x: &Option<Vec<f64>>| x.as_ref().map(|x| x[a..e].to_vec());
                let sig: Vec<RunSignals> = signals
                    .iter()
                    .map(|s| RunSignals {
                        time_s: s.time_s[a..e].to_vec(),
                        chunk: s.chunk[a..e].to_vec(),
                        s_rad: cut(&s.s_rad),
                        current_a: cut(&s.current_a),
                        ..RunSignals::default()
                    })
                    .collect();
                let mut st = state.clone();
                st.q.iter_mut().for_each(|q| *q = q[a..e].to_vec());
                sl.push(&RunJoints {
                    signals: sig.iter().collect(),
                    state: Some(&st),
                })
                .unwrap();
                rows += sl.take_rows().iter().map(|d| d.len()).sum::<usize>();
            }
            sl.end_run().unwrap();
            let (rest, _) = sl.finish().unwrap();
            rows + rest.iter().map(|d| d.0.len()).sum::<usize>()
        })
    });
    g.finish();
}

criterion_group!(benches, bench, whole_body);
criterion_main!(benches);
