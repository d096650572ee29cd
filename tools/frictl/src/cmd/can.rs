//! `frictl can`: record and replay `candump -L` logs on SocketCAN interfaces.
//!
//! `frictl can record IFACE FILE [--count N] [--seconds S]` (stops on SIGINT/SIGTERM too, flushing the
//! file) and `frictl can replay FILE [--iface IFACE] [--loop] [--speed X]`. The format and pacing
//! live in [`frictionless_canlog`]. Not a bus analyser: no decoding, no filters.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use frictionless_canlog as canlog;

pub use frictl_cli::can::*;

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// Runs `frictl can`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.action {
        Action::Record {
            iface,
            file,
            count,
            seconds,
        } => {
            let duration = match seconds {
                Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
                Some(s) => anyhow::bail!("--seconds {s}: must be finite and > 0"),
                None => None,
            };
            // SAFETY: the handler only stores to an atomic (async-signal-safe).
            unsafe {
                let h = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
                libc::signal(libc::SIGINT, h);
                libc::signal(libc::SIGTERM, h);
            }
            let mut w = frictionless::output_file::AtomicFile::create(&file)
                .with_context(|| format!("creating {}", file.display()))?;
            let n = canlog::record(&iface, &mut w, count, duration, &|| {
                STOP.load(Ordering::Relaxed)
            })?;
            w.commit()
                .with_context(|| format!("cannot write {}", file.display()))?;
            eprintln!("recorded {n} frames from {iface} to {}", file.display());
            Ok(())
        }
        Action::Replay {
            file,
            iface,
            repeat,
            speed,
        } => {
            anyhow::ensure!(
                speed.is_finite() && speed > 0.0,
                "--speed {speed}: must be finite and > 0"
            );
            let entries = canlog::read_log(&file)?;
            let n = canlog::replay_to_iface(
                &entries,
                iface.as_deref(),
                speed,
                if repeat { 0 } else { 1 },
            )?;
            eprintln!("replayed {n} frames from {}", file.display());
            Ok(())
        }
    }
}
