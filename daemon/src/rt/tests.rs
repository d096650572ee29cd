//! Unit tests of the RT tick, the crew and the RT set-up.

use super::rt_setup::{apply_rt_settings, hold_cpu_dma_latency};
use super::*;
use frictionless_shm_types::{FLAG_NON_FINITE, FLAG_STALE, STATUS_CPU_PINNED};

/// A CPU index beyond CPU_SETSIZE (the config refuses it; a `Config` built in code
/// may not) is an affinity refusal, not a panic in `CPU_SET`.
#[test]
fn out_of_range_cpu_is_refused_without_panicking() {
    let text = "[backend]\nkind = \"shm\"\n[[joint]]\nname = \"a\"\nindex = 0\ngear_ratio = 1.0\nkt = 0.1\nmax_curr = 1.0\nfriction_model = \"none\"\n";
    let mut cfg = crate::config::parse(std::path::Path::new("t.toml"), text).unwrap();
    for cpu in [libc::CPU_SETSIZE as usize, usize::MAX] {
        cfg.raw.loop_.cpu = Some(cpu);
        let c = cfg.clone();
        let grant = std::thread::spawn(move || apply_rt_settings(&c).map(|g| g.flags))
            .join()
            .expect("no panic")
            .expect("refusals are not fatal without require_rt");
        assert_eq!(grant & STATUS_CPU_PINNED, 0, "cpu {cpu}");
    }
}

fn params(on_stale: &str) -> Box<Params> {
    let text = format!(
        r#"
[backend]
kind = "shm"
[safety]
on_stale = "{on_stale}"
[[joint]]
name = "a"
index = 2
gear_ratio = -100.0
kt = 0.1
max_curr = 5.0
kfc = 1.0
lpf = {{ order = 1, cutoff_hz = 50.0 }}
friction_model = "cv"
kc = 1.0
ka = 1000.0
kv = 0.0
"#
    );
    let cfg = crate::config::parse(std::path::Path::new("t.toml"), &text).unwrap();
    crate::params::build(&cfg, 0).unwrap()
}

fn inputs(tau: f64, v: f64) -> Inputs {
    let mut st = JointStates::zeroed();
    st.n_joints = 3;
    st.sdot_rad_s[2] = v;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 3;
    rq.enable_mask = 1 << 2;
    rq.tau_des_nm[2] = tau;
    Inputs {
        states: Latest {
            value: st,
            have: true,
            new_at_tick: 0,
        },
        request: Latest {
            value: rq,
            have: true,
            new_at_tick: 0,
        },
    }
}

const FRESH: Freshness = Freshness {
    state_stale: false,
    request_stale: false,
};

fn run(p: &mut Params, inp: &Inputs, f: Freshness, prev: &mut u64) -> MotorCurrentCommand {
    let mut cmd = MotorCurrentCommand::zeroed();
    let mut tau_f = [0.0; MAX_JOINTS];
    compute(p, inp, f, prev, &mut cmd, &mut tau_f);
    cmd
}

#[test]
fn enable_edge_resets_the_filter_and_masks_follow_the_request() {
    let mut p = params("zero");
    let mut prev = 0;
    let inp = inputs(0.0, 1.0);
    let first = run(&mut p, &inp, FRESH, &mut prev).i_ref_a[2];
    assert_eq!(prev, 1 << 2);
    let second = run(&mut p, &inp, FRESH, &mut prev).i_ref_a[2];
    assert!(second.abs() > first.abs(), "LPF rising: {first} → {second}");
    // Disable: 0 A, not valid, flagged.
    let mut off = inputs(0.0, 1.0);
    off.request.value.enable_mask = 0;
    let c = run(&mut p, &off, FRESH, &mut prev);
    assert_eq!(
        (c.valid_mask, c.i_ref_a[2], c.flags[2]),
        (0, 0.0, FLAG_DISABLED)
    );
    // Re-enable: the filter starts again from 0 (same first value as at the start).
    let again = run(&mut p, &inp, FRESH, &mut prev).i_ref_a[2];
    assert_eq!(again, first);
}

/// The command carries the estimate the law was given: the CV model's value, before kfc and
/// the LPF (which the current and the status's τ̂_F went through); 0 off the model path.
#[test]
fn the_command_carries_the_model_estimate_before_kfc_and_filter() {
    let mut p = params("zero");
    p.joints[0].law.gains.kfc = 0.5;
    let mut prev = 0;
    let inp = inputs(0.0, 1.0);
    let mut cmd = MotorCurrentCommand::zeroed();
    let mut tau_f = [0.0; MAX_JOINTS];
    compute(&mut p, &inp, FRESH, &mut prev, &mut cmd, &mut tau_f);
    // CV at ṡ = 1 rad/s: kc·tanh(ka·ṡ) + kv·ṡ = tanh(1000) ≈ 1 Nm.
    let model = 1000.0f64.tanh();
    assert!(
        (cmd.tau_f_model_nm[2] - model).abs() < 1e-12,
        "{}",
        cmd.tau_f_model_nm[2]
    );
    // The law's τ̂_F went through kfc and the first LPF step: well below the model's.
    assert!(tau_f[2].abs() < 0.5 * model, "law τ̂_F {}", tau_f[2]);
    let mut off = inputs(0.0, 1.0);
    off.request.value.enable_mask = 0;
    compute(&mut p, &off, FRESH, &mut prev, &mut cmd, &mut tau_f);
    assert_eq!(cmd.tau_f_model_nm[2], 0.0, "a disabled joint ran no model");
}

#[test]
fn stale_fault_and_nan_paths() {
    let mut p = params("static_model");
    let mut prev = 0;
    let inp = inputs(2.0, 1.0);
    let stale = Freshness {
        state_stale: true,
        request_stale: false,
    };
    let c = run(&mut p, &inp, stale, &mut prev);
    assert_eq!(c.flags[2], FLAG_STALE);
    assert!((c.i_ref_a[2] - 2.0 / (0.1 * -100.0)).abs() < 1e-12);
    let both = Freshness {
        state_stale: true,
        request_stale: true,
    };
    assert_eq!(run(&mut p, &inp, both, &mut prev).i_ref_a[2], 0.0);
    let mut fault = inputs(2.0, 1.0);
    fault.states.value.fault_flags[2] = 1;
    let c = run(&mut p, &fault, FRESH, &mut prev);
    assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_FAULT));
    let mut nan = inputs(2.0, 1.0);
    nan.states.value.sdot_rad_s[2] = f64::NAN;
    let c = run(&mut p, &nan, FRESH, &mut prev);
    assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_NON_FINITE));
    // No request ever received: nothing valid.
    let mut none = inputs(2.0, 1.0);
    none.request.have = false;
    assert_eq!(run(&mut p, &none, FRESH, &mut prev).valid_mask, 0);
}

/// `n` joints at indices 0, 3, 6, …: PINNs of different sizes and dtypes (seeded random
/// weights), CV and SCV models; the law with a filter and clamps.
fn mixed_params(n: usize, rt_threads: u8) -> Box<Params> {
    use crate::params::{JointRt, ModelSlots, OodRt};
    use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
    use frictionless::filter::CausalButterworth;
    use frictionless::friction::{CvParams, ScvParams};
    use frictionless::law::{Gains, JointLaw};
    use frictionless::mlp::StorageDtype;
    use frictionless::model::PinnEstimator;
    use frictionless::random::{RandomMlpSpec, seeded_mlp};
    use frictionless::units::GearRatio;
    use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
    let r = -100.0;
    let joints = (0..n)
        .map(|k| {
            let model = match k % 4 {
                0 | 1 => {
                    let features = FeatureSpec {
                        set: FeatureSet::DeltaThetaJointVel,
                        history: 4 + k % 3,
                        temperature: false,
                    };
                    let width = 16 + 8 * (k % 5);
                    let file = ModelFile {
                        meta: ModelMeta {
                            joint_name: format!("j{k}"),
                            gear_ratio: GearRatio::new(r).unwrap(),
                            kt_nm_per_a: 0.1,
                            features,
                            scv: None,
                            training: TrainingMeta::unknown("rt test", 0),
                        },
                        dtype: [StorageDtype::F32, StorageDtype::F16, StorageDtype::Bf16][k % 3],
                        mlp: seeded_mlp(
                            &RandomMlpSpec::new(&[features.n_inputs(), width, width, 1]),
                            k as u64,
                        )
                        .unwrap(),
                    };
                    let policy = if k % 2 == 0 {
                        WarmupPolicy::HoldZero
                    } else {
                        WarmupPolicy::ZeroPad
                    };
                    JointModel::Pinn(Box::new(
                        PinnEstimator::from_model_file(&file, policy).unwrap(),
                    ))
                }
                2 => JointModel::Cv(CvParams {
                    kc: 1.0,
                    ka: 50.0,
                    kv: 0.3,
                }),
                _ => JointModel::Scv(ScvParams {
                    kc: 1.0,
                    ka: 2.78,
                    kv: 0.29,
                    ks: 6.0,
                    vs: 0.13,
                    alpha: 0.6,
                }),
            };
            let gains = Gains {
                kt_nm_per_a: 0.1,
                gear_ratio: r,
                kfc: 0.8,
                kp: 0.1,
                ki: 0.5,
                max_curr_a: 4.0,
                max_output_friction_nm: 3.0,
                joint_velocity_threshold_rad_s: 0.05,
                dt_s: 1e-3,
                speed_limit: None,
            };
            JointRt {
                index: 3 * k,
                model,
                law: JointLaw::new(
                    gains,
                    Some(CausalButterworth::design(2, 30.0, 1000.0).unwrap()),
                ),
                ood: OodRt::off(),
                compensation: true,
                slots: ModelSlots::new(Vec::new()),
                model_switched: false,
            }
        })
        .collect();
    let configured_mask = (0..n).fold(0u64, |m, k| m | 1 << (3 * k));
    let mut p = Box::new(Params {
        generation: 0,
        joints,
        stale_after_ticks: 5,
        on_stale: OnStale::StaticModel,
        configured_mask,
        split: 0,
        helper_mask: 0,
    });
    p.split_threads(rt_threads);
    p
}

/// Tick `t`'s inputs for joints at 0, 3, 6, …: moving states, NaN samples, faults, enable
/// toggles and stale stretches.
fn changing_inputs(n: usize, t: u64) -> (Inputs, Freshness) {
    let mut st = JointStates::zeroed();
    let mut rq = TorqueRequest::zeroed();
    st.n_joints = (3 * n) as u32;
    rq.n_joints = (3 * n) as u32;
    st.seq = t;
    rq.enable_mask = u64::MAX;
    for k in 0..n {
        let i = 3 * k;
        let x = (t as f64 * 0.013 + k as f64).sin();
        st.s_rad[i] = 0.3 * x;
        st.sdot_rad_s[i] = 0.8 * (t as f64 * 0.007 + k as f64 * 0.5).cos();
        st.theta_motor_rad[i] = -100.0 * st.s_rad[i] + 0.02 * x;
        st.omega_motor_rad_s[i] = -100.0 * st.sdot_rad_s[i];
        st.tau_meas_nm[i] = 2.0 * x;
        rq.tau_des_nm[i] = 3.0 * x;
        if (t + k as u64).is_multiple_of(97) {
            st.sdot_rad_s[i] = f64::NAN;
        }
        if (t / 50 + k as u64).is_multiple_of(7) {
            rq.enable_mask &= !(1 << i);
        }
        if (t + 3 * k as u64) % 211 == 5 {
            st.fault_flags[i] = 1;
        }
    }
    let fresh = Freshness {
        state_stale: t % 400 >= 390,
        request_stale: t % 900 >= 895,
    };
    let inp = Inputs {
        states: Latest {
            value: st,
            have: true,
            new_at_tick: t,
        },
        request: Latest {
            value: rq,
            have: t > 3,
            new_at_tick: t,
        },
    };
    (inp, fresh)
}

fn test_crew(budget_ns: u64) -> Crew {
    let plan = CrewPlan {
        period_ns: 1_000_000,
        budget_ns,
        release_ns: budget_ns,
        prefetch: Prefetch::After,
        lead_ns: 0,
        lockstep: true,
    };
    Crew::spawn(plan, ThreadRt::default()).unwrap().0
}

#[test]
fn two_threads_give_the_one_thread_output_bit_for_bit() {
    let n = 11;
    let mut one = mixed_params(n, 1);
    let mut two = mixed_params(n, 2);
    assert_eq!(one.split, n);
    assert!(two.split > 0 && two.split < n, "split {}", two.split);
    assert_ne!(two.helper_mask, 0);
    assert_eq!(two.helper_mask & !two.configured_mask, 0);
    // A budget no scheduler delay reaches: the helper is never late here.
    let mut crew = test_crew(60_000_000_000);
    let (mut prev1, mut prev2) = (0u64, 0u64);
    let (mut c1, mut c2) = (MotorCurrentCommand::zeroed(), MotorCurrentCommand::zeroed());
    let (mut f1, mut f2) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
    let mut nonzero = 0;
    for t in 0..3000 {
        let (inp, fresh) = changing_inputs(n, t);
        compute(&mut one, &inp, fresh, &mut prev1, &mut c1, &mut f1);
        let wake = monotonic_ns();
        assert!(crew.compute(&mut two, &inp, fresh, &mut prev2, &mut c2, &mut f2, wake, 0));
        assert_eq!(prev1, prev2, "tick {t}");
        assert_eq!(
            (c1.valid_mask, c1.n_joints, c1.state_seq),
            (c2.valid_mask, c2.n_joints, c2.state_seq)
        );
        for k in 0..MAX_JOINTS {
            assert_eq!(
                c1.i_ref_a[k].to_bits(),
                c2.i_ref_a[k].to_bits(),
                "tick {t} joint {k}"
            );
            assert_eq!(c1.flags[k], c2.flags[k], "tick {t} joint {k}");
            assert_eq!(f1[k].to_bits(), f2[k].to_bits(), "tick {t} joint {k}");
            nonzero += usize::from(c1.i_ref_a[k] != 0.0);
        }
    }
    assert_eq!(crew.late_ticks(), 0);
    assert!(nonzero > 10_000, "the joints were driven: {nonzero}");
    let stolen = crew.stolen_ticks();
    let h = crew.stop();
    assert_eq!(
        h.jobs + stolen,
        3000,
        "every job ran once, on one thread or the other"
    );
}

#[test]
fn a_helper_that_has_not_started_loses_its_half_to_the_main_thread_same_outputs() {
    let n = 9;
    let mut one = mixed_params(n, 1);
    let mut two = mixed_params(n, 2);
    // No budget to wait for the helper at all: only the claim keeps its joints from going stale.
    let mut crew = test_crew(0);
    let (mut prev1, mut prev2) = (0u64, 0u64);
    let (mut c1, mut c2) = (MotorCurrentCommand::zeroed(), MotorCurrentCommand::zeroed());
    let (mut f1, mut f2) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
    crew.ren.hold.store(true, Ordering::Release);
    for t in 0..600 {
        if t == 300 {
            // The helper wakes up: from here on it may claim jobs again (or lose them).
            crew.ren.hold.store(false, Ordering::Release);
        }
        let (inp, fresh) = changing_inputs(n, t);
        compute(&mut one, &inp, fresh, &mut prev1, &mut c1, &mut f1);
        let on_time = crew.compute(
            &mut two,
            &inp,
            fresh,
            &mut prev2,
            &mut c2,
            &mut f2,
            monotonic_ns(),
            0,
        );
        if t < 300 {
            assert!(
                on_time,
                "tick {t}: a held helper's half is run here, never late"
            );
            assert_eq!(crew.stolen_ticks(), t + 1);
        }
        if !on_time {
            // Claimed by the helper and not done within a zero budget: the stale path (tested
            // below); its joints restart bumplessly afterwards and are no longer comparable.
            break;
        }
        assert_eq!(prev1, prev2, "tick {t}");
        for k in 0..MAX_JOINTS {
            assert_eq!(
                c1.i_ref_a[k].to_bits(),
                c2.i_ref_a[k].to_bits(),
                "tick {t} joint {k}"
            );
            assert_eq!(c1.flags[k], c2.flags[k], "tick {t} joint {k}");
            assert_eq!(f1[k].to_bits(), f2[k].to_bits(), "tick {t} joint {k}");
        }
    }
    assert!(crew.stolen_ticks() >= 300);
    drop(crew);
}

#[test]
fn a_late_helper_marks_its_joints_stale_and_never_hangs() {
    let n = 8;
    let mut one = mixed_params(n, 1);
    let mut two = mixed_params(n, 2);
    let helper_mask = two.helper_mask;
    // No budget at all: the join gives up as soon as this thread's half is done.
    let mut crew = test_crew(0);
    let (mut prev1, mut prev2) = (0u64, 0u64);
    let (mut c1, mut c2) = (MotorCurrentCommand::zeroed(), MotorCurrentCommand::zeroed());
    let (mut f1, mut f2) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
    let mut late = 0;
    for t in 0..500 {
        let (inp, fresh) = changing_inputs(n, t);
        compute(&mut one, &inp, fresh, &mut prev1, &mut c1, &mut f1);
        let on_time = crew.compute(
            &mut two,
            &inp,
            fresh,
            &mut prev2,
            &mut c2,
            &mut f2,
            monotonic_ns(),
            0,
        );
        for k in 0..MAX_JOINTS {
            if helper_mask & (1 << k) != 0 && !on_time {
                assert_eq!(c2.i_ref_a[k], 0.0, "tick {t} joint {k}");
                let want = if c2.valid_mask & (1 << k) != 0 {
                    FLAG_STALE
                } else {
                    FLAG_DISABLED
                };
                assert_eq!(c2.flags[k], want, "tick {t} joint {k}");
            } else if helper_mask & (1 << k) == 0 {
                // This thread's joints are never affected by the helper.
                assert_eq!(
                    c1.i_ref_a[k].to_bits(),
                    c2.i_ref_a[k].to_bits(),
                    "tick {t} joint {k}"
                );
            }
        }
        late += usize::from(!on_time);
    }
    assert_eq!(crew.late_ticks(), late as u64);
    drop(crew); // joins the helper before the parameters go
}

#[test]
fn the_split_balances_weight_bytes_and_keeps_index_order() {
    let p = mixed_params(12, 2);
    let bytes = |js: &[JointRt]| js.iter().map(|j| j.model.weight_bytes()).sum::<usize>();
    let (a, b) = (bytes(&p.joints[..p.split]), bytes(&p.joints[p.split..]));
    let heaviest = p
        .joints
        .iter()
        .map(|j| j.model.weight_bytes())
        .max()
        .unwrap();
    assert!(a.abs_diff(b) <= heaviest, "{a} vs {b}");
    for half in [&p.joints[..p.split], &p.joints[p.split..]] {
        assert!(half.windows(2).all(|w| w[0].index < w[1].index));
    }
    let mut all: Vec<usize> = p.joints.iter().map(|j| j.index).collect();
    all.sort_unstable();
    assert_eq!(all, (0..12).map(|k| 3 * k).collect::<Vec<_>>());
    let q = mixed_params(12, 1);
    assert_eq!((q.split, q.helper_mask), (12, 0));
}

#[test]
fn fine_histogram_quantiles_have_1us_resolution() {
    let mut h = FineHistogram::new();
    assert_eq!(h.quantile_upper_ns(0.5), 0, "empty");
    // 1.5 µs, 2.5 µs, …, 100.5 µs: value i lands in bucket [i, i+1) µs.
    for us in 1..=100u64 {
        h.record(us * 1000 + 500);
    }
    assert_eq!(h.quantile_upper_ns(0.5), 51_000);
    assert_eq!(h.quantile_upper_ns(0.99), 100_000);
    assert_eq!(h.quantile_upper_ns(1.0), 100_500, "capped by the max");
    h.record(1_000_000_000);
    assert_eq!((h.overflow, h.total, h.max_ns), (1, 101, 1_000_000_000));
    assert_eq!(h.quantile_upper_ns(1.0), 1_000_000_000);
    let s = RtSummary {
        ticks: 101,
        missed: 0,
        lockstep: false,
        lateness: h,
        status: Box::new(DaemonStatus::zeroed()),
        thread: RtThreadReport {
            policy: libc::SCHED_FIFO,
            priority: 80,
            usage: ThreadUsage {
                minflt: 3,
                ..ThreadUsage::default()
            },
            ..RtThreadReport::default()
        },
        helper: None,
        helper_late: 0,
        helper_stolen: 0,
    }
    .report();
    assert!(s.contains("trigger=clock\n"), "{s}");
    assert!(s.contains("lateness_p50_ns=52000\n"), "{s}");
    assert!(s.contains("lateness_max_ns=1000000000\n"), "{s}");
    assert!(s.contains("rt_policy=SCHED_FIFO\nrt_priority=80\n"), "{s}");
    assert!(s.contains("rt_minflt=3\nrt_majflt=0\n"), "{s}");
    assert!(s.contains("rt_pm_qos_us=none\n"), "{s}");
    // 1.5 … 100.5 µs once each, then 1 s in the overflow.
    let hist: String = (1..=100).map(|us| format!("{us}:1,")).collect();
    assert!(
        s.contains(&format!(
            "lateness_overflow=1\nlateness_hist_us={}\n",
            hist.trim_end_matches(',')
        )),
        "{s}"
    );
}

#[test]
fn cpu_dma_latency_is_held_and_read_back_or_the_refusal_is_an_error() {
    match hold_cpu_dma_latency(0) {
        // While our request is open the effective bound is the minimum of all: 0.
        Ok((_file, got_us)) => assert_eq!(got_us, 0),
        Err(e) => assert!(
            matches!(
                e.kind(),
                std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::NotFound
            ),
            "{e}"
        ),
    }
}

#[test]
fn thread_usage_sees_this_threads_page_faults_and_sleeps() {
    let before = ThreadUsage::now();
    // A fresh mapping (mmap at this size): every first touch of a page faults.
    let mut v = vec![0u8; (1 << 20) + 64 * 4096];
    for k in (0..v.len()).step_by(4096) {
        v[k] = 1;
    }
    std::hint::black_box(&mut v);
    std::thread::sleep(std::time::Duration::from_millis(1));
    let d = ThreadUsage::now().since(before);
    assert!(d.minflt >= 64, "{d:?}");
    assert!(d.nvcsw >= 1, "a sleep is a voluntary switch: {d:?}");
}

#[test]
fn a_silent_field_bus_drive_gets_the_on_stale_output_not_a_fault() {
    let mut prev = 0;
    let mut inp = inputs(2.0, 1.0);
    inp.states.value.fault_flags[2] = FAULT_FEEDBACK_STALE;
    let mut p = params("static_model");
    let c = run(&mut p, &inp, FRESH, &mut prev);
    assert_eq!(c.flags[2], FLAG_STALE);
    assert!((c.i_ref_a[2] - 2.0 / (0.1 * -100.0)).abs() < 1e-12);
    let mut p = params("zero");
    let c = run(&mut p, &inp, FRESH, &mut prev);
    assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_STALE));
    // Any other fault bit still wins over staleness.
    inp.states.value.fault_flags[2] |= frictionless_shm_types::FAULT_DRIVE;
    let c = run(&mut p, &inp, FRESH, &mut prev);
    assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_FAULT));
}

#[test]
fn law_flags_map_to_the_abi_bits() {
    assert_eq!(abi_flags(LawFlags::NONE), 0);
    let all = LawFlags {
        friction_clipped: true,
        current_saturated: true,
        non_finite: true,
    };
    assert_eq!(
        abi_flags(all),
        FLAG_FRICTION_CLIPPED | FLAG_CURRENT_SATURATED | FLAG_NON_FINITE
    );
    let clipped = LawFlags {
        friction_clipped: true,
        ..LawFlags::NONE
    };
    assert_eq!(abi_flags(clipped), FLAG_FRICTION_CLIPPED);
}

#[test]
fn freshness_by_seq_age_and_stamp_age() {
    let mut l = Latest::new(0u8);
    assert!(l.stale(0, 0, 0, 5, 1000), "nothing received yet");
    l.update(Some(1), 10);
    assert!(!l.stale(15, 10_000, 9_000, 5, 1000));
    assert!(
        l.stale(16, 10_000, 9_000, 5, 1000),
        "no new sample for 6 ticks"
    );
    assert!(l.stale(11, 20_000, 9_000, 5, 1000), "stamp 11 periods old");
}

/// Step 2b: a runtime change is applied at the tick boundary and the tick computes exactly the
/// law with the new value; a change checked against another generation is dropped.
#[test]
fn runtime_sets_apply_at_the_tick_boundary_and_stale_generations_drop() {
    use crate::runtime::{Change, RuntimeSet};
    use frictionless::law::{JointLaw, LawInput};
    let mut p = params("zero");
    let mut twin = p.joints[0].law; // the law with the file's values, stepped alongside
    let (tx, rx) = std::sync::mpsc::sync_channel(4);
    let mut prev = 0;
    let inp = inputs(2.0, 1.0);
    let law_out = |law: &mut JointLaw, f: f64| {
        law.step(&LawInput {
            tau_des_nm: 2.0,
            friction_nm: f,
            sdot_rad_s: 1.0,
            tau_meas_nm: 0.0,
        })
        .i_a
    };
    // The joint's CV model at ṡ = 1 (stateless: the same value every tick).
    let f = match &p.joints[0].model {
        JointModel::Cv(cv) => frictionless::friction::StaticFriction::torque_nm(cv, 1.0),
        other => panic!("the test joint is CV, not {other:?}"),
    };
    let c = run(&mut p, &inp, FRESH, &mut prev);
    twin.reset();
    assert_eq!(c.i_ref_a[2], law_out(&mut twin, f));
    for (change, on) in [
        (Change::Kfc(0.4), true),
        (Change::MaxCurr(0.15), true),
        (Change::Compensation(false), false),
        (Change::Compensation(true), true),
    ] {
        tx.send(RuntimeSet {
            generation: 0,
            joint_index: 2,
            change,
        })
        .unwrap();
        assert_eq!(apply_runtime_sets(&mut p, &rx), (1, 0));
        match change {
            Change::Kfc(v) => twin.gains.kfc = v,
            Change::MaxCurr(v) => twin.gains.max_curr_a = v,
            _ => {}
        }
        let c = run(&mut p, &inp, FRESH, &mut prev);
        let want = law_out(&mut twin, if on { f } else { 0.0 });
        assert_eq!(c.i_ref_a[2], want, "{change:?}");
    }
    assert_eq!(p.joints[0].law.gains.kfc, 0.4);
    // Checked against generation 1 (a reload the RT thread has not taken) or an unknown joint.
    for (generation, joint_index) in [(1, 2), (0, 5)] {
        tx.send(RuntimeSet {
            generation,
            joint_index,
            change: Change::Kfc(2.0),
        })
        .unwrap();
    }
    assert_eq!(apply_runtime_sets(&mut p, &rx), (0, 2));
    assert_eq!(p.joints[0].law.gains.kfc, 0.4);
    // Empty queue: nothing to do.
    assert_eq!(apply_runtime_sets(&mut p, &rx), (0, 0));
}
