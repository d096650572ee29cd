//! `frictiond`: the real-time friction-compensation daemon (systemd notify service).
//!
//! What this binary **is**: the supervisor. It parses and validates the config and every model
//! file, builds the runtime parameters, starts the RT thread ([`rt`]), and then handles signals
//! (SIGTERM/SIGINT → zero currents, STOPPING=1, exit 0; SIGHUP → reload config and models off the RT
//! thread, hand them over lock-free, keep the running set if the new one is bad), systemd
//! notifications (READY, WATCHDOG gated on the RT heartbeat, STATUS, RELOADING + MONOTONIC_USEC) and
//! freeing of replaced parameter sets. `frictiond --config FILE --check` validates without IPC.
//!
//! Environment: `FRICTIOND_ALLOC_REPORT=FILE` counts RT-thread allocations after READY and writes
//! them at exit; `FRICTIOND_LATENCY_REPORT=FILE` writes the loop statistics at exit (wake lateness
//! p50/p99/p99.9/max at 1 µs resolution, compute time, input age — `benches/lateness.sh`).
//!
//! What it is **not**: the control law (`frictionless::law`), the tick (`frictiond::rt`), or the
//! config schema (`frictiond::config`) — those live in the library.

use frictiond::{alloc_count, config, params, rt, sdnotify};

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Parser;
use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

#[global_allocator]
static GLOBAL: alloc_count::CountingAlloc = alloc_count::CountingAlloc;

/// Command line.
#[derive(Debug, Parser)]
#[command(
    name = "frictiond",
    version,
    about = "1 kHz friction-compensation daemon"
)]
struct Cli {
    /// Configuration file (TOML).
    #[arg(long, short)]
    config: PathBuf,
    /// Validate the config and every model file, print a per-joint summary, exit.
    #[arg(long)]
    check: bool,
}

fn init_logging() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let tty = std::io::stderr().is_terminal();
    let b = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(tty);
    if tty {
        b.init();
    } else {
        // journald adds its own timestamps.
        b.without_time().init();
    }
}

fn summary(cfg: &config::Config) -> String {
    use std::fmt::Write;
    let l = &cfg.raw.loop_;
    let mut s = format!(
        "{}: OK\n  loop: period {} µs ({:.0} Hz), cpu {:?}, priority {:?}, lock_memory {}, cpu_dma_latency_us {:?}\n  backend: {:?} prefix {:?} root {:?}\n  safety: stale after {} ticks → {:?}\n",
        cfg.file.display(),
        l.period_us,
        1e6 / l.period_us as f64,
        l.cpu,
        l.priority,
        l.lock_memory,
        l.cpu_dma_latency_us,
        cfg.raw.backend.kind,
        cfg.raw.backend.service_prefix,
        cfg.root_path,
        cfg.raw.safety.stale_after_ticks,
        cfg.raw.safety.on_stale,
    );
    for (j, m) in cfg.raw.joint.iter().zip(&cfg.models) {
        let model = match m {
            config::ModelSpec::None => "none".to_owned(),
            config::ModelSpec::Cv(p) => format!("cv kc={} ka={} kv={}", p.kc, p.ka, p.kv),
            config::ModelSpec::Scv(p) => format!(
                "scv kc={} ka={} kv={} ks={} vs={} alpha={}",
                p.kc, p.ka, p.kv, p.ks, p.vs, p.alpha
            ),
            config::ModelSpec::Pinn {
                path,
                warmup,
                fallback,
            } => {
                let ood = match fallback {
                    Some(config::StaticFallback::Cv(_)) => "cv",
                    Some(config::StaticFallback::Scv(_)) => "scv",
                    None => "none",
                };
                format!(
                    "pinn {} (warmup {warmup:?}; out of range: {:?}, margin {}, static {ood})",
                    path.display(),
                    j.ood,
                    j.ood_margin
                )
            }
        };
        let _ = writeln!(
            s,
            "  joint[{}] {:<16} r={:<8} kt={:<8} kfc={:<5} kp={} ki={} max_curr={} A max_output_friction={} Nm gate={} rad/s lpf={} | {}",
            j.index,
            j.name,
            j.gear_ratio,
            j.kt,
            j.kfc,
            j.kp,
            j.ki,
            j.max_curr,
            j.max_output_friction,
            j.joint_velocity_threshold_rad_s,
            j.lpf
                .map(|f| format!("order {} @ {} Hz", f.order, f.cutoff_hz))
                .unwrap_or_else(|| "off".into()),
            model
        );
    }
    s.push_str(&config::bus_summary(cfg));
    s
}

fn main() -> std::process::ExitCode {
    init_logging();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // One line, on stderr (the journal under systemd), whatever RUST_LOG filters.
            eprintln!("frictiond: error: {}", frictionless::error_line(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let cfg = config::load(&cli.config)?;
    if cli.check {
        // Also build the runtime parameters (filters, models) so --check catches everything.
        params::build(&cfg, 0)?;
        print!("{}", summary(&cfg));
        return Ok(());
    }
    let params = params::build(&cfg, 0)?;
    tracing::info!(
        "config {} validated: {} joint(s), period {} µs",
        cfg.file.display(),
        cfg.raw.joint.len(),
        cfg.raw.loop_.period_us
    );

    // Signals first, before any thread exists; iceoryx2 nodes run with signal handling disabled.
    let mut signals = signal_hook::iterator::Signals::new([SIGTERM, SIGINT, SIGHUP])
        .context("installing signal handlers")?;
    let alloc_report = std::env::var_os("FRICTIOND_ALLOC_REPORT").map(PathBuf::from);
    // Loop statistics at exit (`key=value` lines, see `rt::RtSummary::report`), for benches.
    let latency_report = std::env::var_os("FRICTIOND_LATENCY_REPORT").map(PathBuf::from);
    let rt = start_rt(&cfg, params, alloc_report.is_some())?;
    let mut cfg = cfg;
    let stop_reason = supervise(&mut cfg, &cli.config, &mut signals, &rt)?;
    shut_down(rt, stop_reason, alloc_report, latency_report)
}

/// The running RT thread and the supervisor's ends of its channels and shared atomics.
struct Rt {
    thread: std::thread::JoinHandle<Option<rt::RtSummary>>,
    /// Replaced parameter sets coming back to be freed off the RT thread.
    rx_old: std::sync::mpsc::Receiver<Box<params::Params>>,
    /// New parameter sets from reloads.
    tx_params: std::sync::mpsc::SyncSender<Box<params::Params>>,
    shared: Arc<rt::Shared>,
}

/// Spawns the RT thread and waits (up to 30 s) until it reports its set-up result.
fn start_rt(
    cfg: &config::Config,
    params: Box<params::Params>,
    count_allocs: bool,
) -> anyhow::Result<Rt> {
    let shared = Arc::new(rt::Shared::default());
    let (tx_params, rx_params) = std::sync::mpsc::sync_channel(1);
    let (tx_old, rx_old) = std::sync::mpsc::sync_channel(4);
    let (tx_started, rx_started) = std::sync::mpsc::sync_channel(1);
    let setup = rt::RtSetup {
        config: cfg.clone(),
        params,
        rx_params,
        tx_old,
        shared: shared.clone(),
        started: tx_started,
        count_allocs,
    };
    let rt_thread = std::thread::Builder::new()
        .name("frictiond-rt".into())
        .stack_size(2 << 20)
        .spawn(move || rt::run(setup))
        .context("spawning the RT thread")?;
    let granted = match rx_started.recv_timeout(Duration::from_secs(30)) {
        Ok(Ok(f)) => f,
        Ok(Err(e)) => {
            let _ = rt_thread.join();
            bail!("RT thread set-up failed: {e}");
        }
        Err(_) => bail!("RT thread did not start within 30 s"),
    };
    tracing::info!(
        "RT thread up: SCHED_FIFO {}, memory locked {}, CPU pinned {}",
        granted & frictionless_shm_types::STATUS_SCHED_FIFO != 0,
        granted & frictionless_shm_types::STATUS_MEMORY_LOCKED != 0,
        granted & frictionless_shm_types::STATUS_CPU_PINNED != 0,
    );
    Ok(Rt {
        thread: rt_thread,
        rx_old,
        tx_params,
        shared,
    })
}

/// The supervisor loop (every 5 ms) until SIGTERM or SIGINT: handles SIGHUP reloads, frees
/// replaced parameter sets, sends READY once the RT loop has run `ready_after_ticks`, pets the
/// watchdog only while the heartbeat advances, and sends STATUS every second. Returns the signal
/// that stopped it.
fn supervise(
    cfg: &mut config::Config,
    config_path: &std::path::Path,
    signals: &mut signal_hook::iterator::Signals,
    rt: &Rt,
) -> anyhow::Result<i32> {
    let shared = &rt.shared;
    let ready_after = cfg.raw.loop_.ready_after_ticks;
    let wd = sdnotify::watchdog_interval();
    let mut ready = false;
    let mut last_wd = Instant::now();
    let mut last_wd_beat = 0u64;
    let mut last_status = Instant::now();
    let mut generation = 0u64;
    let mut last_beat = 0u64;
    let mut last_beat_change = Instant::now();
    let mut stop_reason = None;
    while stop_reason.is_none() {
        for sig in signals.pending() {
            match sig {
                SIGTERM | SIGINT => stop_reason = Some(sig),
                SIGHUP => reload(cfg, config_path, &rt.tx_params, &mut generation),
                _ => {}
            }
        }
        while let Ok(old) = rt.rx_old.try_recv() {
            tracing::debug!("freeing parameter generation {}", old.generation);
            drop(old);
        }
        if rt.thread.is_finished() {
            bail!("RT thread ended unexpectedly");
        }
        let beat = shared.heartbeat.load(Ordering::Relaxed);
        if beat != last_beat {
            last_beat = beat;
            last_beat_change = Instant::now();
        }
        if !ready && beat >= ready_after {
            ready = true;
            sdnotify::notify_logged("READY=1\nSTATUS=running");
            tracing::info!(
                "ready after {beat} ticks ({} missed)",
                shared.missed.load(Ordering::Relaxed)
            );
        }
        if let Some(wd) = wd
            && ready
            && last_wd.elapsed() >= wd / 2
        {
            // Only pet the watchdog while the RT loop advances: a stuck loop gets restarted.
            if beat != last_wd_beat {
                sdnotify::notify_logged("WATCHDOG=1");
                last_wd_beat = beat;
            } else {
                tracing::error!("RT heartbeat stalled at tick {beat}: withholding WATCHDOG=1");
            }
            last_wd = Instant::now();
        }
        if ready && last_status.elapsed() >= Duration::from_secs(1) {
            last_status = Instant::now();
            notify_status(shared, beat);
        }
        if last_beat_change.elapsed() > Duration::from_secs(5) {
            tracing::warn!("RT heartbeat has not advanced for 5 s (tick {beat})");
            last_beat_change = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(stop_reason.unwrap_or(0))
}

/// Sends the periodic `STATUS=` line: ticks, wake lateness, missed ticks, parameter generation.
fn notify_status(shared: &rt::Shared, beat: u64) {
    let p99 = shared.lateness_p99_ns.load(Ordering::Relaxed);
    let max = shared.lateness_max_ns.load(Ordering::Relaxed);
    let missed = shared.missed.load(Ordering::Relaxed);
    sdnotify::notify_logged(&format!(
        "STATUS=ticks {beat}, lateness p99 <= {} us, max {} us, missed {missed}, generation {}",
        p99 / 1000,
        max / 1000,
        shared.generation.load(Ordering::Relaxed)
    ));
}

/// Stops after `stop_reason`: STOPPING=1, a second SIGTERM/SIGINT exits at once, the RT thread
/// publishes zero currents and ends, then the exit reports are written.
fn shut_down(
    rt: Rt,
    stop_reason: i32,
    alloc_report: Option<PathBuf>,
    latency_report: Option<PathBuf>,
) -> anyhow::Result<()> {
    let Rt {
        thread: rt_thread,
        rx_old,
        // Held (not dropped) until the end, as while supervising.
        tx_params: _tx_params,
        shared,
    } = rt;
    tracing::info!(
        "signal {} received: publishing zero currents and stopping",
        stop_reason
    );
    sdnotify::notify_logged("STOPPING=1");
    // A second SIGTERM/SIGINT while stopping exits at once with status 1.
    for s in [SIGTERM, SIGINT] {
        let _ = signal_hook::flag::register_conditional_shutdown(
            s,
            1,
            Arc::new(std::sync::atomic::AtomicBool::new(true)),
        );
    }
    shared.stop.store(true, Ordering::Relaxed);
    let summary = match rt_thread.join() {
        Ok(s) => s,
        Err(_) => bail!("RT thread panicked"),
    };
    while rx_old.try_recv().is_ok() {}
    if let Some(path) = alloc_report {
        let (counted, exempt) = alloc_count::totals();
        let ticks = shared.counted_ticks.load(Ordering::Relaxed);
        let text = format!(
            "rt_allocations={counted}\nrt_exempt_allocations={exempt}\nrt_counted_ticks={ticks}\n"
        );
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    if let (Some(path), Some(summary)) = (latency_report, &summary) {
        std::fs::write(&path, summary.report())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    tracing::info!(
        "stopped cleanly: {} ticks, {} missed, wake lateness p99 <= {} us, max {:.1} us",
        shared.heartbeat.load(Ordering::Relaxed),
        shared.missed.load(Ordering::Relaxed),
        shared.lateness_p99_ns.load(Ordering::Relaxed) / 1000,
        shared.lateness_max_ns.load(Ordering::Relaxed) as f64 / 1e3
    );
    Ok(())
}

/// SIGHUP: reload config and models off the RT thread; on success hand the new parameters over,
/// on failure keep the running ones and log why.
fn reload(
    cfg: &mut config::Config,
    path: &std::path::Path,
    tx: &std::sync::mpsc::SyncSender<Box<params::Params>>,
    generation: &mut u64,
) {
    sdnotify::notify_logged(&format!(
        "RELOADING=1\nMONOTONIC_USEC={}\nSTATUS=reloading",
        sdnotify::monotonic_usec()
    ));
    let result = config::load(path)
        .map_err(|e| e.to_string())
        .and_then(|new| {
            if new.raw.loop_ != cfg.raw.loop_
                || new.raw.backend != cfg.raw.backend
                || new.root_path != cfg.root_path
            {
                tracing::warn!(
                    "[loop] and [backend] changes need a restart; applying joints and safety only"
                );
            }
            let p = params::build(&new, *generation + 1).map_err(|e| e.to_string())?;
            Ok((new, p))
        });
    match result {
        Ok((new, p)) => match tx.try_send(p) {
            Ok(()) => {
                *generation += 1;
                tracing::info!("reloaded {}: generation {}", path.display(), generation);
                *cfg = new;
            }
            Err(_) => tracing::error!("reload skipped: the previous hand-over is still pending"),
        },
        Err(e) => tracing::error!("reload rejected, keeping generation {generation}: {e}"),
    }
    sdnotify::notify_logged("READY=1\nSTATUS=running");
}
