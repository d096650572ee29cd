//! What an import is asked to do: the logs, the joints, the column or channel mapping and the
//! labelling settings, as plain values.
//!
//! What this module **is**: [`CsvOptions`], [`McapOptions`] and [`MatOptions`], each with the
//! [`CommonOptions`] every format shares. A command line (`frictl import csv|mat|mcap`) or any
//! other caller fills them; the import functions ([`crate::run_csv`], …) take them.
//!
//! What it is **not**: an argument parser. Error texts name the `frictl import` flag of a bad value
//! (`--joint`, `--base-quat`), the interface users meet these options through.

use std::path::PathBuf;

use frictionless_dataset::LabelSource;
use frictionless_ident::label_settings::LabelSettings;

/// The options every log format shares.
#[derive(Clone, Debug)]
pub struct CommonOptions {
    /// The dataset CSV to write (its sidecar beside it with `.json`); with several joints it holds
    /// `{joint}`, replaced by each joint's name.
    pub out: PathBuf,
    /// Label every joint the log has (the whole-body state and the URDF name them) instead of the
    /// listed joints.
    pub all_joints: bool,
    /// The label source (`None`: `given` if τ_F is read, else `torque-sensor` if τ_joint is, else
    /// `current`).
    pub label: Option<LabelSource>,
    /// Signed gear ratios: `R` for every joint or `NAME=R` for one.
    pub gear_ratio: Vec<String>,
    /// Torque constants [Nm/A]: `KT` or `NAME=KT`.
    pub kt: Vec<String>,
    /// A time gap larger than this starts a new chunk [s] (`None`: the format's default).
    pub gap_s: Option<f64>,
    /// Roles whose sign is flipped.
    pub negate: Vec<String>,
    /// The URDF for τ_ID of the current label.
    pub urdf: Option<String>,
    /// The joint's name in the URDF when it differs from the log's (single-joint view only).
    pub urdf_joint: Option<String>,
    /// URDF joints held fixed, `NAME=RAD`.
    pub fixed_joints: Vec<String>,
    /// The URDF frame whose orientation the logged base orientation is (`None`: the one the log
    /// names, or the root link).
    pub base_frame: Option<String>,
    /// Resampling, filter, smoother and sample-limit settings.
    pub settings: LabelSettings,
    /// Gravity along −z of the world frame [m/s²] (`None`: standard gravity).
    pub gravity_m_s2: Option<f64>,
}

/// `frictl import csv`: any CSV, columns and units mapped by role.
#[derive(Clone, Debug)]
pub struct CsvOptions {
    /// The CSV logs, one run each.
    pub files: Vec<PathBuf>,
    /// The joints to label (one dataset each).
    pub joint: Vec<String>,
    /// `ROLE=COLUMN` mappings (a column may hold `{joint}`).
    pub columns: Vec<String>,
    /// `ROLE=UNIT` (default SI).
    pub units: Vec<String>,
    /// The column template of every URDF joint's position, for the whole-body τ_ID.
    pub positions: Option<String>,
    /// The velocity column template.
    pub velocities: Option<String>,
    /// The acceleration column template.
    pub accelerations: Option<String>,
    /// Columns `X,Y,Z,W` of the root link's orientation in the world.
    pub base_quat: Option<String>,
    /// Measured wrenches, `FRAME=TEMPLATE` (`{c}` for fx … mz).
    pub wrenches: Vec<String>,
    /// The field delimiter.
    pub delimiter: char,
    /// Stream the log in windows of this many grid samples (`None`: read it whole).
    pub window_samples: Option<usize>,
    /// The options every format shares.
    pub common: CommonOptions,
}

/// `frictl import mcap`: ROS 2 bags of sensor_msgs/JointState.
#[derive(Clone, Debug)]
pub struct McapOptions {
    /// The MCAP bags, one run each.
    pub files: Vec<PathBuf>,
    /// The joints to label (one dataset each).
    pub joint: Vec<String>,
    /// The JointState topic.
    pub topic: String,
    /// The role of the `effort` field (`tau_joint`, `tau_motor`, `tau_f`, `current`, `none`).
    pub effort: String,
    /// A sensor_msgs/Imu topic whose orientation is the root link's.
    pub base_orientation: Option<String>,
    /// Measured wrenches, `FRAME=TOPIC` (geometry_msgs/WrenchStamped).
    pub wrenches: Vec<String>,
    /// Stream the bag in windows of this many grid samples (`None`: read it whole).
    pub window_samples: Option<usize>,
    /// The options every format shares.
    pub common: CommonOptions,
}

/// `frictl import mat`: the YARP robot logger's MATLAB v7.3 files.
#[derive(Clone, Debug)]
pub struct MatOptions {
    /// The `.mat` files, one run each.
    pub files: Vec<PathBuf>,
    /// The joints to label (none: the one of the desired-current channel).
    pub joint: Vec<String>,
    /// The channel of the root link's orientation in the world.
    pub base_orientation: Option<String>,
    /// Measured wrenches, `FRAME=CHANNEL`.
    pub wrenches: Vec<String>,
    /// Take the logged joint velocities and accelerations instead of smoothing the positions.
    pub logged_derivatives: bool,
    /// Stream the log in windows of this many grid samples (`None`: read it whole).
    pub window_samples: Option<usize>,
    /// The options every format shares.
    pub common: CommonOptions,
}
