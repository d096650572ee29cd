//! `frictl record` — records the daemon's I/O streams to a CSV file.
//!
//! What it **is**: subscribes to `<prefix>/joint_states`, `<prefix>/torque_request` and
//! `<prefix>/motor_current_command` and writes one CSV row per received motor-current command, with
//! the newest joint state and torque request at that moment: host time, the command's `seq`,
//! `stamp_ns`, `state_stamp_ns`, and per joint `s_rad, sdot_rad_s, theta_motor_rad,
//! omega_motor_rad_s, current_a, tau_meas_nm, tau_des_nm, enabled, i_ref_a, flags`. Stops after
//! `--duration-s` or `--max-rows`, or on Ctrl-C/SIGTERM.
//!
//! What it is **not**: lossless at 1 kHz under load (latest-value services with buffer 1: a slow
//! recorder skips samples; `seq` gaps show where).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use frictionless_shm_types::{
    Ipc, IpcConfig, JointStates, MAX_JOINTS, MotorCurrentCommand, TorqueRequest,
};

pub use frictl_cli::record::*;

/// CSV header for `n` joints.
pub fn header(n: usize) -> Vec<String> {
    let mut h = vec![
        "host_ns".to_string(),
        "cmd_seq".into(),
        "cmd_stamp_ns".into(),
        "state_stamp_ns".into(),
        "state_seq".into(),
    ];
    for k in 0..n {
        for f in [
            "s_rad",
            "sdot_rad_s",
            "theta_motor_rad",
            "omega_motor_rad_s",
            "current_a",
            "tau_meas_nm",
            "tau_des_nm",
            "enabled",
            "i_ref_a",
            "flags",
        ] {
            h.push(format!("j{k}_{f}"));
        }
    }
    h
}

/// One CSV row.
pub fn row(
    n: usize,
    host_ns: u64,
    c: &MotorCurrentCommand,
    s: &JointStates,
    r: &TorqueRequest,
) -> Vec<String> {
    let mut v = vec![
        host_ns.to_string(),
        c.seq.to_string(),
        c.stamp_ns.to_string(),
        c.state_stamp_ns.to_string(),
        c.state_seq.to_string(),
    ];
    for k in 0..n {
        v.extend([
            s.s_rad[k].to_string(),
            s.sdot_rad_s[k].to_string(),
            s.theta_motor_rad[k].to_string(),
            s.omega_motor_rad_s[k].to_string(),
            s.current_a[k].to_string(),
            s.tau_meas_nm[k].to_string(),
            r.tau_des_nm[k].to_string(),
            u8::from(r.is_enabled(k)).to_string(),
            c.i_ref_a[k].to_string(),
            c.flags[k].to_string(),
        ]);
    }
    v
}

/// Runs `frictl record`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.joints == 0 || args.joints > MAX_JOINTS {
        anyhow::bail!("--joints {} must be 1..={MAX_JOINTS}", args.joints);
    }
    install_stop_handlers()?;
    let cfg = IpcConfig::new(args.root_path.as_deref(), &args.prefix);
    let ipc = Ipc::open(&cfg, "frictl_record").context("opening iceoryx2")?;
    let states = ipc.joint_states()?.inbox()?;
    let request = ipc.torque_request()?.inbox()?;
    let cmds = ipc.motor_current_command()?.inbox()?;
    let mut w = csv::Writer::from_writer(
        frictionless::output_file::AtomicFile::create(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?,
    );
    w.write_record(header(args.joints))?;
    let mut s = JointStates::zeroed();
    let mut r = TorqueRequest::zeroed();
    let t0 = Instant::now();
    let mut rows = 0u64;
    while !STOP.load(Ordering::Relaxed) {
        if args.duration_s > 0.0 && t0.elapsed().as_secs_f64() >= args.duration_s {
            break;
        }
        if args.max_rows > 0 && rows >= args.max_rows {
            break;
        }
        let _ = cmds.wait(Duration::from_millis(50));
        if let Some(x) = states.latest().map_err(|e| anyhow::anyhow!("{e}"))? {
            s = x;
        }
        if let Some(x) = request.latest().map_err(|e| anyhow::anyhow!("{e}"))? {
            r = x;
        }
        if let Some(c) = cmds.latest().map_err(|e| anyhow::anyhow!("{e}"))? {
            w.write_record(row(
                args.joints,
                frictionless_shm_types::monotonic_ns(),
                &c,
                &s,
                &r,
            ))?;
            rows += 1;
        }
    }
    w.into_inner()
        .map_err(|e| anyhow::anyhow!("cannot flush {}: {}", args.out.display(), e.error()))?
        .commit()
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!("frictl record: {rows} rows → {}", args.out.display());
    Ok(())
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_stop_signal(_sig: libc::c_int) {
    // Async-signal-safe: one atomic store.
    STOP.store(true, Ordering::Relaxed);
}

/// SIGINT/SIGTERM end the recording cleanly (the CSV is flushed). Plain `sigaction` with an
/// atomic flag: the tools crate has no signal-hook dependency.
fn install_stop_handlers() -> anyhow::Result<()> {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: a zeroed sigaction with a valid handler address and an empty mask.
        let rc = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_stop_signal as extern "C" fn(libc::c_int) as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            libc::sigaction(sig, &sa, std::ptr::null_mut())
        };
        if rc != 0 {
            anyhow::bail!(
                "installing handler for signal {sig}: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_and_row_have_the_same_width_and_order() {
        let mut c = MotorCurrentCommand::zeroed();
        c.seq = 9;
        c.i_ref_a[1] = -1.5;
        let mut s = JointStates::zeroed();
        s.sdot_rad_s[1] = 0.25;
        let mut r = TorqueRequest::zeroed();
        r.enable_mask = 0b10;
        r.tau_des_nm[1] = 3.0;
        let h = header(2);
        let v = row(2, 1, &c, &s, &r);
        assert_eq!(h.len(), v.len());
        let col = |name: &str| h.iter().position(|x| x == name).unwrap();
        assert_eq!(v[col("cmd_seq")], "9");
        assert_eq!(v[col("j1_sdot_rad_s")], "0.25");
        assert_eq!(v[col("j1_tau_des_nm")], "3");
        assert_eq!(v[col("j1_enabled")], "1");
        assert_eq!(v[col("j0_enabled")], "0");
        assert_eq!(v[col("j1_i_ref_a")], "-1.5");
    }
}
