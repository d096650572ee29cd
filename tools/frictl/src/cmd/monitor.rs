//! `frictl monitor` — a terminal view of a running `frictiond`'s [`DaemonStatus`].
//!
//! What it **is**: subscribes to `<prefix>/daemon_status` (same iceoryx2 root path and prefix as the
//! daemon) and prints, at most every `--interval-ms`, loop statistics (ticks, missed deadlines,
//! wake-lateness / compute / input-age quantiles) and one line per joint (model, τ̂_F, i_ref, flags).
//! `--once` prints one snapshot and exits (scripts, tests).
//!
//! What it is **not**: no control; it never publishes anything.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use frictionless_shm_types::{
    BusCounters, DaemonStatus, FLAG_CURRENT_SATURATED, FLAG_DISABLED, FLAG_FAULT,
    FLAG_FRICTION_CLIPPED, FLAG_NON_FINITE, FLAG_OUT_OF_RANGE, FLAG_STALE, FLAG_WARMING_UP,
    Histogram, Ipc, IpcConfig, STATUS_CPU_PINNED, STATUS_INPUT_STALE, STATUS_MEMORY_LOCKED,
    STATUS_SCHED_FIFO, STATUS_STOPPING,
};

pub use frictl_cli::monitor::*;

fn kind_name(k: u8) -> &'static str {
    frictionless::model::ModelKind::from_code(k).map_or("?", |k| k.name())
}

fn flag_names(f: u32) -> String {
    let names = [
        (FLAG_CURRENT_SATURATED, "SAT"),
        (FLAG_FRICTION_CLIPPED, "CLIP"),
        (FLAG_NON_FINITE, "NAN"),
        (FLAG_STALE, "STALE"),
        (FLAG_DISABLED, "off"),
        (FLAG_FAULT, "FAULT"),
        (FLAG_WARMING_UP, "warm"),
        (FLAG_OUT_OF_RANGE, "OOD"),
    ];
    let v: Vec<&str> = names
        .iter()
        .filter(|(b, _)| f & b != 0)
        .map(|(_, n)| *n)
        .collect();
    if v.is_empty() {
        "-".into()
    } else {
        v.join(",")
    }
}

fn hist_line(name: &str, h: &Histogram) -> String {
    format!(
        "{name:<10} n={:<9} mean {:>8.1} µs  p50≤{:>6} µs  p99≤{:>6} µs  p99.9≤{:>6} µs  max {:>8.1} µs",
        h.total,
        h.mean_ns() / 1e3,
        h.quantile_upper_ns(0.5) / 1000,
        h.quantile_upper_ns(0.99) / 1000,
        h.quantile_upper_ns(0.999) / 1000,
        h.max_ns as f64 / 1e3
    )
}

/// The backend's link counters on one line, with its detail slots by name.
fn bus_line(c: &BusCounters) -> String {
    let kind = c.bus_kind().map_or("?", |k| k.name());
    let mut line = format!(
        "bus {kind} ({} link(s)): rx {}  tx {}  dropped {}  error reports {}  link down {}  io errors {}  stale mask {:#x}",
        c.links,
        c.rx_messages,
        c.tx_messages,
        c.tx_dropped,
        c.error_reports,
        c.link_down,
        c.io_errors,
        c.stale_feedback_mask
    );
    for (name, v) in c.named_detail() {
        line.push_str(&format!("  {name} {v}"));
    }
    line.push('\n');
    line
}

/// Renders one status snapshot as text.
pub fn render(s: &DaemonStatus) -> String {
    let rt: Vec<&str> = [
        (STATUS_SCHED_FIFO, "FIFO"),
        (STATUS_MEMORY_LOCKED, "mlock"),
        (STATUS_CPU_PINNED, "pinned"),
        (STATUS_INPUT_STALE, "INPUT-STALE"),
        (STATUS_STOPPING, "STOPPING"),
    ]
    .iter()
    .filter(|(b, _)| s.flags & b != 0)
    .map(|(_, n)| *n)
    .collect();
    let age = if s.input_age_ns == u64::MAX {
        "none".to_string()
    } else {
        format!("{:.1} µs", s.input_age_ns as f64 / 1e3)
    };
    let mut out = format!(
        "frictiond: ticks {}  period {} µs  missed {}  stale ticks {}  generation {}  [{}]  input age {}\n{}\n{}\n{}\n",
        s.ticks,
        s.period_ns / 1000,
        s.missed_deadlines,
        s.stale_ticks,
        s.generation,
        rt.join(" "),
        age,
        hist_line("lateness", &s.lateness),
        hist_line("compute", &s.compute),
        hist_line("input age", &s.input_age),
    );
    out.push_str(&bus_line(&s.bus));
    out.push_str(" idx  model     τ̂_F [Nm]    i_ref [A]  out-of-range ticks  flags\n");
    for k in 0..(s.n_joints as usize).min(frictionless_shm_types::MAX_JOINTS) {
        // Joints are sparse by index; show those with any activity or a configured model.
        out.push_str(&format!(
            " {k:>3}  {:<8} {:>10.4} {:>11.4}  {:>18}  {}\n",
            kind_name(s.model_kind[k]),
            s.tau_f_hat_nm[k],
            s.i_ref_a[k],
            s.out_of_range_ticks[k],
            flag_names(s.joint_flags[k])
        ));
    }
    out
}

/// Runs `frictl monitor`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = IpcConfig::new(args.root_path.as_deref(), &args.prefix);
    let ipc = Ipc::open(&cfg, "frictl_monitor").context("opening iceoryx2")?;
    let inbox = ipc
        .daemon_status()
        .context("opening daemon_status")?
        .inbox()
        .context("subscribing")?;
    let mut last_seen = Instant::now();
    loop {
        let got = inbox
            .wait_latest(Duration::from_millis(args.interval_ms.max(10)))
            .map_err(|e| anyhow::anyhow!("receiving status: {e}"))?;
        match got {
            Some(s) => {
                last_seen = Instant::now();
                if !args.once {
                    print!("\x1b[2J\x1b[H");
                }
                print!("{}", render(&s));
                if args.once {
                    return Ok(());
                }
                std::thread::sleep(Duration::from_millis(args.interval_ms));
            }
            None => {
                if args.timeout_s > 0 && last_seen.elapsed() > Duration::from_secs(args.timeout_s) {
                    bail!(
                        "no DaemonStatus on `{}` for {} s (is frictiond running with this prefix/root path?)",
                        cfg.service_name(frictionless_shm_types::ServiceKind::DaemonStatus),
                        args.timeout_s
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_shows_the_out_of_range_count_and_flag() {
        let mut s = DaemonStatus::zeroed();
        s.n_joints = 2;
        s.model_kind[1] = frictionless::model::ModelKind::Pinn.code();
        s.out_of_range_ticks[1] = 1234;
        s.joint_flags[1] = FLAG_OUT_OF_RANGE;
        let text = render(&s);
        let line = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some("1"))
            .unwrap();
        assert!(
            line.contains("pinn") && line.contains(" 1234 ") && line.ends_with("OOD"),
            "{line}"
        );
        assert!(text.contains("out-of-range ticks"), "{text}");
    }

    #[test]
    fn render_shows_the_bus_counters_with_their_kind_and_detail() {
        use frictionless_shm_types::{BusKind, CAN_DETAIL_ERROR_PASSIVE};
        let mut s = DaemonStatus::zeroed();
        s.bus = BusCounters::new(BusKind::Can, 2);
        s.bus.rx_messages = 77;
        s.bus.link_down = 1;
        s.bus.detail[CAN_DETAIL_ERROR_PASSIVE] = 5;
        let text = render(&s);
        let line = text.lines().find(|l| l.starts_with("bus ")).expect(&text);
        assert!(line.starts_with("bus can (2 link(s))"), "{line}");
        assert!(
            line.contains("rx 77 ") && line.contains("link down 1 "),
            "{line}"
        );
        assert!(line.ends_with("error_passive 5  emcy 0"), "{line}");
    }
}
