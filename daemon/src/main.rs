//! `frictiond`: the real-time friction-compensation daemon (systemd notify service).
//!
//! What this binary **is**: the supervisor. It parses and validates the config and every model
//! file, builds the runtime parameters, starts the RT thread ([`rt`]), and then handles signals
//! (SIGTERM/SIGINT → zero currents, STOPPING=1, exit 0; SIGHUP → reload config and models on a
//! worker thread ([`ReloadWorker`]) bounded by [`RELOAD_BOUND`], hand them over lock-free, keep the running set if the
//! new one is bad; the signal loop never reads a file), systemd
//! notifications (READY, WATCHDOG gated on the RT heartbeat, STATUS, RELOADING + MONOTONIC_USEC) and
//! freeing of replaced parameter sets, and logs stale input once on entry and once on recovery
//! (rate-limited, [`StaleLog`]), and answers runtime control requests on `<prefix>/control`
//! ([`frictiond::control`]: checked here, applied by the RT thread at its next tick boundary). One
//! daemon per service prefix ([`instance::InstanceLock`]).
//! `frictiond --config FILE --check` validates without IPC.
//!
//! Environment: `FRICTIOND_ALLOC_REPORT=FILE` counts RT-thread allocations after READY and writes
//! them at exit; `FRICTIOND_LATENCY_REPORT=FILE` writes the loop statistics at exit (wake lateness
//! p50/p99/p99.9/max at 1 µs resolution, compute time, input age — `benches/lateness.sh`).
//!
//! What it is **not**: the control law (`frictionless::law`), the tick (`frictiond::rt`), or the
//! config schema (`frictiond::config`) — those live in the library.

use frictiond::{alloc_count, config, instance, params, rt, sdnotify};

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

/// `FRICTIONLESS_GENERATE_ASSETS=DIR frictiond` writes `DIR/man/frictiond.1` and the bash, zsh and
/// fish completions in `DIR/{bash,zsh,fish}/` from [`Cli`] and exits: the Debian package's build runs it
/// (packaging/deb.sh). An environment variable, not an option, so that the pages and completions
/// describe only the real command line.
fn generate_assets(dir: &std::path::Path) -> anyhow::Result<()> {
    use clap::CommandFactory;
    use clap_complete::Shell;
    let cmd = Cli::command();
    let man = dir.join("man");
    std::fs::create_dir_all(&man).with_context(|| format!("creating {}", man.display()))?;
    clap_mangen::generate_to(cmd.clone(), &man)
        .with_context(|| format!("writing man pages to {}", man.display()))?;
    for (shell, sub) in [
        (Shell::Bash, "bash"),
        (Shell::Zsh, "zsh"),
        (Shell::Fish, "fish"),
    ] {
        let out = dir.join(sub);
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        clap_complete::generate_to(shell, &mut cmd.clone(), "frictiond", &out)
            .with_context(|| format!("writing {shell} completions to {}", out.display()))?;
    }
    Ok(())
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
        "{}: OK\n  loop: period {} µs ({:.0} Hz), cpu {:?}, priority {:?}, lock_memory {}, cpu_dma_latency_us {:?}, rt_threads {} (helper_cpu {:?}), prefetch {:?}\n  backend: {:?} prefix {:?} root {:?}\n  safety: stale after {} ticks → {:?}\n",
        cfg.file.display(),
        l.period_us,
        1e6 / l.period_us as f64,
        l.cpu,
        l.priority,
        l.lock_memory,
        l.cpu_dma_latency_us,
        l.rt_threads,
        l.helper_cpu,
        l.prefetch,
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
            config::ModelSpec::Lugre(p) => format!(
                "lugre kc={} kv={} ks={} vs={} alpha={} sigma0={} sigma1={}",
                p.kc, p.kv, p.ks, p.vs, p.alpha, p.sigma0, p.sigma1
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
    let result = match std::env::var_os("FRICTIONLESS_GENERATE_ASSETS") {
        Some(dir) => generate_assets(std::path::Path::new(&dir)),
        None => {
            init_logging();
            run(Cli::parse())
        }
    };
    match result {
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
    // Before any port exists: a second daemon on this prefix would command the same motors.
    let _instance = instance::InstanceLock::acquire(&cfg)?;
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
    let stop_reason = supervise(cfg, &cli.config, &mut signals, &rt)?;
    shut_down(rt, stop_reason, alloc_report, latency_report)
}

/// Opens `<prefix>/control` on a node of the supervisor's own (the RT thread's ports are its own).
fn open_control(
    cfg: &config::Config,
) -> anyhow::Result<(
    frictionless_shm_types::Ipc,
    frictionless_shm_types::control::ControlServer,
)> {
    let ipc_cfg = frictionless_shm_types::IpcConfig::new(
        cfg.root_path.as_deref(),
        &cfg.raw.backend.service_prefix,
    );
    let ipc = frictionless_shm_types::Ipc::open(&ipc_cfg, "frictiond-control")
        .context("opening the control node")?;
    let server = ipc
        .control_server()
        .context("opening the control service")?;
    Ok((ipc, server))
}

/// Capacity of the runtime-change queue to the RT thread (a full queue refuses a request).
const CONTROL_QUEUE: usize = 64;

/// The running RT thread and the supervisor's ends of its channels and shared atomics.
struct Rt {
    /// Runtime changes to the RT thread, applied at its next tick boundary.
    tx_control: std::sync::mpsc::SyncSender<frictiond::runtime::RuntimeSet>,
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
    let (tx_control, rx_control) =
        std::sync::mpsc::sync_channel::<frictiond::runtime::RuntimeSet>(CONTROL_QUEUE);
    let setup = rt::RtSetup {
        config: cfg.clone(),
        params,
        rx_params,
        tx_old,
        rx_control,
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
        tx_control,
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
    cfg: config::Config,
    config_path: &std::path::Path,
    signals: &mut signal_hook::iterator::Signals,
    rt: &Rt,
) -> anyhow::Result<i32> {
    let shared = &rt.shared;
    let ready_after = cfg.raw.loop_.ready_after_ticks;
    let (_control_node, control) = open_control(&cfg)?;
    let mut control_state =
        frictiond::control::ControlState::new(&cfg, 0, frictionless_shm_types::monotonic_ns());
    let mut reloads = Reloads::new(cfg);
    let mut stale_log = StaleLog::default();
    let wd = sdnotify::watchdog_interval();
    let mut ready = false;
    let mut last_wd = Instant::now();
    let mut last_wd_beat = 0u64;
    let mut last_status = Instant::now();
    let mut last_beat = 0u64;
    let mut last_beat_change = Instant::now();
    let mut stop_reason = None;
    while stop_reason.is_none() {
        for sig in signals.pending() {
            match sig {
                SIGTERM | SIGINT => stop_reason = Some(sig),
                SIGHUP => reloads.start(config_path),
                _ => {}
            }
        }
        reloads.poll(&rt.tx_params);
        if reloads.generation != control_state.generation() {
            // A reload restores every runtime value to the new file's.
            control_state.reset(
                &reloads.running,
                reloads.generation,
                frictionless_shm_types::monotonic_ns(),
            );
        }
        let served = control.serve(|req| {
            control_state.answer(
                &reloads.running,
                reloads.running.raw.control.writes,
                req,
                &rt.tx_control,
                frictionless_shm_types::monotonic_ns(),
                shared.heartbeat.load(Ordering::Relaxed),
            )
        });
        if let Err(e) = served {
            tracing::warn!("control: {e}");
        }
        for line in stale_log.observe(
            shared.stale_episodes.load(Ordering::Relaxed),
            shared.input_stale.load(Ordering::Relaxed),
            Instant::now(),
        ) {
            match line {
                StaleLine::Entry(m) => tracing::warn!("{m}"),
                StaleLine::Recovery(m) => tracing::info!("{m}"),
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
        tx_control: _tx_control,
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
        let applied = shared.control_applied.load(Ordering::Relaxed);
        let dropped = shared.control_dropped.load(Ordering::Relaxed);
        let text = format!(
            "rt_allocations={counted}\nrt_exempt_allocations={exempt}\nrt_counted_ticks={ticks}\n\
             rt_control_applied={applied}\nrt_control_dropped={dropped}\n"
        );
        frictionless::output_file::write(&path, text)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let (Some(path), Some(summary)) = (latency_report, &summary) {
        frictionless::output_file::write(&path, summary.report())
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

/// How long a reload (reading the config and every model, building the parameters) may take on its
/// worker thread before it is abandoned and the running parameters kept. Regular files load in
/// milliseconds; a config path that is a FIFO or a hung network file system blocks forever.
const RELOAD_BOUND: Duration = Duration::from_secs(10);

/// Abandoned (still blocked) reload threads after which further SIGHUPs are refused.
const MAX_BLOCKED_RELOADS: usize = 4;

/// What a reload worker sends back: the new config (with the running `[loop]`, `[backend]` and
/// root path) and its parameters, or why it was rejected.
type ReloadResult = Result<(config::Config, Box<params::Params>), String>;

/// The reload worker: one long-lived thread that loads configs on request, so the signal loop never
/// reads a file and the process does not gain a thread (and an allocator arena) per SIGHUP. A worker
/// that blocks past [`RELOAD_BOUND`] is abandoned (it exits when its read returns) and the next
/// SIGHUP starts a fresh one.
struct ReloadWorker {
    tx: std::sync::mpsc::SyncSender<(config::Config, PathBuf, u64)>,
    rx: std::sync::mpsc::Receiver<ReloadResult>,
    thread: std::thread::JoinHandle<()>,
}

impl ReloadWorker {
    fn spawn() -> std::io::Result<Self> {
        let (tx, rx_req) = std::sync::mpsc::sync_channel::<(config::Config, PathBuf, u64)>(1);
        let (tx_res, rx) = std::sync::mpsc::sync_channel(1);
        let thread = std::thread::Builder::new()
            .name("frictiond-reload".into())
            .spawn(move || {
                while let Ok((running, path, generation)) = rx_req.recv() {
                    if tx_res
                        .send(load_for_reload(&running, &path, generation))
                        .is_err()
                    {
                        break; // abandoned
                    }
                }
            })?;
        Ok(Self { tx, rx, thread })
    }
}

/// SIGHUP reloads: the running config, the generation, the worker, the reload in flight (at most
/// one: when it started and which file) and the abandoned workers.
struct Reloads {
    /// What the RT thread was started with: `[loop]`, `[backend]` and the root path stay these
    /// until a restart, and every reload is compared against them.
    running: config::Config,
    generation: u64,
    worker: Option<ReloadWorker>,
    pending: Option<(Instant, PathBuf)>,
    abandoned: Vec<std::thread::JoinHandle<()>>,
}

/// What a reload would change that only a restart applies (empty: nothing). Compared against the
/// running config, not the last file read.
pub(crate) fn needs_restart(running: &config::Config, new: &config::Config) -> Vec<&'static str> {
    let mut v = Vec::new();
    if new.raw.loop_ != running.raw.loop_ {
        v.push("[loop]");
    }
    if new.raw.backend != running.raw.backend || new.root_path != running.root_path {
        v.push("[backend]");
    }
    v
}

/// The reload itself (on the worker thread): load and validate `path`, warn about what needs a
/// restart, keep the running `[loop]`/`[backend]`/root (so joints are built for the period the
/// loop runs at), build the parameters as `generation`.
fn load_for_reload(
    running: &config::Config,
    path: &std::path::Path,
    generation: u64,
) -> ReloadResult {
    let mut new = config::load(path).map_err(|e| e.to_string())?;
    let fixed = frictiond::backend::AnyBackend::reload_conflicts(running, &new);
    if !fixed.is_empty() {
        return Err(format!(
            "{} needs a restart: the {} backend fixed these when it opened ({}); nothing applied",
            path.display(),
            running.raw.backend.kind.label(),
            fixed.join("; ")
        ));
    }
    let restart = needs_restart(running, &new);
    if !restart.is_empty() {
        tracing::warn!(
            "{} changes need a restart; applying joints and safety only (running with the {} the daemon started with)",
            restart.join(" and "),
            restart.join(" and ")
        );
    }
    new.raw.loop_ = running.raw.loop_.clone();
    new.raw.backend = running.raw.backend.clone();
    new.root_path = running.root_path.clone();
    let p = params::build(&new, generation).map_err(|e| e.to_string())?;
    Ok((new, p))
}

impl Reloads {
    fn new(running: config::Config) -> Self {
        Self {
            running,
            generation: 0,
            worker: None,
            pending: None,
            abandoned: Vec::new(),
        }
    }

    /// SIGHUP: hands the reload to the worker, unless one is in flight or too many are blocked.
    fn start(&mut self, path: &std::path::Path) {
        if self.pending.is_some() {
            tracing::warn!("SIGHUP ignored: the previous reload is still running");
            return;
        }
        self.abandoned.retain(|t| !t.is_finished());
        if self.abandoned.len() >= MAX_BLOCKED_RELOADS {
            tracing::error!(
                "SIGHUP refused: {} earlier reloads are still blocked reading their files; restart frictiond",
                self.abandoned.len()
            );
            return;
        }
        sdnotify::notify_logged(&format!(
            "RELOADING=1\nMONOTONIC_USEC={}\nSTATUS=reloading",
            sdnotify::monotonic_usec()
        ));
        if self.worker.is_none() {
            match ReloadWorker::spawn() {
                Ok(w) => self.worker = Some(w),
                Err(e) => {
                    tracing::error!("reload rejected: spawning the reload thread: {e}");
                    sdnotify::notify_logged("READY=1\nSTATUS=running");
                    return;
                }
            }
        }
        let w = self.worker.as_ref().expect("set above");
        let request = (
            self.running.clone(),
            path.to_path_buf(),
            self.generation + 1,
        );
        if w.tx.try_send(request).is_err() {
            // The worker ended (it never does while its channels live): start afresh next time.
            self.worker = None;
            tracing::error!("reload rejected: the reload thread is gone");
            sdnotify::notify_logged("READY=1\nSTATUS=running");
            return;
        }
        self.pending = Some((Instant::now(), path.to_path_buf()));
    }

    /// Every supervisor pass: applies a finished reload (hands the parameters to the RT thread),
    /// or abandons the worker past [`RELOAD_BOUND`].
    fn poll(&mut self, tx: &std::sync::mpsc::SyncSender<Box<params::Params>>) {
        let (Some((started, _)), Some(w)) = (&self.pending, &self.worker) else {
            return;
        };
        let result = match w.rx.try_recv() {
            Ok(r) => r,
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                if started.elapsed() < RELOAD_BOUND {
                    return;
                }
                let w = self.worker.take().expect("checked above");
                self.abandoned.push(w.thread);
                Err(format!(
                    "not finished within {} s (blocked reading a file?): abandoned",
                    RELOAD_BOUND.as_secs()
                ))
            }
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                self.worker = None;
                Err("the reload thread ended without a result".to_owned())
            }
        };
        let (_, path) = self.pending.take().expect("checked above");
        match result {
            Ok((new, params)) => match tx.try_send(params) {
                Ok(()) => {
                    self.generation += 1;
                    tracing::info!(
                        "reloaded {}: generation {}",
                        path.display(),
                        self.generation
                    );
                    // Keeps the running [loop]/[backend] (load_for_reload put them back).
                    self.running = new;
                }
                Err(_) => {
                    tracing::error!("reload skipped: the previous hand-over is still pending")
                }
            },
            Err(e) => tracing::error!(
                "reload rejected, keeping generation {}: {e}",
                self.generation
            ),
        }
        sdnotify::notify_logged("READY=1\nSTATUS=running");
    }
}

/// Rate limit of the stale-input log lines: at most one entry and one recovery line per window.
const STALE_LOG_WINDOW: Duration = Duration::from_secs(10);

/// A stale-input log line.
#[derive(Debug, Clone, PartialEq)]
enum StaleLine {
    /// Input became stale (warn).
    Entry(String),
    /// Input fresh again (info).
    Recovery(String),
}

/// Turns the RT thread's stale flag and episode counter into log lines: one when input goes
/// stale, one when it recovers, each at most once per [`STALE_LOG_WINDOW`]; episodes in between are
/// counted into the next line.
#[derive(Debug, Default)]
struct StaleLog {
    episodes: u64,
    stale: bool,
    last_entry: Option<Instant>,
    last_recovery: Option<Instant>,
    unlogged_entries: u64,
    unlogged_recoveries: u64,
}

impl StaleLog {
    fn observe(&mut self, episodes: u64, stale: bool, now: Instant) -> Vec<StaleLine> {
        let mut out = Vec::new();
        let new_entries = episodes.saturating_sub(self.episodes);
        // Every entry but a still-running last one has recovered.
        let new_recoveries = if new_entries > 0 {
            new_entries - u64::from(stale) + u64::from(self.stale)
        } else {
            u64::from(self.stale && !stale)
        };
        self.episodes = episodes;
        self.stale = stale;
        let due =
            |last: Option<Instant>| last.is_none_or(|t| now.duration_since(t) >= STALE_LOG_WINDOW);
        let more = |n: u64| {
            if n > 0 {
                format!(" ({n} more since the last message)")
            } else {
                String::new()
            }
        };
        if new_entries > 0 {
            if due(self.last_entry) {
                out.push(StaleLine::Entry(format!(
                    "input stale (no joint states or torque request within stale_after_ticks): safe output{}",
                    more(self.unlogged_entries + new_entries - 1)
                )));
                self.last_entry = Some(now);
                self.unlogged_entries = 0;
            } else {
                self.unlogged_entries += new_entries;
            }
        }
        if new_recoveries > 0 {
            if due(self.last_recovery) {
                out.push(StaleLine::Recovery(format!(
                    "input fresh again{}",
                    more(self.unlogged_recoveries + new_recoveries - 1)
                )));
                self.last_recovery = Some(now);
                self.unlogged_recoveries = 0;
            } else {
                self.unlogged_recoveries += new_recoveries;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_log_logs_entry_and_recovery_once_per_window_and_counts_the_rest() {
        let t0 = Instant::now();
        let mut l = StaleLog::default();
        assert!(l.observe(0, false, t0).is_empty());
        let v = l.observe(1, true, t0);
        assert!(
            matches!(&v[..], [StaleLine::Entry(m)] if !m.contains("more")),
            "{v:?}"
        );
        assert!(
            l.observe(1, true, t0 + Duration::from_millis(5)).is_empty(),
            "once per entry"
        );
        let v = l.observe(1, false, t0 + Duration::from_millis(10));
        assert!(matches!(&v[..], [StaleLine::Recovery(_)]), "{v:?}");
        // Three more episodes within the window (one still stale): nothing logged.
        assert!(l.observe(4, true, t0 + Duration::from_secs(1)).is_empty());
        assert!(l.observe(4, false, t0 + Duration::from_secs(2)).is_empty());
        // After the window the next entry carries the count of the unlogged ones.
        let v = l.observe(5, true, t0 + Duration::from_secs(11));
        assert_eq!(
            v,
            vec![StaleLine::Entry(
                "input stale (no joint states or torque request within stale_after_ticks): safe output (3 more since the last message)".into()
            )]
        );
        let v = l.observe(5, false, t0 + Duration::from_secs(12));
        assert_eq!(
            v,
            vec![StaleLine::Recovery(
                "input fresh again (3 more since the last message)".into()
            )]
        );
        // Entry and recovery both between two polls.
        let v = l.observe(6, false, t0 + Duration::from_secs(30));
        assert_eq!(v.len(), 2, "{v:?}");
    }
}
