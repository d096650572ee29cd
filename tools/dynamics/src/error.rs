//! Errors of the dynamics module: each names the URDF (file or label) and the joint, link, frame or
//! value at fault. Nothing in the module panics on bad input.

/// Everything that can go wrong building a model or calling an algorithm on it.
#[derive(Debug, thiserror::Error)]
pub enum DynamicsError {
    /// The URDF could not be read or parsed.
    #[error("cannot read URDF {path}: {message}")]
    Read {
        /// File path or label.
        path: String,
        /// Reader or parser message.
        message: String,
    },
    /// The link/joint graph is not a tree with one root (or names are duplicated/unknown).
    #[error("URDF {source_name}: {message}")]
    Structure {
        /// File path or label.
        source_name: String,
        /// What is wrong, naming the joint or link.
        message: String,
    },
    /// A `<inertial>` value is not finite, or the mass is negative.
    #[error("URDF {source_name}: link '{link}': inertial {what}")]
    BadInertial {
        /// File path or label.
        source_name: String,
        /// Link name.
        link: String,
        /// The offending key and value.
        what: String,
    },
    /// A joint type this module does not support as a movable joint (floating, planar, spherical).
    #[error(
        "URDF {source_name}: joint '{joint}' has unsupported type '{kind}' (lock it in a reduced model)"
    )]
    UnsupportedJoint {
        /// File path or label.
        source_name: String,
        /// Joint name.
        joint: String,
        /// URDF joint type.
        kind: String,
    },
    /// A joint axis of zero (or non-finite) length.
    #[error("URDF {source_name}: joint '{joint}' has an invalid axis {axis:?}")]
    BadAxis {
        /// File path or label.
        source_name: String,
        /// Joint name.
        joint: String,
        /// The axis as written.
        axis: [f64; 3],
    },
    /// A joint name that is not a (movable) joint of the model.
    #[error("{source_name}: no movable joint named '{joint}'")]
    UnknownJoint {
        /// File path or label.
        source_name: String,
        /// The name asked for.
        joint: String,
    },
    /// A fixed joint named where a movable one is required.
    #[error("{source_name}: joint '{joint}' is fixed, not movable")]
    NotMovable {
        /// File path or label.
        source_name: String,
        /// Joint name.
        joint: String,
    },
    /// A frame name that is neither a link nor a joint of the model.
    #[error("{source_name}: no frame (link or joint) named '{frame}'")]
    UnknownFrame {
        /// File path or label.
        source_name: String,
        /// The name asked for.
        frame: String,
    },
    /// A slice or matrix of the wrong size.
    #[error("{what}: expected length {expected}, got {got}")]
    Dimension {
        /// Which argument.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// A non-finite or otherwise invalid numeric input.
    #[error("invalid input {what}: {value}")]
    BadInput {
        /// Which argument.
        what: String,
        /// The value.
        value: String,
    },
    /// A joint whose articulated inertia about its axis is not positive: M(q) is singular there.
    #[error(
        "{source_name}: joint '{joint}' moves a subtree with no inertia about its axis (articulated inertia {value}): forward dynamics is undefined"
    )]
    Singular {
        /// File path or label.
        source_name: String,
        /// Joint name.
        joint: String,
        /// Sᵀ·I^A·S [kg·m² or kg].
        value: f64,
    },
}
