//! RT set-up: what the RT thread does before its first tick, and the RT settings of each thread.
//!
//! [`start`] runs on the RT thread: it opens the backend (its iceoryx2 ports are `!Send`), applies
//! the RT settings ([`apply_rt_settings`]: PM QoS, then [`apply_thread_rt`]: timer slack, CPU
//! affinity, SCHED_FIFO, mlockall — each verified, refusals reported and fatal under
//! `require_rt`), starts the helper thread of `rt_threads = 2` and pre-faults the stack. Set-up
//! may allocate and log; nothing here runs per tick.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, SyncSender};

use frictionless_shm_types::{STATUS_CPU_PINNED, STATUS_MEMORY_LOCKED, STATUS_SCHED_FIFO};

use super::Shared;
use super::crew::{Crew, CrewPlan, ThreadRt};
use crate::backend::{AnyBackend, BackendError};
use crate::config::{BackendKind, Config};
use crate::params::Params;

/// Everything the RT thread gets from the supervisor.
pub struct RtSetup {
    /// The validated config (loop, backend, safety).
    pub config: Config,
    /// Initial parameters.
    pub params: Box<Params>,
    /// New parameters from reloads.
    pub rx_params: Receiver<Box<Params>>,
    /// Old parameters back to the supervisor to be freed.
    pub tx_old: SyncSender<Box<Params>>,
    /// Runtime changes, checked off-thread, applied at a tick boundary (bounded queue).
    pub rx_control: Receiver<crate::runtime::RuntimeSet>,
    /// Shared atomics.
    pub shared: Arc<Shared>,
    /// Start-up result: Ok(granted STATUS_* flags) or why set-up failed.
    pub started: SyncSender<Result<u32, RtSetupError>>,
    /// Count RT-thread allocations after `ready_after_ticks`.
    pub count_allocs: bool,
}

/// Why the RT thread could not start (reported through [`RtSetup::started`]).
#[derive(Debug, thiserror::Error)]
pub enum RtSetupError {
    /// The backend could not be opened.
    #[error("opening the {kind:?} backend: {source}")]
    Backend {
        /// `[backend] kind`.
        kind: BackendKind,
        /// Why.
        source: BackendError,
    },
    /// The helper thread of `rt_threads = 2` could not be started.
    #[error("starting the helper RT thread (rt_threads = 2): {0}")]
    Helper(#[source] std::io::Error),
    /// `[loop] require_rt = true` and at least one RT setting was refused.
    #[error("loop.require_rt = true and RT settings were refused: {}", join_refusals(.0))]
    RtRefused(Vec<RtRefusal>),
}

/// One RT setting the kernel refused (logged; fatal under `[loop] require_rt = true`).
#[derive(Debug, thiserror::Error)]
pub enum RtRefusal {
    /// `/dev/cpu_dma_latency` could not be held.
    #[error("cpu_dma_latency {us} µs: /dev/cpu_dma_latency: {source} (root only)")]
    CpuDmaLatency {
        /// Requested bound [µs].
        us: u32,
        /// The OS error.
        source: std::io::Error,
    },
    /// `prctl(PR_SET_TIMERSLACK)` failed.
    #[error("PR_SET_TIMERSLACK: {0}")]
    TimerSlack(#[source] std::io::Error),
    /// The thread could not be pinned to `[loop] cpu`.
    #[error("CPU affinity {cpu}: {source}")]
    Affinity {
        /// Requested CPU.
        cpu: usize,
        /// The OS error.
        source: std::io::Error,
    },
    /// SCHED_FIFO at `[loop] priority` was not granted.
    #[error("SCHED_FIFO {priority}: {source} (needs CAP_SYS_NICE or LimitRTPRIO)")]
    SchedFifo {
        /// Requested priority.
        priority: i32,
        /// The OS error.
        source: std::io::Error,
    },
    /// `mlockall` failed.
    #[error("mlockall: {0} (needs CAP_IPC_LOCK or LimitMEMLOCK)")]
    Mlockall(#[source] std::io::Error),
}

fn join_refusals(r: &[RtRefusal]) -> String {
    r.iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// What [`apply_rt_settings`] obtained.
pub(super) struct RtGrant {
    /// Granted `STATUS_*` flags.
    pub(super) flags: u32,
    /// The open `/dev/cpu_dma_latency` holding the PM QoS request (dropped = released).
    _pm_qos: Option<std::fs::File>,
    /// The PM QoS value read back from `/dev/cpu_dma_latency` [µs], when held.
    pub(super) pm_qos_us: Option<i32>,
}

/// `[loop] cpu_dma_latency_us`: writes the bound to `/dev/cpu_dma_latency` and keeps the file open
/// (the kernel drops the request on close), then reads the effective value back.
pub(super) fn hold_cpu_dma_latency(us: u32) -> std::io::Result<(std::fs::File, i32)> {
    use std::io::{Read, Write};
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open("/dev/cpu_dma_latency")?;
    f.write_all(&(us as i32).to_ne_bytes())?;
    let mut b = [0u8; 4];
    f.read_exact(&mut b)?;
    Ok((f, i32::from_ne_bytes(b)))
}

/// Applies RT settings to the calling (main RT) thread: PM QoS, then [`apply_thread_rt`] with
/// `[loop] cpu`; returns what was granted. Logs refusals.
pub(super) fn apply_rt_settings(cfg: &Config) -> Result<RtGrant, RtSetupError> {
    let l = &cfg.raw.loop_;
    let mut refused = Vec::new();
    let (mut pm_qos, mut pm_qos_us) = (None, None);
    if let Some(us) = l.cpu_dma_latency_us {
        match hold_cpu_dma_latency(us) {
            Ok((f, got)) => {
                if got as i64 > us as i64 {
                    tracing::warn!(
                        "cpu_dma_latency: asked for {us} µs, the effective bound is {got} µs"
                    );
                }
                (pm_qos, pm_qos_us) = (Some(f), Some(got));
            }
            Err(source) => refused.push(RtRefusal::CpuDmaLatency { us, source }),
        }
    }
    let flags = apply_thread_rt(
        ThreadRt {
            cpu: l.cpu,
            priority: l.priority,
            lock_memory: l.lock_memory,
        },
        &mut refused,
    );
    for r in &refused {
        tracing::warn!("RT setting refused: {r}");
    }
    if l.require_rt && !refused.is_empty() {
        return Err(RtSetupError::RtRefused(refused));
    }
    Ok(RtGrant {
        flags,
        _pm_qos: pm_qos,
        pm_qos_us,
    })
}

/// Per-thread RT settings on the calling thread (timer slack, affinity, SCHED_FIFO, mlockall);
/// returns the granted `STATUS_*` flags and appends refusals to `refused`. Shared by the main RT
/// thread and the helper of `rt_threads = 2`.
pub(super) fn apply_thread_rt(t: ThreadRt, refused: &mut Vec<RtRefusal>) -> u32 {
    let mut flags = 0;
    // SAFETY: plain syscalls on the calling thread with valid arguments.
    unsafe {
        // Timer slack 1 ns (default 50 µs would dominate SCHED_OTHER lateness).
        if libc::prctl(libc::PR_SET_TIMERSLACK, 1, 0, 0, 0) != 0 {
            refused.push(RtRefusal::TimerSlack(std::io::Error::last_os_error()));
        }
        // `libc::CPU_SET` indexes an array of CPU_SETSIZE bits and panics beyond it: the config
        // refuses such CPUs, and an out-of-range index is a refusal here too, never a panic.
        if let Some(cpu) = t.cpu.filter(|&c| c >= libc::CPU_SETSIZE as usize) {
            refused.push(RtRefusal::Affinity {
                cpu,
                source: std::io::Error::from_raw_os_error(libc::EINVAL),
            });
        } else if let Some(cpu) = t.cpu {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            let ok = libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0;
            let mut got: libc::cpu_set_t = std::mem::zeroed();
            libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut got);
            if ok && libc::CPU_ISSET(cpu, &got) && libc::CPU_COUNT(&got) == 1 {
                flags |= STATUS_CPU_PINNED;
            } else {
                refused.push(RtRefusal::Affinity {
                    cpu,
                    source: std::io::Error::last_os_error(),
                });
            }
        }
        if let Some(prio) = t.priority {
            // Zeroed then set: musl's sched_param has extra (sporadic-server) fields glibc lacks.
            let mut sp: libc::sched_param = std::mem::zeroed();
            sp.sched_priority = prio;
            let rc = libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &sp);
            let mut pol = 0;
            let mut got: libc::sched_param = std::mem::zeroed();
            libc::pthread_getschedparam(libc::pthread_self(), &mut pol, &mut got);
            if rc == 0 && pol == libc::SCHED_FIFO && got.sched_priority == prio {
                flags |= STATUS_SCHED_FIFO;
            } else {
                refused.push(RtRefusal::SchedFifo {
                    priority: prio,
                    source: std::io::Error::from_raw_os_error(rc),
                });
            }
        }
        if t.lock_memory {
            // MCL_FUTURE under a finite RLIMIT_MEMLOCK makes later allocations past the limit fail:
            // only ask for it when the limit is unlimited (or we are root).
            let mut rl = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut rl);
            let future = rl.rlim_cur == libc::RLIM_INFINITY || libc::geteuid() == 0;
            let mcl = libc::MCL_CURRENT | if future { libc::MCL_FUTURE } else { 0 };
            if libc::mlockall(mcl) == 0 {
                flags |= STATUS_MEMORY_LOCKED;
                if !future {
                    tracing::warn!(
                        "mlockall: MCL_CURRENT only (RLIMIT_MEMLOCK is finite; set LimitMEMLOCK=infinity)"
                    );
                }
            } else {
                refused.push(RtRefusal::Mlockall(std::io::Error::last_os_error()));
            }
        }
    }
    flags
}

/// Touches `bytes` of stack so the loop never page-faults on it.
#[inline(never)]
pub(super) fn prefault_stack() {
    let mut buf = [0u8; 256 * 1024];
    for k in (0..buf.len()).step_by(4096) {
        buf[k] = 1;
    }
    std::hint::black_box(&mut buf);
}

/// The calling thread's scheduling policy and priority.
pub(super) fn sched_of_self() -> (i32, i32) {
    let mut pol = 0;
    // SAFETY: valid out-pointers for the calling thread.
    let mut sp: libc::sched_param = unsafe { std::mem::zeroed() };
    unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut pol, &mut sp) };
    (pol, sp.sched_priority)
}

/// Set-up on the RT thread: opens the backend (its iceoryx2 ports are `!Send`), applies the RT
/// settings, starts the helper thread of `rt_threads = 2` (same priority and memory locking,
/// `helper_cpu`; its refusals count like the main thread's), pre-faults the stack and reports the
/// outcome through `started`. `None` if set-up failed (the error went to `started`).
pub(super) fn start(
    config: &Config,
    shared: &Shared,
    started: &SyncSender<Result<u32, RtSetupError>>,
) -> Option<(AnyBackend, RtGrant, Option<Crew>)> {
    let backend = match AnyBackend::open(config) {
        Ok(b) => b,
        Err(source) => {
            let _ = started.send(Err(RtSetupError::Backend {
                kind: config.raw.backend.kind,
                source,
            }));
            return None;
        }
    };
    let mut grant = match apply_rt_settings(config) {
        Ok(g) => g,
        Err(e) => {
            let _ = started.send(Err(e));
            return None;
        }
    };
    let l = &config.raw.loop_;
    let crew = if l.rt_threads >= 2 {
        let rt = ThreadRt {
            cpu: l.helper_cpu,
            priority: l.priority,
            lock_memory: l.lock_memory,
        };
        match Crew::spawn(CrewPlan::of(config), rt) {
            Ok((crew, flags, refused)) => {
                for r in &refused {
                    tracing::warn!("RT setting refused (helper thread): {r}");
                }
                if l.require_rt && !refused.is_empty() {
                    let _ = started.send(Err(RtSetupError::RtRefused(refused)));
                    return None;
                }
                // A setting counts as granted only when both threads got it.
                let both = STATUS_SCHED_FIFO | STATUS_MEMORY_LOCKED;
                grant.flags &= flags | !both;
                if l.helper_cpu.is_some() && flags & STATUS_CPU_PINNED == 0 {
                    grant.flags &= !STATUS_CPU_PINNED;
                }
                Some(crew)
            }
            Err(e) => {
                let _ = started.send(Err(RtSetupError::Helper(e)));
                return None;
            }
        }
    } else {
        None
    };
    shared.rt_flags.store(grant.flags, Ordering::Relaxed);
    prefault_stack();
    let _ = started.send(Ok(grant.flags));
    Some((backend, grant, crew))
}
