//! `frictl sim` — the virtual harmonic-drive joints.
//!
//! `frictl sim run`: an offline open-loop run of a preset with a current profile, logged as CSV (the
//! same columns as `frictl acquire`, truth included). `frictl sim params`: print the merged parameters.
//! `frictl sim serve`: the joints as a plant process — over iceoryx2 (`--backend shm`, real time or
//! lockstep, [`frictionless_plant::shm`]) or as motor drives on SocketCAN (`--backend can`,
//! [`frictionless_plant::can`]).

use std::io::IsTerminal;

use anyhow::Context;
use frictionless_acquire::log::CsvLog;
use frictionless_acquire::protocol::{LogRow, Mode};
use frictionless_sim::params::{check_set_joints, load_table};
use frictionless_sim::profile::CurrentProfile;
use frictionless_sim::{Plant, PlantParams};

pub use frictl_cli::sim::*;

/// Runs `frictl sim`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        SimCommand::Params { params } => {
            check_set_joints(&params.sets, &[params.preset.as_str()])?;
            let table = load_table(&params.preset, params.params.as_deref(), &params.sets)?;
            // Validate before printing, so a bad override fails here too.
            PlantParams::from_table(&table)?;
            frictionless_acquire::ProtocolConfig::from_table(&table)?;
            print!("{}", toml::to_string_pretty(&table)?);
            Ok(())
        }
        SimCommand::Serve(a) => serve(*a),
        SimCommand::Run {
            params,
            current_profile,
            duration_s,
            tau_ext_nm,
            seed,
            out,
        } => {
            anyhow::ensure!(
                duration_s.is_finite() && duration_s > 0.0,
                "--duration-s must be a positive number, got {duration_s}"
            );
            anyhow::ensure!(tau_ext_nm.is_finite(), "--tau-ext-nm must be finite");
            check_set_joints(&params.sets, &[params.preset.as_str()])?;
            let table = load_table(&params.preset, params.params.as_deref(), &params.sets)?;
            let p = PlantParams::from_table(&table)?;
            let period_s = p.sample_period_s();
            let profile = CurrentProfile::parse(&current_profile, period_s)?;
            let mut plant = Plant::from_params(p, seed)?;
            let file = frictionless::output_file::AtomicFile::create(&out)
                .with_context(|| format!("cannot create {}", out.display()))?;
            let mut log = CsvLog::new(file, true)?;
            let n = (duration_s / period_s).round() as u64;
            let bar = if std::io::stderr().is_terminal() {
                indicatif::ProgressBar::new(n)
            } else {
                indicatif::ProgressBar::hidden()
            };
            for k in 0..n {
                let meas = plant.measurement();
                let i_ref = profile.current_a(meas.time_s);
                log.write(&LogRow {
                    chunk: 0,
                    active: true,
                    mode: Mode::Current,
                    meas,
                    i_ref_a: i_ref,
                    truth: Some(plant.truth()),
                })?;
                plant.step(i_ref, tau_ext_nm);
                if k % 10_000 == 0 {
                    bar.set_position(k);
                }
            }
            bar.finish_and_clear();
            log.finish()?
                .commit()
                .with_context(|| format!("cannot write {}", out.display()))?;
            eprintln!("frictl sim run: {n} samples -> {}", out.display());
            Ok(())
        }
    }
}

/// `frictl sim serve`.
fn serve(a: ServeArgs) -> anyhow::Result<()> {
    // A pose is joint angles: finite and within three turns (a value in degrees or a typo is
    // refused before anything starts; before, 100 rad was accepted).
    if let Some((k, q)) = a.initial_pose_rad.iter().enumerate().find(|(_, q)| {
        !(q.is_finite() && q.abs() <= frictionless_import::urdf::MAX_FIXED_JOINT_RAD)
    }) {
        anyhow::bail!(
            "--initial-pose-rad entry {}: {q} rad is outside ±{:.2} rad (three turns); the pose \
             is in rad",
            k + 1,
            frictionless_import::urdf::MAX_FIXED_JOINT_RAD
        );
    }
    let stop = frictionless_plant::install_stop_flag()?;
    let mut robot =
        frictionless_plant::build_robot(&a.preset, a.params.as_deref(), &a.sets, a.seed)?;
    match a.backend {
        Backend::Shm => {
            // The reported velocity uses each preset's protocol.velocity_filter_hz, like acquire
            // (the leg's joints: the presets' common default).
            let mut velocity_filter_hz = Vec::with_capacity(robot.len());
            for k in 0..robot.len() {
                velocity_filter_hz.push(if robot.is_leg() {
                    frictionless_plant::shm::DEFAULT_VELOCITY_FILTER_HZ
                } else {
                    let table = load_table(robot.name(k), a.params.as_deref(), &a.sets)?;
                    frictionless_acquire::ProtocolConfig::from_table(&table)?.velocity_filter_hz
                });
            }
            let opts = frictionless_plant::shm::ShmServeOptions {
                ipc: frictionless_shm_types::IpcConfig::new(a.root_path.as_deref(), &a.prefix),
                lockstep: a.lockstep,
                lockstep_timeout_ms: a.lockstep_timeout_ms,
                lockstep_min_subscribers: a.lockstep_subscribers,
                command_timeout_ms: a.command_timeout_ms,
                duration_s: a.duration_s,
                initial_pose_rad: a.initial_pose_rad,
                velocity_filter_hz,
            };
            frictionless_plant::shm::run(&mut robot, &opts, stop)?;
            Ok(())
        }
        Backend::Can => {
            anyhow::ensure!(
                !a.lockstep,
                "--lockstep is a shared-memory mode; --backend can runs in real time"
            );
            if !a.initial_pose_rad.is_empty() {
                robot.reset_at_rest(&a.initial_pose_rad)?;
            }
            serve_can(&mut robot, &a, stop)
        }
    }
}

/// `frictl sim serve --backend can`: [`frictionless_plant::can::run`].
fn serve_can(
    robot: &mut frictionless_plant::ServedRobot,
    a: &ServeArgs,
    stop: &std::sync::atomic::AtomicBool,
) -> anyhow::Result<()> {
    let opts = frictionless_plant::can::CanServeOptions {
        bus: a.bus.clone(),
        protocol: a.protocol,
        node_ids: a.node_ids.clone(),
        command_timeout_ms: a.command_timeout_ms,
        duration_s: a.duration_s,
    };
    Ok(frictionless_plant::can::run(robot, &opts, stop)?)
}
