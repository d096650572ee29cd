//! Loop statistics off the tick's critical path: the 1 µs wake-lateness histogram, the thread's
//! resource usage, and the summary the RT thread hands back at exit (the `key=value` report of the
//! exit log and `FRICTIOND_LATENCY_REPORT`). The per-tick recording into the status snapshot is
//! the tick's own step 4 (`Telemetry` in the parent module).

use frictionless_shm_types::{DaemonStatus, STATUS_CPU_PINNED, STATUS_MEMORY_LOCKED};

/// Resource usage of the calling thread (`getrusage(RUSAGE_THREAD)`): read before and after the
/// loop only (a syscall), to tell page faults and preemptions apart from timer wake-up latency.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ThreadUsage {
    /// Minor page faults.
    pub minflt: u64,
    /// Major page faults.
    pub majflt: u64,
    /// Voluntary context switches (one per sleep of the clock trigger).
    pub nvcsw: u64,
    /// Involuntary context switches (preemptions).
    pub nivcsw: u64,
}

impl ThreadUsage {
    /// The calling thread's counters now (zero if the call fails).
    pub fn now() -> Self {
        // SAFETY: getrusage writes into a valid, zeroed rusage.
        let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
        if unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut ru) } != 0 {
            return Self::default();
        }
        Self {
            minflt: ru.ru_minflt as u64,
            majflt: ru.ru_majflt as u64,
            nvcsw: ru.ru_nvcsw as u64,
            nivcsw: ru.ru_nivcsw as u64,
        }
    }

    /// Counts since `earlier`.
    pub fn since(self, earlier: Self) -> Self {
        Self {
            minflt: self.minflt.saturating_sub(earlier.minflt),
            majflt: self.majflt.saturating_sub(earlier.majflt),
            nvcsw: self.nvcsw.saturating_sub(earlier.nvcsw),
            nivcsw: self.nivcsw.saturating_sub(earlier.nivcsw),
        }
    }
}

/// Wake lateness with 1 µs buckets up to [`FineHistogram::BUCKETS`] µs (the shared-memory
/// [`Histogram`](frictionless_shm_types::Histogram) has power-of-two buckets, too coarse to
/// compare with `cyclictest`). Allocated and pre-faulted before the loop; `record` is O(1).
#[derive(Debug)]
pub struct FineHistogram {
    counts: Box<[u64]>,
    /// Values at or above the last bucket.
    pub overflow: u64,
    /// Number of recorded values.
    pub total: u64,
    /// Largest recorded value [ns].
    pub max_ns: u64,
}

impl FineHistogram {
    /// Number of 1 µs buckets (20 ms).
    pub const BUCKETS: usize = 20_000;

    /// An empty histogram (allocates and touches every page once).
    pub fn new() -> Self {
        let mut counts = vec![1u64; Self::BUCKETS].into_boxed_slice();
        counts.fill(0);
        Self {
            counts,
            overflow: 0,
            total: 0,
            max_ns: 0,
        }
    }

    /// Records one value [ns].
    #[inline]
    pub fn record(&mut self, ns: u64) {
        let us = (ns / 1000) as usize;
        match self.counts.get_mut(us) {
            Some(c) => *c += 1,
            None => self.overflow += 1,
        }
        self.total += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    /// Upper edge [ns] of the 1 µs bucket holding quantile `q` (capped by the max); 0 when empty.
    pub fn quantile_upper_ns(&self, q: f64) -> u64 {
        if self.total == 0 {
            return 0;
        }
        let want = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (k, c) in self.counts.iter().enumerate() {
            acc += c;
            if acc >= want {
                return ((k as u64 + 1) * 1000).min(self.max_ns);
            }
        }
        self.max_ns
    }
}

impl Default for FineHistogram {
    fn default() -> Self {
        Self::new()
    }
}

/// What the RT thread hands back when it ends: loop statistics for the exit log and the
/// `FRICTIOND_LATENCY_REPORT` file.
#[derive(Debug)]
pub struct RtSummary {
    /// Ticks run.
    pub ticks: u64,
    /// Missed deadlines (always 0 with the lockstep trigger).
    pub missed: u64,
    /// Whether the lockstep trigger ran (then `lateness` is empty: there is no deadline).
    pub lockstep: bool,
    /// Wake lateness against the absolute deadline, 1 µs buckets (clock trigger only).
    pub lateness: FineHistogram,
    /// The last status snapshot (power-of-two histograms of lateness, compute time, input age).
    pub status: Box<DaemonStatus>,
    /// How the RT thread ran: what it was granted and what happened to it during the loop.
    pub thread: RtThreadReport,
    /// How the helper thread ran (`rt_threads = 2`), if there was one.
    pub helper: Option<HelperReport>,
    /// Ticks whose helper half was late (published as 0 A + `FLAG_STALE`).
    pub helper_late: u64,
    /// Ticks whose helper half the main RT thread ran itself (the helper had not started it).
    pub helper_stolen: u64,
}

/// How the helper thread ran (for the latency report).
#[derive(Debug, Clone, Copy, Default)]
pub struct HelperReport {
    /// Granted `STATUS_*` flags (`STATUS_CPU_PINNED` only with `helper_cpu`).
    pub rt_flags: u32,
    /// Scheduling policy at the end.
    pub policy: i32,
    /// Priority at the end.
    pub priority: i32,
    /// Jobs run.
    pub jobs: u64,
    /// Page faults and context switches during the loop.
    pub usage: ThreadUsage,
}

/// How the RT thread ran (for the latency report).
#[derive(Debug, Clone, Copy, Default)]
pub struct RtThreadReport {
    /// Kernel thread id.
    pub tid: i32,
    /// Granted `STATUS_*` flags.
    pub rt_flags: u32,
    /// Scheduling policy (`SCHED_*`) and priority at the end of the loop.
    pub policy: i32,
    /// Priority at the end of the loop (0 under SCHED_OTHER).
    pub priority: i32,
    /// CPU the thread ran on when the loop started and when it ended.
    pub cpu_start: i32,
    /// See `cpu_start`.
    pub cpu_end: i32,
    /// PM QoS bound held on `/dev/cpu_dma_latency` [µs] (read back), if any.
    pub pm_qos_us: Option<i32>,
    /// Page faults and context switches during the loop.
    pub usage: ThreadUsage,
}

impl RtThreadReport {
    fn policy_name(&self) -> &'static str {
        policy_name(self.policy)
    }
}

/// Name of a `SCHED_*` policy.
fn policy_name(policy: i32) -> &'static str {
    match policy {
        libc::SCHED_FIFO => "SCHED_FIFO",
        libc::SCHED_RR => "SCHED_RR",
        libc::SCHED_OTHER => "SCHED_OTHER",
        libc::SCHED_BATCH => "SCHED_BATCH",
        libc::SCHED_IDLE => "SCHED_IDLE",
        _ => "unknown",
    }
}

impl RtSummary {
    /// `key=value` lines: ticks, missed, trigger, and p50/p99/p99.9/max of wake lateness (1 µs
    /// resolution), compute time and input age (power-of-two bucket upper bounds) [ns].
    pub fn report(&self) -> String {
        use std::fmt::Write;
        let mut s = format!(
            "trigger={}\nticks={}\nmissed={}\n",
            if self.lockstep { "lockstep" } else { "clock" },
            self.ticks,
            self.missed
        );
        let h = &self.lateness;
        let _ = writeln!(
            s,
            "lateness_n={}\nlateness_p50_ns={}\nlateness_p99_ns={}\nlateness_p999_ns={}\nlateness_max_ns={}",
            h.total,
            h.quantile_upper_ns(0.5),
            h.quantile_upper_ns(0.99),
            h.quantile_upper_ns(0.999),
            h.max_ns
        );
        // The whole 1 µs histogram (non-empty buckets), so runs can be merged (benches/lateness.sh
        // interleaves frictiond and cyclictest in chunks and computes both quantiles one way).
        let _ = write!(s, "lateness_overflow={}\nlateness_hist_us=", h.overflow);
        let mut first = true;
        for (us, &c) in h.counts.iter().enumerate().filter(|(_, c)| **c > 0) {
            let _ = write!(s, "{}{us}:{c}", if first { "" } else { "," });
            first = false;
        }
        s.push('\n');
        let t = &self.thread;
        let _ = writeln!(
            s,
            "rt_tid={}\nrt_policy={}\nrt_priority={}\nrt_cpu_pinned={}\nrt_memory_locked={}\nrt_cpu_start={}\nrt_cpu_end={}\nrt_pm_qos_us={}\nrt_minflt={}\nrt_majflt={}\nrt_nvcsw={}\nrt_nivcsw={}",
            t.tid,
            t.policy_name(),
            t.priority,
            t.rt_flags & STATUS_CPU_PINNED != 0,
            t.rt_flags & STATUS_MEMORY_LOCKED != 0,
            t.cpu_start,
            t.cpu_end,
            t.pm_qos_us
                .map_or_else(|| "none".to_owned(), |v| v.to_string()),
            t.usage.minflt,
            t.usage.majflt,
            t.usage.nvcsw,
            t.usage.nivcsw
        );
        let _ = writeln!(
            s,
            "rt_threads={}\nhelper_late={}\nhelper_stolen={}",
            if self.helper.is_some() { 2 } else { 1 },
            self.helper_late,
            self.helper_stolen
        );
        if let Some(h) = &self.helper {
            let _ = writeln!(
                s,
                "helper_policy={}\nhelper_priority={}\nhelper_cpu_pinned={}\nhelper_jobs={}\nhelper_minflt={}\nhelper_majflt={}\nhelper_nivcsw={}",
                policy_name(h.policy),
                h.priority,
                h.rt_flags & STATUS_CPU_PINNED != 0,
                h.jobs,
                h.usage.minflt,
                h.usage.majflt,
                h.usage.nivcsw
            );
        }
        for (name, h) in [
            ("compute", &self.status.compute),
            ("input_age", &self.status.input_age),
        ] {
            let _ = writeln!(
                s,
                "{name}_n={}\n{name}_mean_ns={:.0}\n{name}_p50_ns={}\n{name}_p99_ns={}\n{name}_p999_ns={}\n{name}_max_ns={}",
                h.total,
                h.mean_ns(),
                h.quantile_upper_ns(0.5),
                h.quantile_upper_ns(0.99),
                h.quantile_upper_ns(0.999),
                h.max_ns
            );
        }
        s
    }
}
