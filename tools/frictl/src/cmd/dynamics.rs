//! `frictl dynamics` — inverse dynamics and model info on a URDF, from the command line.
//!
//! It is a thin JSON-lines front end over `frictionless_dynamics`; it does no dynamics itself.

use std::collections::{BTreeMap, HashMap};
use std::io::{BufRead, BufWriter, Write};

use anyhow::{Context, bail};
use frictionless_dynamics::{
    BaseState, DEFAULT_URDF, DEFAULT_URDF_PATH, ExternalWrench, Force, JointKind, Reduction, Robot,
    Workspace,
};
use nalgebra::Vector3;
use serde::Deserialize;

pub use frictl_cli::dynamics::*;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CaseJson {
    #[serde(default)]
    q: HashMap<String, f64>,
    #[serde(default)]
    qd: HashMap<String, f64>,
    #[serde(default)]
    qdd: HashMap<String, f64>,
    #[serde(default)]
    base: Option<BaseJson>,
    #[serde(default)]
    wrenches: HashMap<String, [f64; 6]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BaseJson {
    #[serde(default)]
    pos: [f64; 3],
    #[serde(default = "identity_quat")]
    quat: [f64; 4],
    #[serde(default)]
    vel: [f64; 6],
    #[serde(default)]
    acc: [f64; 6],
}

fn identity_quat() -> [f64; 4] {
    [0.0, 0.0, 0.0, 1.0]
}

/// Runs `frictl dynamics`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Sub::Rnea(a) => rnea(a),
        Sub::Info(a) => info(a),
    }
}

fn load(m: &ModelArgs) -> anyhow::Result<Robot> {
    let reduction = match &m.keep {
        Some(keep) => {
            let mut locked_q = HashMap::new();
            for l in &m.lock {
                let (name, val) = l
                    .split_once('=')
                    .with_context(|| format!("--lock {l}: expected NAME=RAD"))?;
                let v: f64 = val
                    .trim()
                    .parse()
                    .with_context(|| format!("--lock {l}: '{val}' is not a number"))?;
                locked_q.insert(name.trim().to_string(), v);
            }
            Some(Reduction {
                keep: keep.iter().map(|s| s.trim().to_string()).collect(),
                locked_q,
            })
        }
        None => {
            if !m.lock.is_empty() {
                bail!("--lock needs --keep (the joints that stay movable)");
            }
            None
        }
    };
    let robot = match &m.urdf {
        Some(p) => Robot::from_urdf_file_reduced(p, reduction.as_ref())?,
        None => Robot::from_urdf_str_reduced(DEFAULT_URDF, DEFAULT_URDF_PATH, reduction.as_ref())?,
    };
    Ok(robot)
}

fn named(
    robot: &Robot,
    map: &HashMap<String, f64>,
    what: &str,
    line: usize,
) -> anyhow::Result<Vec<f64>> {
    for (k, v) in map {
        if !v.is_finite() {
            bail!("line {line}: {what}[{k}] = {v} is not finite");
        }
    }
    robot
        .vector_from_names(map.iter().map(|(k, v)| (k.as_str(), *v)))
        .with_context(|| format!("line {line}: in \"{what}\""))
}

fn rnea(a: RneaArgs) -> anyhow::Result<()> {
    let robot = load(&a.model)?;
    let reader: Box<dyn BufRead> = if a.cases.as_os_str() == "-" {
        Box::new(std::io::stdin().lock())
    } else {
        let (f, _) = frictionless::regular_file::open(&a.cases)
            .with_context(|| format!("cannot open cases file {}", a.cases.display()))?;
        Box::new(std::io::BufReader::new(f))
    };
    let mut file = match &a.out {
        Some(p) => Some(
            frictionless::output_file::AtomicFile::create(p)
                .with_context(|| format!("cannot create {}", p.display()))?,
        ),
        None => None,
    };
    let mut stdout = BufWriter::new(std::io::stdout().lock());
    let out: &mut dyn Write = match &mut file {
        Some(f) => f,
        None => &mut stdout,
    };
    let mut ws = Workspace::new(&robot);
    let mut tau = vec![0.0; robot.dof()];
    let src = a.cases.display().to_string();
    for (i, line) in reader.lines().enumerate() {
        let line_no = i + 1;
        let line = line.with_context(|| format!("{src}: cannot read line {line_no}"))?;
        if line.trim().is_empty() {
            continue;
        }
        let case: CaseJson = serde_json::from_str(&line)
            .with_context(|| format!("{src}: line {line_no} is not a valid case"))?;
        let q = named(&robot, &case.q, "q", line_no)?;
        let qd = named(&robot, &case.qd, "qd", line_no)?;
        let qdd = named(&robot, &case.qdd, "qdd", line_no)?;
        let mut ext = Vec::with_capacity(case.wrenches.len());
        for (frame, w) in &case.wrenches {
            if w.iter().any(|x| !x.is_finite()) {
                bail!("{src}: line {line_no}: wrench at '{frame}' {w:?} is not finite");
            }
            ext.push(ExternalWrench {
                frame: robot
                    .frame_id(frame)
                    .with_context(|| format!("{src}: line {line_no}"))?,
                wrench: Force::new(
                    Vector3::new(w[3], w[4], w[5]),
                    Vector3::new(w[0], w[1], w[2]),
                ),
            });
        }
        let mut obj = serde_json::Map::new();
        if a.floating_base {
            let base = match &case.base {
                Some(b) => BaseState::from_arrays(b.pos, b.quat, b.vel, b.acc)
                    .with_context(|| format!("{src}: line {line_no}"))?,
                None => BaseState::at_rest(),
            };
            let bw = robot.rnea_floating(&mut ws, &base, &q, &qd, &qdd, &ext, &mut tau)?;
            obj.insert("tau".into(), tau_json(&robot, &tau));
            let w = [bw.lin.x, bw.lin.y, bw.lin.z, bw.ang.x, bw.ang.y, bw.ang.z];
            obj.insert("base_wrench".into(), serde_json::json!(w));
        } else {
            if case.base.is_some() {
                bail!("{src}: line {line_no}: has \"base\" but --floating-base was not given");
            }
            robot.rnea_with_wrenches(&mut ws, &q, &qd, &qdd, &ext, &mut tau)?;
            obj.insert("tau".into(), tau_json(&robot, &tau));
        }
        serde_json::to_writer(&mut *out, &obj)?;
        out.write_all(b"\n")?;
    }
    out.flush()?;
    if let (Some(f), Some(p)) = (file, &a.out) {
        f.commit()
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

fn tau_json(robot: &Robot, tau: &[f64]) -> serde_json::Value {
    let m: BTreeMap<&str, f64> = robot.joint_names().zip(tau.iter().copied()).collect();
    serde_json::json!(m)
}

fn info(m: ModelArgs) -> anyhow::Result<()> {
    let robot = load(&m)?;
    println!("robot      {}", robot.name);
    println!("source     {}", robot.source);
    println!(
        "root link  {} ({:.3} kg incl. welded links)",
        robot.root_link, robot.root_inertia.mass_kg
    );
    println!("dof        {}", robot.dof());
    println!("frames     {}", robot.frames.len());
    println!("total mass {:.3} kg", robot.total_mass_kg());
    let q0 = vec![0.0; robot.dof()];
    println!(
        "\n{:<20} {:<9} {:>24} {:>19} {:>9} {:>12}  child link",
        "joint", "kind", "axis", "limits", "mass kg", "I_L@0 kg·m²"
    );
    for (j, jt) in robot.joints.iter().enumerate() {
        let view = robot.single_joint_view(&jt.name, &q0)?;
        let kind = match jt.kind {
            JointKind::Revolute => "revolute",
            JointKind::Prismatic => "prismatic",
        };
        let parent = if jt.parent_body == 0 {
            robot.root_link.as_str()
        } else {
            robot.joints[jt.parent_body - 1].name.as_str()
        };
        println!(
            "{:<20} {:<9} ({:>6.3}, {:>6.3}, {:>6.3}) [{:>7.4}, {:>7.4}] {:>9.3} {:>12.5}  {} (index {j}, after {parent})",
            jt.name,
            kind,
            jt.axis.x,
            jt.axis.y,
            jt.axis.z,
            jt.lower,
            jt.upper,
            jt.inertia.mass_kg,
            view.inertia_kg_m2(),
            jt.child_link,
        );
    }
    Ok(())
}
