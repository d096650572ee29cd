//! Arguments of `frictl dynamics`.

use std::path::PathBuf;

/// Arguments of `frictl dynamics`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to compute.
    #[command(subcommand)]
    pub command: Sub,
}

/// The `frictl dynamics` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Sub {
    /// Inverse dynamics (RNEA) for each JSON line of a cases file.
    #[command(long_about = RNEA_HELP)]
    Rnea(RneaArgs),
    /// Print the model: joints (axis, limits, moved mass), frames count, total mass.
    Info(ModelArgs),
}

const RNEA_HELP: &str = "\
Inverse dynamics (RNEA) for each JSON line of a cases file; one JSON line out per case.

Input line (joints not named are 0; unknown joint or frame names are an error):
  {\"q\": {joint: rad}, \"qd\": {joint: rad/s}, \"qdd\": {joint: rad/s^2},
   \"base\": {\"pos\": [x,y,z], \"quat\": [x,y,z,w], \"vel\": [6], \"acc\": [6]},   (--floating-base only)
   \"wrenches\": {frame: [fx,fy,fz,mx,my,mz]}}                               (optional)
Output line:
  {\"tau\": {joint: Nm (N for prismatic)}, \"base_wrench\": [fx,fy,fz,mx,my,mz]}  (base_wrench when floating)

Conventions (Pinocchio's): gravity [0, 0, -9.80665] m/s^2 in the world frame; fixed base = root link welded
to the world at identity; tau = M(q) qdd + C(q, qd) qd + g(q) - J^T f_ext, no damping/friction/rotor inertia.
Floating base = free-flyer: base pose is the root-link origin position and orientation quaternion (x,y,z,w)
in the world; base vel = [v; w] body-fixed (root-link axes, linear first), acc its time derivative (Pinocchio's
a[0..6]); base_wrench = the free-flyer generalised force [f; n] in root-link axes about its origin. Each
external wrench acts ON the robot at the frame origin, in the frame's own axes; frames are link names and
joint names. Without --urdf the project's own 15-DoF leg+torso model (config/urdf/virtual_leg.urdf, built in)
is used.";

/// Model selection shared by the subcommands.
#[derive(clap::Args, Debug)]
pub struct ModelArgs {
    /// URDF file (default: the project's own leg, config/urdf/virtual_leg.urdf, built in).
    #[arg(long)]
    pub urdf: Option<PathBuf>,
    /// Reduced model: comma-separated joints that stay movable; all others are locked.
    #[arg(long, value_delimiter = ',')]
    pub keep: Option<Vec<String>>,
    /// Position of a locked joint, NAME=RAD (repeatable; locked joints not given are at 0).
    #[arg(long = "lock", value_name = "NAME=RAD")]
    pub lock: Vec<String>,
}

/// Arguments of `frictl dynamics rnea`.
#[derive(clap::Args, Debug)]
pub struct RneaArgs {
    /// The model.
    #[command(flatten)]
    pub model: ModelArgs,
    /// Treat the root link as a free-flyer (cases may give "base"; output has "base_wrench").
    #[arg(long)]
    pub floating_base: bool,
    /// JSON-lines cases file ("-" for stdin).
    #[arg(long)]
    pub cases: PathBuf,
    /// Output file (default: stdout).
    #[arg(long)]
    pub out: Option<PathBuf>,
}
