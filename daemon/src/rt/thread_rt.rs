//! The RT settings of one thread, shared by the main RT thread ([`super::rt_setup`]) and the
//! helper of `rt_threads = 2` ([`super::crew`]): what is asked ([`ThreadRt`]), what the kernel
//! refused ([`RtRefusal`]), and the calls that apply, read back and pre-fault. Set-up only.

use frictionless_shm_types::{STATUS_CPU_PINNED, STATUS_MEMORY_LOCKED, STATUS_SCHED_FIFO};

/// RT settings of one thread (`[loop]` `cpu` / `helper_cpu`, `priority`, `lock_memory`).
#[derive(Debug, Clone, Copy, Default)]
pub struct ThreadRt {
    /// CPU to pin to.
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority.
    pub priority: Option<i32>,
    /// `mlockall` (again from this thread, so its stack is locked too).
    pub lock_memory: bool,
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
