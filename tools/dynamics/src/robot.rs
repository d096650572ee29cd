//! The kinematic tree built from a URDF: bodies connected by 1-DoF joints, with fixed joints lumped.
//!
//! What it **is**: parsing (`urdf-rs`), lumping of fixed joints (the child link's inertia is moved
//! into the nearest moving body), inertial `<origin rpy>` rotation (`I = R·I·Rᵀ`), joint-axis
//! normalisation, and "reduced models" (every joint not in a named set locked at a given position,
//! like iDynTree's `loadReducedModel`). Joints are always looked up by **name**; their index order is
//! depth-first from the root link and must not be relied upon.
//!
//! What it is **not**: the algorithms (see [`super::algorithms`]), geometry, collision, or URDF
//! `<dynamics>` damping/friction (Gazebo placeholders on the iCub/ergoCub models: ignored). `<mimic>`
//! tags are ignored (the joint is treated as independent).

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use super::error::DynamicsError;
use super::spatial::{SpatialInertia, Transform, axis_angle, axis_angle_sin_cos};

/// Standard gravity [m/s²], along −z of the world frame: every [`Robot`]'s unless
/// [`Robot::with_gravity_m_s2`] sets another.
pub const GRAVITY_M_S2: f64 = 9.80665;

/// Kind of a movable joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// URDF `revolute` or `continuous`: q in rad, generalised force in N·m.
    Revolute,
    /// URDF `prismatic`: q in m, generalised force in N.
    Prismatic,
}

/// One movable joint and the body it moves (the child link plus every link welded to it).
#[derive(Clone, Debug)]
pub struct Joint {
    /// Joint name from the URDF.
    pub name: String,
    /// Name of the URDF child link (the body's own frame).
    pub child_link: String,
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Body index of the parent body (0 = the root body; joint `j` moves body `j + 1`).
    pub parent_body: usize,
    /// Placement of the joint frame at q = 0 in the parent body frame.
    pub tree: Transform,
    /// Unit joint axis in the joint frame.
    pub axis: Vector3<f64>,
    /// Lower position limit from the URDF [rad or m] (−∞ if absent).
    pub lower: f64,
    /// Upper position limit from the URDF [rad or m] (+∞ if absent).
    pub upper: f64,
    /// Inertia of the body (with lumped fixed links) in its own frame.
    pub inertia: SpatialInertia,
}

impl Joint {
    /// Placement of a revolute joint's body in its parent body from (sin q, cos q) (what
    /// [`Joint::placement`] computes with `q.sin_cos()`; for a prismatic joint use `placement`).
    #[inline]
    pub fn placement_sin_cos(&self, sin_q: f64, cos_q: f64) -> Transform {
        Transform {
            rot: self.tree.rot * axis_angle_sin_cos(&self.axis, sin_q, cos_q),
            pos: self.tree.pos,
        }
    }

    /// Placement of the moved body in its parent body at joint position `q` [rad or m].
    #[inline]
    pub fn placement(&self, q: f64) -> Transform {
        match self.kind {
            JointKind::Revolute => Transform {
                rot: self.tree.rot * axis_angle(&self.axis, q),
                pos: self.tree.pos,
            },
            JointKind::Prismatic => Transform {
                rot: self.tree.rot,
                pos: self.tree.pos + self.tree.rot * (self.axis * q),
            },
        }
    }
}

/// A named frame (every URDF link, and every URDF joint at its child link) attached to a body.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Link or joint name.
    pub name: String,
    /// Body index (0 = root body, `j + 1` = body moved by joint `j`).
    pub body: usize,
    /// Placement of the frame in the body frame.
    pub placement: Transform,
}

/// Handle to a named frame of a [`Robot`] (see [`Robot::frame_id`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameId(pub usize);

/// Which joints stay movable when building a reduced model.
#[derive(Clone, Debug, Default)]
pub struct Reduction {
    /// Names of the joints that stay movable (in any order).
    pub keep: Vec<String>,
    /// Positions [rad or m] at which the other joints are locked; joints not listed are locked at 0.
    pub locked_q: HashMap<String, f64>,
}

/// A rigid-body tree built from a URDF, ready for RNEA/CRBA.
#[derive(Clone, Debug)]
pub struct Robot {
    /// URDF `<robot name>`.
    pub name: String,
    /// Where the model came from (file path or a label), for error messages.
    pub source: String,
    /// Name of the root link (the fixed base, or the floating base body).
    pub root_link: String,
    /// Inertia of the root body (root link plus links welded to it), in the root link frame.
    pub root_inertia: SpatialInertia,
    /// Movable joints in depth-first order (never rely on this order: use names).
    pub joints: Vec<Joint>,
    /// Named frames: every link, and every joint (at its child link).
    pub frames: Vec<Frame>,
    joint_index: HashMap<String, usize>,
    frame_index: HashMap<String, usize>,
    /// Magnitude of gravity [m/s²], along −z of the world frame.
    gravity_m_s2: f64,
}

impl Robot {
    /// Parses a URDF file; every non-fixed joint is movable.
    pub fn from_urdf_file(path: impl AsRef<Path>) -> Result<Robot, DynamicsError> {
        Self::from_urdf_file_reduced(path, None)
    }

    /// Parses a URDF file keeping only `reduction.keep` movable (all joints if `None`).
    pub fn from_urdf_file_reduced(
        path: impl AsRef<Path>,
        reduction: Option<&Reduction>,
    ) -> Result<Robot, DynamicsError> {
        let path = path.as_ref();
        let source = path.display().to_string();
        let text =
            frictionless::regular_file::read_text(path).map_err(|e| DynamicsError::Read {
                path: source.clone(),
                message: e.to_string(),
            })?;
        Self::from_urdf_str_reduced(&text, &source, reduction)
    }

    /// Parses URDF text; `source` names it in error messages.
    pub fn from_urdf_str(text: &str, source: &str) -> Result<Robot, DynamicsError> {
        Self::from_urdf_str_reduced(text, source, None)
    }

    /// Parses URDF text keeping only `reduction.keep` movable (all joints if `None`).
    pub fn from_urdf_str_reduced(
        text: &str,
        source: &str,
        reduction: Option<&Reduction>,
    ) -> Result<Robot, DynamicsError> {
        let urdf =
            urdf_rs::read_from_string(&dynamics_only(text)).map_err(|e| DynamicsError::Read {
                path: source.to_string(),
                message: e.to_string(),
            })?;
        build(&urdf, source, reduction)
    }

    /// The same model under gravity of magnitude `gravity_m_s2` [m/s²] along −z of the world
    /// frame (default [`GRAVITY_M_S2`]); every algorithm uses it. Fails unless
    /// finite and ≥ 0.
    pub fn with_gravity_m_s2(mut self, gravity_m_s2: f64) -> Result<Robot, DynamicsError> {
        if !(gravity_m_s2.is_finite() && gravity_m_s2 >= 0.0) {
            return Err(DynamicsError::BadInput {
                what: "gravity [m/s^2] (finite, >= 0)".into(),
                value: gravity_m_s2.to_string(),
            });
        }
        self.gravity_m_s2 = gravity_m_s2;
        Ok(self)
    }

    /// Magnitude of the model's gravity [m/s²] ([`Self::with_gravity_m_s2`]).
    pub fn gravity_m_s2(&self) -> f64 {
        self.gravity_m_s2
    }

    /// The model's gravity vector in the world frame [m/s²]: `[0, 0, −g]`.
    pub fn gravity_world_m_s2(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, -self.gravity_m_s2)
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// Movable joint names in index order.
    pub fn joint_names(&self) -> impl Iterator<Item = &str> {
        self.joints.iter().map(|j| j.name.as_str())
    }

    /// Index of a movable joint by name.
    pub fn joint_index(&self, name: &str) -> Result<usize, DynamicsError> {
        self.joint_index
            .get(name)
            .copied()
            .ok_or_else(|| DynamicsError::UnknownJoint {
                source_name: self.source.clone(),
                joint: name.to_string(),
            })
    }

    /// Handle of a named frame (link or joint name).
    pub fn frame_id(&self, name: &str) -> Result<FrameId, DynamicsError> {
        self.frame_index
            .get(name)
            .map(|&i| FrameId(i))
            .ok_or_else(|| DynamicsError::UnknownFrame {
                source_name: self.source.clone(),
                frame: name.to_string(),
            })
    }

    /// Total mass of the model [kg].
    pub fn total_mass_kg(&self) -> f64 {
        self.root_inertia.mass_kg + self.joints.iter().map(|j| j.inertia.mass_kg).sum::<f64>()
    }

    /// Body index of the parent of body `b` (`None` for the root body 0).
    pub fn parent_body(&self, b: usize) -> Option<usize> {
        if b == 0 {
            None
        } else {
            Some(self.joints[b - 1].parent_body)
        }
    }

    /// Builds a joint-position vector from a name → value map; joints not named are 0.
    /// Fails on a name that is not a movable joint of this model.
    pub fn vector_from_names<'a>(
        &self,
        values: impl IntoIterator<Item = (&'a str, f64)>,
    ) -> Result<Vec<f64>, DynamicsError> {
        let mut v = vec![0.0; self.dof()];
        for (name, x) in values {
            v[self.joint_index(name)?] = x;
        }
        Ok(v)
    }
}

/// The URDF without what dynamics never reads: every `<visual>` and `<collision>` element and the
/// robot-level `<material>` definitions. Real robot descriptions carry geometry urdf-rs refuses
/// although URDF parsers accept it (iCub's and Romeo's `<texture />` without a `filename`), and a
/// model's inertias and joints should not fail to load over a mesh. Text that is not well-formed XML
/// is returned unchanged, so that urdf-rs reports the error.
fn dynamics_only(text: &str) -> std::borrow::Cow<'_, str> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(text);
    let mut drop: Vec<std::ops::Range<usize>> = Vec::new();
    let mut depth = 0usize;
    loop {
        let start = reader.buffer_position() as usize;
        let unused = |name: &[u8], depth: usize| {
            name == b"visual" || name == b"collision" || (name == b"material" && depth == 1)
        };
        match reader.read_event() {
            Ok(Event::Start(e)) if unused(e.name().as_ref(), depth) => {
                if reader.read_to_end(e.name()).is_err() {
                    return text.into();
                }
                drop.push(start..reader.buffer_position() as usize);
            }
            Ok(Event::Empty(e)) if unused(e.name().as_ref(), depth) => {
                drop.push(start..reader.buffer_position() as usize);
            }
            Ok(Event::Start(_)) => depth += 1,
            Ok(Event::End(_)) => depth = depth.saturating_sub(1),
            Ok(Event::Eof) => break,
            Ok(_) => {}
            Err(_) => return text.into(),
        }
    }
    if drop.is_empty() {
        return text.into();
    }
    let mut kept = String::with_capacity(text.len());
    let mut at = 0;
    for r in drop {
        kept.push_str(text.get(at..r.start).unwrap_or_default());
        at = r.end;
    }
    kept.push_str(text.get(at..).unwrap_or_default());
    kept.into()
}

struct ParsedLink {
    inertia: SpatialInertia,
}

fn parse_link(link: &urdf_rs::Link, source: &str) -> Result<ParsedLink, DynamicsError> {
    let inl = &link.inertial;
    let i = &inl.inertia;
    let values = [
        ("mass", inl.mass.value),
        ("ixx", i.ixx),
        ("ixy", i.ixy),
        ("ixz", i.ixz),
        ("iyy", i.iyy),
        ("iyz", i.iyz),
        ("izz", i.izz),
    ]
    .into_iter()
    .chain(inl.origin.xyz.0.iter().map(|&v| ("origin xyz", v)))
    .chain(inl.origin.rpy.0.iter().map(|&v| ("origin rpy", v)));
    for (what, v) in values {
        if !v.is_finite() {
            return Err(DynamicsError::BadInertial {
                source_name: source.to_string(),
                link: link.name.clone(),
                what: format!("{what} = {v} is not finite"),
            });
        }
    }
    if inl.mass.value < 0.0 {
        return Err(DynamicsError::BadInertial {
            source_name: source.to_string(),
            link: link.name.clone(),
            what: format!("mass = {} is negative", inl.mass.value),
        });
    }
    let ic = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    let origin = Transform::from_xyz_rpy(inl.origin.xyz.0, inl.origin.rpy.0);
    // Inertia given in the inertial frame (rotated by rpy): I_link = R·I·Rᵀ, COM at xyz.
    let ic_link = origin.rot * ic * origin.rot.transpose();
    Ok(ParsedLink {
        inertia: SpatialInertia::from_com(inl.mass.value, origin.pos, ic_link),
    })
}

/// The URDF's link/joint graph, checked: names unique, every joint between known links, each link
/// the child of at most one joint, exactly one root.
struct Graph<'u> {
    link_index: HashMap<&'u str, usize>,
    urdf_joint_names: HashMap<&'u str, usize>,
    /// URDF joint indices whose parent is each link, in file order.
    children: Vec<Vec<usize>>,
    root: usize,
}

fn index_graph<'u>(urdf: &'u urdf_rs::Robot, source: &str) -> Result<Graph<'u>, DynamicsError> {
    let src = || source.to_string();
    let mut link_index = HashMap::new();
    for (i, l) in urdf.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(DynamicsError::Structure {
                source_name: src(),
                message: format!("link '{}' is defined twice", l.name),
            });
        }
    }
    let mut urdf_joint_names = HashMap::new();
    let mut parent_joint: Vec<Option<usize>> = vec![None; urdf.links.len()];
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); urdf.links.len()];
    for (ji, j) in urdf.joints.iter().enumerate() {
        if urdf_joint_names.insert(j.name.as_str(), ji).is_some() {
            return Err(DynamicsError::Structure {
                source_name: src(),
                message: format!("joint '{}' is defined twice", j.name),
            });
        }
        let find = |name: &str| {
            link_index
                .get(name)
                .copied()
                .ok_or_else(|| DynamicsError::Structure {
                    source_name: src(),
                    message: format!("joint '{}' references unknown link '{}'", j.name, name),
                })
        };
        let p = find(&j.parent.link)?;
        let c = find(&j.child.link)?;
        if let Some(other) = parent_joint[c] {
            return Err(DynamicsError::Structure {
                source_name: src(),
                message: format!(
                    "link '{}' is the child of two joints ('{}' and '{}')",
                    j.child.link, urdf.joints[other].name, j.name
                ),
            });
        }
        parent_joint[c] = Some(ji);
        children[p].push(ji);
    }
    let roots: Vec<usize> = (0..urdf.links.len())
        .filter(|&i| parent_joint[i].is_none())
        .collect();
    if urdf.links.is_empty() {
        return Err(DynamicsError::Structure {
            source_name: src(),
            message: "no <link> elements (a xacro file of macros only? expand it with xacro first)"
                .to_string(),
        });
    }
    if roots.len() != 1 {
        return Err(DynamicsError::Structure {
            source_name: src(),
            message: format!(
                "expected exactly one root link, found {:?}",
                roots
                    .iter()
                    .map(|&i| urdf.links[i].name.as_str())
                    .collect::<Vec<_>>()
            ),
        });
    }
    Ok(Graph {
        link_index,
        urdf_joint_names,
        children,
        root: roots[0],
    })
}

/// Every joint the reduction names exists and is not fixed, and none is both kept and locked.
fn validate_reduction(
    urdf: &urdf_rs::Robot,
    graph: &Graph<'_>,
    r: &Reduction,
    source: &str,
) -> Result<(), DynamicsError> {
    let src = || source.to_string();
    for name in r.keep.iter().chain(r.locked_q.keys()) {
        match graph.urdf_joint_names.get(name.as_str()) {
            None => {
                return Err(DynamicsError::UnknownJoint {
                    source_name: src(),
                    joint: name.clone(),
                });
            }
            Some(&ji) if urdf.joints[ji].joint_type == urdf_rs::JointType::Fixed => {
                return Err(DynamicsError::NotMovable {
                    source_name: src(),
                    joint: name.clone(),
                });
            }
            _ => {}
        }
    }
    if let Some(name) = r.keep.iter().find(|k| r.locked_q.contains_key(*k)) {
        return Err(DynamicsError::Structure {
            source_name: src(),
            message: format!("joint '{name}' is both kept and locked"),
        });
    }
    Ok(())
}

/// The kind of a URDF joint (`None` = fixed, or an unsupported type the reduction locks anyway)
/// and its unit axis (`x` when it has no kind).
fn joint_kind_and_axis(
    j: &urdf_rs::Joint,
    reduction: Option<&Reduction>,
    source: &str,
) -> Result<(Option<JointKind>, Vector3<f64>), DynamicsError> {
    let kind = match j.joint_type {
        urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => Some(JointKind::Revolute),
        urdf_rs::JointType::Prismatic => Some(JointKind::Prismatic),
        urdf_rs::JointType::Fixed => None,
        ref other => {
            let locked = reduction.is_some_and(|r| !r.keep.contains(&j.name));
            if locked {
                None
            } else {
                return Err(DynamicsError::UnsupportedJoint {
                    source_name: source.to_string(),
                    joint: j.name.clone(),
                    kind: format!("{other:?}").to_lowercase(),
                });
            }
        }
    };
    let axis_raw = Vector3::from(j.axis.xyz.0);
    let axis_norm = axis_raw.norm();
    if kind.is_some() && !(axis_norm.is_finite() && axis_norm > 1e-9) {
        return Err(DynamicsError::BadAxis {
            source_name: source.to_string(),
            joint: j.name.clone(),
            axis: j.axis.xyz.0,
        });
    }
    let axis = if kind.is_some() {
        axis_raw / axis_norm
    } else {
        Vector3::x()
    };
    Ok((kind, axis))
}

/// The bodies of the model as the tree walk produces them.
struct Bodies {
    root_inertia: SpatialInertia,
    joints: Vec<Joint>,
    frames: Vec<Frame>,
}

/// Placement in its parent body of a child link behind a fixed joint, or behind a movable joint
/// locked at its reduction position (0 if the reduction gives none).
fn locked_placement(
    j: &urdf_rs::Joint,
    kind: Option<JointKind>,
    axis: Vector3<f64>,
    joint_in_body: Transform,
    reduction: Option<&Reduction>,
) -> Transform {
    let q_lock = reduction
        .and_then(|r| r.locked_q.get(&j.name).copied())
        .unwrap_or(0.0);
    match kind {
        Some(k) => {
            let tmp = Joint {
                name: String::new(),
                child_link: String::new(),
                kind: k,
                parent_body: 0,
                tree: joint_in_body,
                axis,
                lower: 0.0,
                upper: 0.0,
                inertia: SpatialInertia::zero(),
            };
            tmp.placement(q_lock)
        }
        None => joint_in_body,
    }
}

impl Bodies {
    /// Lumps the child link of `j` (inertia `child_inertia`, placed at `child_in_body`) into `body`.
    fn lump(
        &mut self,
        j: &urdf_rs::Joint,
        body: usize,
        child_in_body: Transform,
        child_inertia: SpatialInertia,
    ) {
        let lumped = child_inertia.to_parent(&child_in_body);
        if body == 0 {
            self.root_inertia += lumped;
        } else {
            self.joints[body - 1].inertia += lumped;
        }
        for name in [&j.child.link, &j.name] {
            self.frames.push(Frame {
                name: name.clone(),
                body,
                placement: child_in_body,
            });
        }
    }
}

/// Walks the tree depth-first from the root, children in file order: each movable joint (kept by
/// the reduction) starts a body, every other child link is lumped into its parent's body.
fn walk_tree(
    urdf: &urdf_rs::Robot,
    graph: &Graph<'_>,
    parsed: &[ParsedLink],
    reduction: Option<&Reduction>,
    source: &str,
) -> Result<Bodies, DynamicsError> {
    let root = graph.root;
    let mut bodies = Bodies {
        root_inertia: parsed[root].inertia,
        joints: Vec::new(),
        frames: vec![Frame {
            name: urdf.links[root].name.clone(),
            body: 0,
            placement: Transform::identity(),
        }],
    };
    let mut visited = vec![false; urdf.links.len()];
    visited[root] = true;
    // Depth-first, children in file order: (link, body, placement of link in body).
    let mut stack: Vec<(usize, usize, Transform)> = vec![(root, 0, Transform::identity())];
    while let Some((link, body, link_in_body)) = stack.pop() {
        for &ji in graph.children[link].iter().rev() {
            let j = &urdf.joints[ji];
            let child = graph.link_index[j.child.link.as_str()];
            if visited[child] {
                return Err(DynamicsError::Structure {
                    source_name: source.to_string(),
                    message: format!("kinematic loop at joint '{}'", j.name),
                });
            }
            visited[child] = true;
            let origin = Transform::from_xyz_rpy(j.origin.xyz.0, j.origin.rpy.0);
            let joint_in_body = link_in_body.compose(&origin);
            let (kind, axis) = joint_kind_and_axis(j, reduction, source)?;
            let movable = kind.is_some() && reduction.is_none_or(|r| r.keep.contains(&j.name));
            if movable {
                let kind = kind.expect("movable implies a kind");
                let new_body = bodies.joints.len() + 1;
                bodies.joints.push(Joint {
                    name: j.name.clone(),
                    child_link: j.child.link.clone(),
                    kind,
                    parent_body: body,
                    tree: joint_in_body,
                    axis,
                    lower: j.limit.lower,
                    upper: j.limit.upper,
                    inertia: parsed[child].inertia,
                });
                for name in [&j.child.link, &j.name] {
                    bodies.frames.push(Frame {
                        name: name.clone(),
                        body: new_body,
                        placement: Transform::identity(),
                    });
                }
                stack.push((child, new_body, Transform::identity()));
            } else {
                // Fixed, or a movable joint locked at its reduction position.
                let child_in_body = locked_placement(j, kind, axis, joint_in_body, reduction);
                bodies.lump(j, body, child_in_body, parsed[child].inertia);
                stack.push((child, body, child_in_body));
            }
        }
    }
    Ok(bodies)
}

fn build(
    urdf: &urdf_rs::Robot,
    source: &str,
    reduction: Option<&Reduction>,
) -> Result<Robot, DynamicsError> {
    let graph = index_graph(urdf, source)?;
    if let Some(r) = reduction {
        validate_reduction(urdf, &graph, r, source)?;
    }
    let parsed: Vec<ParsedLink> = urdf
        .links
        .iter()
        .map(|l| parse_link(l, source))
        .collect::<Result<_, _>>()?;
    let Bodies {
        root_inertia,
        joints,
        frames,
    } = walk_tree(urdf, &graph, &parsed, reduction, source)?;
    if let Some(r) = reduction {
        // `keep` names a non-fixed joint (checked above), so it must have become movable.
        debug_assert!(r.keep.iter().all(|k| joints.iter().any(|j| &j.name == k)));
    }
    let joint_index = joints
        .iter()
        .enumerate()
        .map(|(i, j)| (j.name.clone(), i))
        .collect();
    let frame_index = frames
        .iter()
        .enumerate()
        .map(|(i, f)| (f.name.clone(), i))
        .collect();
    Ok(Robot {
        name: urdf.name.clone(),
        source: source.to_string(),
        root_link: urdf.links[graph.root].name.clone(),
        root_inertia,
        joints,
        frames,
        joint_index,
        frame_index,
        gravity_m_s2: GRAVITY_M_S2,
    })
}

#[cfg(test)]
mod tests {
    use super::super::algorithms::Workspace;
    use super::GRAVITY_M_S2;

    #[test]
    fn gravity_torques_scale_with_the_models_gravity() {
        let leg = super::super::virtual_leg().unwrap();
        assert_eq!(leg.gravity_m_s2(), GRAVITY_M_S2);
        let q: Vec<f64> = (0..leg.dof()).map(|k| 0.3 + 0.2 * k as f64).collect();
        let zero = vec![0.0; leg.dof()];
        let torques = |g: f64| {
            let r = leg.clone().with_gravity_m_s2(g).unwrap();
            let mut ws = Workspace::new(&r);
            let (mut tau, mut grav) = (zero.clone(), zero.clone());
            r.rnea(&mut ws, &q, &zero, &zero, &mut tau).unwrap();
            r.gravity_torques(&mut ws, &q, &mut grav).unwrap();
            assert_eq!(tau, grav);
            let knee = r.single_joint_view("l_knee", &q).unwrap();
            (tau, knee.gravity_nm(q[r.joint_index("l_knee").unwrap()]))
        };
        let (t1, k1) = torques(GRAVITY_M_S2);
        let (t2, k2) = torques(2.0 * GRAVITY_M_S2);
        let (t0, k0) = torques(0.0);
        assert!(t1.iter().any(|t| t.abs() > 0.1), "{t1:?}");
        for k in 0..t1.len() {
            assert!(
                (t2[k] - 2.0 * t1[k]).abs() < 1e-9 * (1.0 + t1[k].abs()),
                "joint {k}"
            );
            assert_eq!(t0[k], 0.0);
        }
        assert!(
            k1.abs() > 0.1 && (k2 - 2.0 * k1).abs() < 1e-9 * k1.abs(),
            "{k1} {k2}"
        );
        assert_eq!(k0, 0.0);
        for bad in [f64::NAN, -1.0, f64::INFINITY] {
            let e = leg.clone().with_gravity_m_s2(bad).unwrap_err().to_string();
            assert!(e.contains("gravity"), "{e}");
        }
    }
}
