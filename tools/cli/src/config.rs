//! Arguments of `frictl config`.

use std::path::PathBuf;

use super::train::MotorEncoder;

/// What a PINN joint does while its inputs are outside the model's training range (frictiond's
/// `[[joint]] ood`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Ood {
    /// Blend to the static model of `--fit` (the default with `--fit`).
    Static,
    /// Flag and count only: the network's estimate is used (the default without `--fit`).
    Flag,
    /// Not checked.
    Off,
}

/// Arguments of `frictl config`: one frictiond `[[joint]]` for a fitted static model or a PINN,
/// written as a complete shared-memory config that frictiond's own checker accepts.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Joint name (the URDF name; a PINN's default: the name its model carries).
    #[arg(long)]
    pub joint: Option<String>,
    /// Index of the joint in the payload arrays.
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// Signed gear ratio r (a PINN's default: its model's).
    #[arg(long, allow_hyphen_values = true)]
    pub gear_ratio: Option<f64>,
    /// Torque constant k_t [Nm/A] (a PINN's default: its model's).
    #[arg(long)]
    pub kt: Option<f64>,
    /// Current clamp ±max_curr [A].
    #[arg(long)]
    pub max_curr: f64,
    /// Friction compensation gain.
    #[arg(long, default_value_t = 1.0)]
    pub kfc: f64,
    /// Friction clip [Nm] (none when absent).
    #[arg(long)]
    pub max_output_friction: Option<f64>,
    /// A fit of `frictl fit … --json`: the joint's model without --pinn, else its static fallback
    /// (CV or SCV).
    #[arg(long, value_name = "FIT.json")]
    pub fit: Option<PathBuf>,
    /// A PINN (`.fwt`): the joint's model.
    #[arg(long, value_name = "MODEL.fwt")]
    pub pinn: Option<PathBuf>,
    /// The PINN's training report (`frictl train`): the Δθ offset an absolute encoder is configured
    /// with, and the latch an incremental one needs.
    #[arg(long, value_name = "REPORT.json")]
    pub train_report: Option<PathBuf>,
    /// The motor encoder's kind: `absolute` (the report's Δθ offset is configured) or `incremental`
    /// (no offset: Δθ latched at every enable; the model must be trained latched per chunk).
    #[arg(long, value_enum, default_value_t = MotorEncoder::Absolute)]
    pub motor_encoder: MotorEncoder,
    /// Out-of-range handling of a PINN joint (default: `static` with --fit, else `flag`).
    #[arg(long, value_enum)]
    pub ood: Option<Ood>,
    /// The frictiond config to write (TOML).
    #[arg(long, short = 'o')]
    pub out: PathBuf,
}
