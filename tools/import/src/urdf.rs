//! The robot of the current label's τ_ID from the command line's `--urdf` and `--fixed-joint`s:
//! the whole body, or one joint's link (the single-joint view).

use std::collections::BTreeMap;

use anyhow::Context;
use frictionless_sim::params::LinkModel;

/// The `--fixed-joint NAME=RAD` values by name.
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
        other.insert(n.trim().to_owned(), v);
    }
    Ok(other)
}

/// The whole-body model for τ_ID: the URDF (default `virtual_leg`) with the `--fixed-joint` values.
pub fn urdf_whole_body(
    urdf: Option<&str>,
    fixed_joints: &[String],
) -> anyhow::Result<frictionless_ident::preprocess::WholeBody> {
    let held = parse_fixed_joints(fixed_joints)?;
    let robot = match urdf.unwrap_or("virtual_leg") {
        "virtual_leg" => frictionless_dynamics::virtual_leg()?,
        path => frictionless_dynamics::Robot::from_urdf_file(path)?,
    };
    frictionless_ident::preprocess::WholeBody::new(robot, held)
        .map_err(|e| anyhow::anyhow!("--fixed-joint: {e}"))
}

/// The URDF link model of `joint` (URDF default `virtual_leg`) with other joints held at the
/// `NAME=RAD` positions, and its description for the sidecar.
pub fn urdf_link(
    urdf: Option<&str>,
    joint: &str,
    fixed_joints: &[String],
) -> anyhow::Result<(LinkModel, String)> {
    anyhow::ensure!(!joint.is_empty(), "no joint name: pass --joint");
    let other = parse_fixed_joints(fixed_joints)?;
    let urdf = urdf.unwrap_or("virtual_leg").to_string();
    let d = format!("URDF {urdf} joint {joint}, other joints {other:?}, fixed base, g = 9.80665");
    Ok((
        LinkModel::Urdf {
            urdf,
            joint: joint.to_string(),
            other_joints_rad: other,
        },
        d,
    ))
}
