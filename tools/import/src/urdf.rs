//! The robot of the current label's τ_ID from the command line's `--urdf` and `--fixed-joint`s:
//! the whole body, or one joint's link (the single-joint view).

use std::collections::BTreeMap;

use anyhow::Context;
use frictionless_sim::params::LinkModel;

/// Largest |position| of a held joint \[rad\]: three turns (no joint of a robot this labels turns
/// further; a larger value is a unit or typing mistake).
pub const MAX_FIXED_JOINT_RAD: f64 = 6.0 * std::f64::consts::PI;

/// The `--fixed-joint NAME=RAD` values by name: each joint once, at a finite position within
/// ±[`MAX_FIXED_JOINT_RAD`].
pub fn parse_fixed_joints(fixed_joints: &[String]) -> anyhow::Result<BTreeMap<String, f64>> {
    let mut other = BTreeMap::new();
    for s in fixed_joints {
        let (n, v) = s
            .split_once('=')
            .with_context(|| format!("--fixed-joint {s:?}: expected NAME=RAD"))?;
        let v: f64 = v
            .trim()
            .parse()
            .with_context(|| format!("--fixed-joint {s:?}: {v:?} is not a number"))?;
        anyhow::ensure!(v.is_finite(), "--fixed-joint {s:?}: not finite");
        anyhow::ensure!(
            v.abs() <= MAX_FIXED_JOINT_RAD,
            "--fixed-joint {s:?}: more than three turns (±{MAX_FIXED_JOINT_RAD:.2} rad); positions \
             are in rad"
        );
        anyhow::ensure!(
            other.insert(n.trim().to_owned(), v).is_none(),
            "--fixed-joint {s:?}: joint `{}` is held twice",
            n.trim()
        );
    }
    Ok(other)
}

/// Refuses a labelled joint (`--joint`, `--urdf-joint`) that is also held by `--fixed-joint`: its
/// own motion would be replaced by a constant in its label's τ_ID.
pub fn check_not_held(labelled: &[&str], fixed_joints: &[String]) -> anyhow::Result<()> {
    let held = parse_fixed_joints(fixed_joints)?;
    if let Some(j) = labelled.iter().find(|j| held.contains_key(**j)) {
        anyhow::bail!(
            "--fixed-joint {j}=…: `{j}` is the labelled joint; a held joint is one whose motion \
             the label ignores (drop it from --fixed-joint)"
        );
    }
    Ok(())
}

/// `--gravity-m-s2`'s value: the one given, else standard gravity [m/s²].
pub fn gravity_m_s2(given: Option<f64>) -> f64 {
    given.unwrap_or(frictionless_dynamics::GRAVITY_M_S2)
}

/// The whole-body model for τ_ID: the URDF (default `virtual_leg`) with the `--fixed-joint` values,
/// under gravity `gravity_m_s2` [m/s²] (`--gravity-m-s2`).
pub fn urdf_whole_body(
    urdf: Option<&str>,
    fixed_joints: &[String],
    gravity_m_s2: f64,
) -> anyhow::Result<frictionless_ident::preprocess::WholeBody> {
    let held = parse_fixed_joints(fixed_joints)?;
    let robot = match urdf.unwrap_or("virtual_leg") {
        "virtual_leg" => frictionless_dynamics::virtual_leg()?,
        path => frictionless_dynamics::Robot::from_urdf_file(path)?,
    }
    .with_gravity_m_s2(gravity_m_s2)
    .map_err(|e| anyhow::anyhow!("--gravity-m-s2 {gravity_m_s2}: {e}"))?;
    frictionless_ident::preprocess::WholeBody::new(robot, held)
        .map_err(|e| anyhow::anyhow!("--fixed-joint: {e}"))
}

/// The URDF link model of `joint` (URDF default `virtual_leg`) with other joints held at the
/// `NAME=RAD` positions under gravity `gravity_m_s2` [m/s²], and its description for the sidecar.
pub fn urdf_link(
    urdf: Option<&str>,
    joint: &str,
    fixed_joints: &[String],
    gravity_m_s2: f64,
) -> anyhow::Result<(LinkModel, String)> {
    anyhow::ensure!(!joint.is_empty(), "no joint name: pass --joint");
    check_not_held(&[joint], fixed_joints)?;
    let other = parse_fixed_joints(fixed_joints)?;
    let urdf = urdf.unwrap_or("virtual_leg").to_string();
    let d = format!(
        "URDF {urdf} joint {joint}, other joints {other:?}, fixed base, {}",
        frictionless_ident::preprocess::gravity_text(gravity_m_s2)
    );
    Ok((
        LinkModel::Urdf {
            urdf,
            joint: joint.to_string(),
            other_joints_rad: other,
            gravity_m_s2: Some(gravity_m_s2),
        },
        d,
    ))
}
