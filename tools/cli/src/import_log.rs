//! `frictl import csv|mat|mcap`: the robot-log importers' arguments, and the options they give
//! `frictionless-import` (which does the work and never sees this parser).

use std::path::PathBuf;

use frictionless_dataset::LabelSource;

use crate::preprocess::PipelineArgs;

/// The log formats `frictl import` reads, each its own subcommand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// `frictl import csv`: any CSV, columns and units mapped by role.
    Csv,
    /// `frictl import mat`: the YARP robot logger's MATLAB v7.3 files (build feature `mat`).
    Mat,
    /// `frictl import mcap`: ROS 2 bags of sensor_msgs/JointState.
    Mcap,
}

impl LogFormat {
    /// The subcommand's name (`csv`, `mat`, `mcap`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Csv => "csv",
            Self::Mat => "mat",
            Self::Mcap => "mcap",
        }
    }

    /// Checks a whole `frictl import FORMAT …` command line (`argv[0..2]` = `import`, the format)
    /// as the command parses it, so a bad option is refused before anything runs.
    pub fn check_argv(self, argv: &[String]) -> anyhow::Result<()> {
        match self {
            Self::Csv => crate::stage::roundtrip::<CsvArgs>(2, argv).map(drop),
            Self::Mat => crate::stage::roundtrip::<MatArgs>(2, argv).map(drop),
            Self::Mcap => crate::stage::roundtrip::<McapArgs>(2, argv).map(drop),
        }
    }
}

/// Label source on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelArg {
    /// r·k_t·i − τ_ID (needs s, current, --gear-ratio, --kt and the link dynamics: --urdf/--joint).
    Current,
    /// τ_motor − τ_joint (needs tau_joint, and tau_motor or current with --gear-ratio and --kt).
    TorqueSensor,
    /// The log's tau_f column.
    Given,
}

impl From<LabelArg> for LabelSource {
    fn from(l: LabelArg) -> Self {
        match l {
            LabelArg::Current => LabelSource::Current,
            LabelArg::TorqueSensor => LabelSource::TorqueSensor,
            LabelArg::Given => LabelSource::Given,
        }
    }
}

/// Options every log format shares.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct CommonArgs {
    /// Output dataset CSV (its sidecar is written next to it with `.json`); with several joints it
    /// must hold `{joint}`, replaced by each joint's name (e.g. `-o ds_{joint}.csv`).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Label every joint the log has (`all`; the whole-body state and the URDF name them) instead
    /// of the `--joint` list.
    #[arg(long = "joints", value_name = "all", value_parser = ["all"])]
    pub joints_all: Option<String>,
    /// Label source (default: `given` if tau_f is read, else `torque-sensor` if tau_joint is, else
    /// `current`).
    #[arg(long, value_enum)]
    #[serde(serialize_with = "super::stage::as_opt_value_enum")]
    pub label: Option<LabelArg>,
    /// Signed gear ratio r (motor angle per joint angle) for r·k_t·i and Δθ = r·s − θ: `R` for every
    /// joint or `NAME=R` for one (repeatable); recorded in the sidecar (1 when not given and not
    /// needed, marked as a placeholder).
    #[arg(long, allow_hyphen_values = true, value_name = "R|NAME=R")]
    pub gear_ratio: Vec<String>,
    /// Torque constant k_t [Nm/A] for r·k_t·i: `KT` or `NAME=KT` (repeatable; 1 when not given and
    /// not needed, as above).
    #[arg(long, allow_hyphen_values = true, value_name = "KT|NAME=KT")]
    pub kt: Vec<String>,
    /// A time gap larger than this starts a new chunk [s] (default 0.1; `.mat`: gaps of the desired
    /// current stream > 1 s).
    #[arg(long, allow_negative_numbers = true)]
    pub gap_s: Option<f64>,
    /// Flip the sign of a role (sign conventions; repeatable), e.g. `--negate tau_f`.
    #[arg(long = "negate", value_name = "ROLE")]
    pub negate: Vec<String>,
    /// URDF for τ_ID of the current label (required by it: a robot log has no default robot).
    #[arg(long)]
    pub urdf: Option<String>,
    /// The joint's name in the URDF when it differs from the log's (single-joint view only).
    #[arg(long)]
    pub urdf_joint: Option<String>,
    /// Position of a URDF joint held fixed [rad] (repeatable); wins over the log's value. Joints
    /// neither logged nor given are held at 0 (warned).
    #[arg(
        long = "fixed-joint",
        value_name = "NAME=RAD",
        allow_hyphen_values = true
    )]
    pub fixed_joints: Vec<String>,
    /// The URDF frame whose orientation in the world the logged base orientation is (an IMU's
    /// frame, e.g. `waist_imu_0`; placed on the root link through the URDF at each sample's q).
    /// Default: the frame the log names — a .mat `orientations/<sensor>` channel's sensor, the
    /// `<frame>` of `frames/<root>/<frame>/orientation`, an MCAP Imu's `header.frame_id` — or the
    /// root link when it names none (a CSV's `--base-quat`).
    #[arg(long, value_name = "FRAME")]
    pub base_frame: Option<String>,
    /// Resampling, filter, smoother and sample-limit settings.
    #[command(flatten)]
    #[serde(flatten)]
    pub pipeline: PipelineArgs,
}

/// Arguments of `frictl import csv`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct CsvArgs {
    /// CSV logs; each becomes one run.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Joint name, the dataset's and the URDF's (repeatable: one dataset per joint; `{joint}` in a
    /// `--column` is replaced by each).
    #[arg(long, required_unless_present = "joints_all")]
    pub joint: Vec<String>,
    /// `ROLE=COLUMN` (repeatable). Roles: time, s, sdot, sddot, theta, omega, current, tau_joint,
    /// tau_motor, tau_f, temperature. A column may hold `{joint}` (e.g. `current=i_{joint}`).
    #[arg(long = "column", value_name = "ROLE=COLUMN", required = true)]
    pub columns: Vec<String>,
    /// `ROLE=UNIT` (repeatable; default SI): time s|ms|us, angles rad|deg, velocities
    /// rad/s|deg/s|rpm, accelerations rad/s^2|deg/s^2, current A|mA, torques Nm|mNm, temperature C.
    /// The s, sdot and sddot units also apply to `--positions`, `--velocities`, `--accelerations`.
    #[arg(long = "unit", value_name = "ROLE=UNIT")]
    pub units: Vec<String>,
    /// Positions of every URDF joint the log has, for the whole-body τ_ID: a column template with
    /// `{joint}` replaced by each URDF joint name (e.g. `q_{joint}`).
    #[arg(long, value_name = "TEMPLATE")]
    pub positions: Option<String>,
    /// Velocity column template (joints without one go through the Kalman smoother).
    #[arg(long, value_name = "TEMPLATE", requires = "positions")]
    pub velocities: Option<String>,
    /// Acceleration column template.
    #[arg(long, value_name = "TEMPLATE", requires = "positions")]
    pub accelerations: Option<String>,
    /// Columns `X,Y,Z,W` of the root link's orientation quaternion in the world (a robot on a
    /// tilted pole; default: the root link at the identity pose).
    #[arg(long, value_name = "X,Y,Z,W", requires = "positions")]
    pub base_quat: Option<String>,
    /// A measured wrench applied to the robot at a URDF frame, `FRAME=TEMPLATE` (repeatable): `{c}`
    /// in the column template is replaced by fx, fy, fz [N] and mx, my, mz [N·m], in the frame's
    /// coordinates about its origin (e.g. `--wrench l_foot=ft_l_foot_{c}`).
    #[arg(long = "wrench", value_name = "FRAME=TEMPLATE", requires = "positions")]
    pub wrenches: Vec<String>,
    /// Field delimiter (one character).
    #[arg(long, default_value = ",")]
    pub delimiter: char,
    /// Stream the log: read and label it in windows of this many grid samples (plus margins the
    /// smoother and filter settings need), appending each joint's rows as they come; the log is
    /// never held whole and the rows equal the whole-log import's.
    #[arg(long, value_name = "N", value_parser = crate::count::window_samples)]
    pub window_samples: Option<usize>,
    /// Options every format shares.
    #[command(flatten)]
    #[serde(flatten)]
    pub common: CommonArgs,
}

/// Arguments of `frictl import mcap`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct McapArgs {
    /// MCAP bags; each becomes one run.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Joint name, matched in every message (repeatable: one dataset per joint).
    #[arg(long, required_unless_present = "joints_all")]
    pub joint: Vec<String>,
    /// Topic of the sensor_msgs/msg/JointState messages.
    #[arg(long, default_value = "/joint_states")]
    pub topic: String,
    /// Role of the `effort` field: tau_joint (a joint torque sensor), tau_motor, tau_f, current, or
    /// none.
    #[arg(long, default_value = "tau_joint")]
    pub effort: String,
    /// Topic of sensor_msgs/msg/Imu messages whose `orientation` (a quaternion x, y, z, w in the
    /// world) is the root link's, for the whole-body state (a robot on a tilted pole; the base is
    /// taken at rest): each JointState message takes the last orientation before it in the bag.
    /// Default: the root link at the identity pose.
    #[arg(long, value_name = "TOPIC")]
    pub base_orientation: Option<String>,
    /// A measured wrench applied to the robot at a URDF frame, `FRAME=TOPIC` (repeatable): the
    /// topic's geometry_msgs/msg/WrenchStamped `force` [N] and `torque` [N·m], in the message's
    /// frame, which must be the URDF frame FRAME, about its origin; each JointState message takes
    /// the last wrench before it in the bag (e.g. `--wrench l_foot_rear_ft=/l_foot_rear_ft`).
    #[arg(long = "wrench", value_name = "FRAME=TOPIC")]
    pub wrenches: Vec<String>,
    /// Stream the bag: read and label it in windows of this many grid samples (see `import csv`).
    /// The first JointState message then decides which of position, velocity and effort are read;
    /// a later message that lacks one of them is an error.
    #[arg(long, value_name = "N", value_parser = crate::count::window_samples)]
    pub window_samples: Option<usize>,
    /// Options every format shares.
    #[command(flatten)]
    #[serde(flatten)]
    pub common: CommonArgs,
}

/// Arguments of `frictl import mat`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct MatArgs {
    /// YARP robot logger `.mat` files; each becomes one run.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Joint name in `elements_names` (repeatable; default: the one in the desired-current
    /// channel).
    #[arg(long)]
    pub joint: Vec<String>,
    /// The channel of the root link's orientation in the world (a robot on a tilted pole; the base
    /// is taken at rest), a path under `robot_logger_device` on the ticks of the joint positions:
    /// 3 elements roll, pitch, yaw [rad] with R = Rz(yaw)·Ry(pitch)·Rx(roll), as the logger writes
    /// an orientation sensor (`orientations/<imu>`, elements `r p y`, taken as the root link's own),
    /// or 4, the quaternion x, y, z, w of a logged frame (`frames/<root>/<frame>/orientation`,
    /// elements `qx qy qz qw`). Components are matched by those element names when present.
    /// Default: the root link at the identity pose.
    #[arg(long, value_name = "CHANNEL")]
    pub base_orientation: Option<String>,
    /// A measured wrench applied to the robot at a URDF frame, `FRAME=CHANNEL` (repeatable): a
    /// channel of 6 elements f_x f_y f_z [N], mu_x mu_y mu_z [N·m] in the frame's coordinates about
    /// its origin, on the ticks of the joint positions (e.g. `--wrench
    /// l_foot_rear_ft=FTs/l_foot_rear_ft`).
    #[arg(long = "wrench", value_name = "FRAME=CHANNEL")]
    pub wrenches: Vec<String>,
    /// Take the whole-body state's joint velocities and accelerations as logged
    /// (`joints_state/velocities`, `joints_state/accelerations`) instead of smoothing them from
    /// the positions (the default, as the authors do).
    #[arg(long)]
    pub logged_derivatives: bool,
    /// Stream the log: read and label it in windows of this many grid samples (see `import csv`).
    #[arg(long, value_name = "N", value_parser = crate::count::window_samples)]
    pub window_samples: Option<usize>,
    /// Options every format shares.
    #[command(flatten)]
    #[serde(flatten)]
    pub common: CommonArgs,
}

impl CommonArgs {
    /// The import's options.
    pub fn options(self) -> frictionless_import::CommonOptions {
        frictionless_import::CommonOptions {
            out: self.out,
            all_joints: self.joints_all.is_some(),
            label: self.label.map(LabelSource::from),
            gear_ratio: self.gear_ratio,
            kt: self.kt,
            gap_s: self.gap_s,
            negate: self.negate,
            urdf: self.urdf,
            urdf_joint: self.urdf_joint,
            fixed_joints: self.fixed_joints,
            base_frame: self.base_frame,
            settings: self.pipeline.label_settings(),
            gravity_m_s2: self.pipeline.gravity_m_s2,
        }
    }
}

impl CsvArgs {
    /// The import's options.
    pub fn options(self) -> frictionless_import::CsvOptions {
        frictionless_import::CsvOptions {
            files: self.files,
            joint: self.joint,
            columns: self.columns,
            units: self.units,
            positions: self.positions,
            velocities: self.velocities,
            accelerations: self.accelerations,
            base_quat: self.base_quat,
            wrenches: self.wrenches,
            delimiter: self.delimiter,
            window_samples: self.window_samples,
            common: self.common.options(),
        }
    }
}

impl McapArgs {
    /// The import's options.
    pub fn options(self) -> frictionless_import::McapOptions {
        frictionless_import::McapOptions {
            files: self.files,
            joint: self.joint,
            topic: self.topic,
            effort: self.effort,
            base_orientation: self.base_orientation,
            wrenches: self.wrenches,
            window_samples: self.window_samples,
            common: self.common.options(),
        }
    }
}

impl MatArgs {
    /// The import's options.
    pub fn options(self) -> frictionless_import::MatOptions {
        frictionless_import::MatOptions {
            files: self.files,
            joint: self.joint,
            base_orientation: self.base_orientation,
            wrenches: self.wrenches,
            logged_derivatives: self.logged_derivatives,
            window_samples: self.window_samples,
            common: self.common.options(),
        }
    }
}
