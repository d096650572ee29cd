//! RT set-up: what the RT thread does before its first tick, and the RT settings of each thread.
//!
//! [`start`] runs on the RT thread: it opens the backend (its iceoryx2 ports are `!Send`), applies
//! the RT settings ([`apply_rt_settings`]: PM QoS, then `thread_rt`'s [`apply_thread_rt`]: timer slack, CPU
//! affinity, SCHED_FIFO, mlockall — each verified, refusals reported and fatal under
//! `require_rt`), starts the helper thread of `rt_threads = 2` and pre-faults the stack. Set-up
//! may allocate and log; nothing here runs per tick.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, SyncSender};

use frictionless_shm_types::{STATUS_CPU_PINNED, STATUS_MEMORY_LOCKED, STATUS_SCHED_FIFO};

use super::Shared;
use super::crew::{Crew, CrewPlan};
use super::thread_rt::{RtRefusal, ThreadRt, apply_thread_rt};
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
    super::thread_rt::prefault_stack();
    let _ = started.send(Ok(grant.flags));
    Some((backend, grant, crew))
}
