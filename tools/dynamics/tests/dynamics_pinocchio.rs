//! Cross-check of the Rust RNEA against Pinocchio on iCub 3 (`iCubGenova09`, icub-models 2.8.1) and the
//! real ergoCub URDF: fixed base over all joints, legs-only reduced models, floating base with sole
//! wrenches; and on every URDF of example-robot-data 6.0.0 Pinocchio loads (≈ 70 robots written by
//! others: arms, quadrupeds, humanoids, hands, mobile manipulators; fixed and floating base, continuous
//! and prismatic joints). References come from `tests/python/gen_pinocchio_refs.py` via
//! `tests/run.sh`; joints are compared **by name**, tolerance 1e-6 N·m.

use std::collections::HashMap;
use std::path::PathBuf;

use frictionless_dynamics::{BaseState, ExternalWrench, Force, Reduction, Robot, Workspace};
use nalgebra::Vector3;
use serde::Deserialize;

const TOL_NM: f64 = 1e-6;

#[derive(Deserialize)]
struct Base {
    pos: [f64; 3],
    quat: [f64; 4],
    vel: [f64; 6],
    acc: [f64; 6],
}

#[derive(Deserialize)]
struct Case {
    model: String,
    urdf: String,
    kind: String,
    keep: Option<Vec<String>>,
    locked_q: HashMap<String, f64>,
    q: HashMap<String, f64>,
    qd: HashMap<String, f64>,
    qdd: HashMap<String, f64>,
    base: Option<Base>,
    wrenches: HashMap<String, [f64; 6]>,
    tau: HashMap<String, f64>,
    base_wrench: Option<[f64; 6]>,
}

/// The Pinocchio reference file; the tests that read it are `#[ignore]`d unless run by
/// `tests/run.sh` (`--include-ignored`), which sets `FRICTIONLESS_REFS`.
fn refs_file() -> PathBuf {
    let dir = std::env::var_os("FRICTIONLESS_REFS").expect(
        "FRICTIONLESS_REFS is unset: run bash tests/run.sh (it writes the Pinocchio references)",
    );
    PathBuf::from(dir).join("pinocchio_rnea.jsonl")
}

#[test]
#[ignore = "needs FRICTIONLESS_REFS: bash tests/run.sh"]
fn rnea_matches_pinocchio_by_joint_name() {
    let path = refs_file();
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "FRICTIONLESS_REFS is set but {} is missing: {e}",
            path.display()
        )
    });
    let mut models: HashMap<String, Robot> = HashMap::new();
    let mut counts: HashMap<(String, String), usize> = HashMap::new();
    let mut worst = 0.0f64;
    for (line_no, line) in text.lines().enumerate() {
        let c: Case =
            serde_json::from_str(line).unwrap_or_else(|e| panic!("line {}: {e}", line_no + 1));
        let key = format!("{}|{:?}|{:?}", c.urdf, c.keep, {
            let mut l: Vec<_> = c.locked_q.iter().map(|(k, v)| format!("{k}={v}")).collect();
            l.sort();
            l
        });
        let robot = models.entry(key).or_insert_with(|| {
            let red = c.keep.as_ref().map(|keep| Reduction {
                keep: keep.clone(),
                locked_q: c.locked_q.clone(),
            });
            Robot::from_urdf_file_reduced(&c.urdf, red.as_ref())
                .unwrap_or_else(|e| panic!("line {}: {e}", line_no + 1))
        });
        let n = robot.dof();
        // Every movable joint of ours is in Pinocchio's output and vice versa.
        assert_eq!(n, c.tau.len(), "line {}: joint count", line_no + 1);
        let vec_of = |m: &HashMap<String, f64>| {
            robot
                .vector_from_names(m.iter().map(|(k, v)| (k.as_str(), *v)))
                .unwrap_or_else(|e| panic!("line {}: {e}", line_no + 1))
        };
        let (q, qd, qdd) = (vec_of(&c.q), vec_of(&c.qd), vec_of(&c.qdd));
        let ext: Vec<ExternalWrench> = c
            .wrenches
            .iter()
            .map(|(f, w)| ExternalWrench {
                frame: robot.frame_id(f).unwrap(),
                wrench: Force::new(
                    Vector3::new(w[3], w[4], w[5]),
                    Vector3::new(w[0], w[1], w[2]),
                ),
            })
            .collect();
        let mut ws = Workspace::new(robot);
        let mut tau = vec![0.0; n];
        match (&c.base, c.kind.as_str()) {
            (Some(b), "floating") => {
                let base = BaseState::from_arrays(b.pos, b.quat, b.vel, b.acc).unwrap();
                let bw = robot
                    .rnea_floating(&mut ws, &base, &q, &qd, &qdd, &ext, &mut tau)
                    .unwrap();
                let expect = c.base_wrench.expect("floating case has base_wrench");
                let got = [bw.lin.x, bw.lin.y, bw.lin.z, bw.ang.x, bw.ang.y, bw.ang.z];
                for k in 0..6 {
                    let err = (got[k] - expect[k]).abs();
                    worst = worst.max(err);
                    assert!(
                        err <= TOL_NM,
                        "line {} ({}): base wrench[{k}] {} vs pinocchio {}",
                        line_no + 1,
                        c.model,
                        got[k],
                        expect[k]
                    );
                }
            }
            (None, "fixed" | "legs") => {
                assert!(ext.is_empty());
                robot.rnea(&mut ws, &q, &qd, &qdd, &mut tau).unwrap();
            }
            (_, k) => panic!("line {}: unexpected case kind {k}", line_no + 1),
        }
        for (name, &expect) in &c.tau {
            let got = tau[robot.joint_index(name).unwrap()];
            let err = (got - expect).abs();
            worst = worst.max(err);
            assert!(
                err <= TOL_NM,
                "line {} ({} {}): joint {name}: {got} Nm vs pinocchio {expect} Nm",
                line_no + 1,
                c.model,
                c.kind
            );
        }
        *counts.entry((c.model.clone(), c.kind.clone())).or_default() += 1;
    }
    // Every model × kind combination must be present (a silently empty file would prove nothing).
    for model in ["iCubGenova09", "ergoCubSN001"] {
        for kind in ["fixed", "legs", "floating"] {
            assert!(
                counts
                    .get(&(model.to_string(), kind.to_string()))
                    .copied()
                    .unwrap_or(0)
                    > 0,
                "no {model} {kind} cases in {}",
                path.display()
            );
        }
    }
    // The robots of example-robot-data: each with fixed- and floating-base cases, and (nearly) all
    // of the package's URDFs present (a generator that silently skipped most would prove little).
    let erd: std::collections::BTreeSet<&str> = counts
        .keys()
        .filter_map(|(m, _)| m.strip_prefix("erd:"))
        .collect();
    for m in &erd {
        for kind in ["fixed", "floating"] {
            assert!(
                counts.contains_key(&(format!("erd:{m}"), kind.to_string())),
                "no erd:{m} {kind} cases in {}",
                path.display()
            );
        }
    }
    assert!(
        erd.len() >= 60,
        "only {} example-robot-data models in {}",
        erd.len(),
        path.display()
    );
    println!(
        "pinocchio cross-check: {} cases, {} example-robot-data models, worst abs error {worst:.3e}",
        counts.values().sum::<usize>(),
        erd.len()
    );
}

#[derive(Deserialize)]
struct AbaCase {
    model: String,
    urdf: String,
    kind: String,
    keep: Option<Vec<String>>,
    locked_q: HashMap<String, f64>,
    q: HashMap<String, f64>,
    qd: HashMap<String, f64>,
    tau: HashMap<String, f64>,
    qdd: HashMap<String, f64>,
}

/// Forward dynamics: the Rust ABA against Pinocchio's `aba` on random states (q, q̇, τ) of the ergoCub and
/// iCub 3 left legs (every other joint locked at a random position) and of the whole models; joints by
/// name, ≤ 1e-9 relative to the largest acceleration of the case (at least 1 rad/s²).
#[test]
#[ignore = "needs FRICTIONLESS_REFS (tests/run.sh)"]
fn aba_matches_pinocchio_by_joint_name() {
    let dir = std::env::var_os("FRICTIONLESS_REFS")
        .expect("FRICTIONLESS_REFS must name the directory of tests/python/gen_*.py's output");
    let path = PathBuf::from(dir).join("pinocchio_aba.jsonl");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (run tests/run.sh)", path.display()));
    let mut counts: HashMap<(String, String), usize> = HashMap::new();
    let mut worst = 0.0f64;
    for (line_no, line) in text.lines().enumerate() {
        let at = || format!("{} line {}", path.display(), line_no + 1);
        let c: AbaCase = serde_json::from_str(line).unwrap_or_else(|e| panic!("{}: {e}", at()));
        let red = c.keep.as_ref().map(|keep| Reduction {
            keep: keep.clone(),
            locked_q: c.locked_q.clone(),
        });
        let robot = Robot::from_urdf_file_reduced(&c.urdf, red.as_ref())
            .unwrap_or_else(|e| panic!("{}: {e}", at()));
        let n = robot.dof();
        assert_eq!(n, c.qdd.len(), "{}: joint count", at());
        let vec_of = |m: &HashMap<String, f64>| {
            robot
                .vector_from_names(m.iter().map(|(k, v)| (k.as_str(), *v)))
                .unwrap_or_else(|e| panic!("{}: {e}", at()))
        };
        let (q, qd, tau) = (vec_of(&c.q), vec_of(&c.qd), vec_of(&c.tau));
        let mut ws = Workspace::new(&robot);
        let mut qdd = vec![0.0; n];
        robot.aba(&mut ws, &q, &qd, &tau, &mut qdd).unwrap();
        let scale = c.qdd.values().fold(1.0f64, |m, x| m.max(x.abs()));
        for (name, &expect) in &c.qdd {
            let got = qdd[robot.joint_index(name).unwrap()];
            let rel = (got - expect).abs() / scale;
            worst = worst.max(rel);
            assert!(
                rel <= 1e-9,
                "{} ({} {}): joint {name}: {got} rad/s² vs pinocchio {expect} rad/s² (relative {rel:e})",
                at(),
                c.model,
                c.kind
            );
        }
        *counts.entry((c.model.clone(), c.kind.clone())).or_default() += 1;
    }
    for model in ["ergoCubSN001", "iCubGenova09"] {
        for kind in ["fixed", "left_leg"] {
            assert!(
                counts.contains_key(&(model.to_string(), kind.to_string())),
                "no {model} {kind} cases in {}",
                path.display()
            );
        }
    }
    println!(
        "pinocchio aba cross-check: {} cases, worst relative error {worst:.3e}",
        counts.values().sum::<usize>()
    );
}
