//! Two RT threads (`[loop] rt_threads = 2`): the helper thread and its deterministic join.
//!
//! Protocol (no locks, no allocation): the main RT thread writes a job (`JobIn`: the helper's joints
//! as a raw slice of the current `Params`, a copy of the inputs, the tick's context) only while the
//! helper is idle, then bumps `epoch` (and wakes the helper with a futex only if it parked; the
//! helper's timer wakes it `HELPER_EARLY_NS` before the deadline, so it is normally spinning). Whoever
//! first moves `claimed` from the previous epoch to the posted one runs the job: the helper when it
//! picks the job up, or the main thread itself when it has finished its own half and the helper has
//! not started (a helper whose timer wake came late on a busy or virtualised CPU), so a late wake
//! costs time, never outputs. The helper computes its half into `JobOut`, stores the epoch in `done`
//! (results ready), prefetches if configured, then stores it in `idle` (it no longer touches the job
//! or the joints); a helper that lost the claim touches neither. The main thread computes its own
//! half, then steals the job or spins for `done` until ¾ period after the wake (lockstep:
//! `lockstep_timeout_ms`), merges the helper's joints by index and publishes. Parameters are handed over (reload) only while the helper is idle,
//! so it never sees a half-swapped set; a helper that is late gets its joints published as 0 A +
//! FLAG_STALE, is not given a new job until idle (the next tick waits at most
//! `HELPER_RELEASE_GRACE_NS` for that, lockstep its full budget), and its joints get a bumpless reset
//! afterwards.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use frictionless_shm_types::{
    FLAG_DISABLED, FLAG_STALE, JointStates, MAX_JOINTS, MotorCurrentCommand, TorqueRequest,
    monotonic_ns, sleep_until_ns,
};

use super::stats::{HelperReport, ThreadUsage};
use super::thread_rt::{RtRefusal, ThreadRt, apply_thread_rt, prefault_stack, sched_of_self};
use super::{Freshness, Inputs, Latest, TickCtx, compute_joints};
use crate::alloc_count;
use crate::config::{Config, OnStale, Prefetch, Trigger};
use crate::params::{JointRt, Params};

/// How long the helper spins for the next job after its timer wake (or after a job, under
/// lockstep) before it parks on the futex [ns].
const HELPER_SPIN_NS: u64 = 100_000;

/// How long before the next deadline the helper's timer wakes it, so it is already spinning when
/// the job is posted rather than still coming out of its sleep (a helper that has not claimed the
/// job when the main thread finishes its own half loses it to the main thread) [ns].
const HELPER_EARLY_NS: u64 = 20_000;

/// Clock trigger: how long a tick waits for a helper that has not released the previous job before
/// it computes its own half without it (the helper's joints are then late again) [ns].
pub const HELPER_RELEASE_GRACE_NS: u64 = 50_000;

/// Longest single futex park of the helper, so a stop request is seen promptly [ns].
const HELPER_PARK_NS: u64 = 20_000_000;

/// The job the main RT thread posts (read by the helper between `epoch` and `idle`).
struct JobIn {
    joints: *mut JointRt,
    n: usize,
    inputs: Inputs,
    fresh: Freshness,
    enabled_now: u64,
    prev_active: u64,
    on_stale: OnStale,
    /// The tick's deadline (0 under lockstep): the helper's next wake is one period later.
    deadline_ns: u64,
    count_allocs: bool,
}

/// The helper's results (written by the helper before `done`, read by the main thread after it).
struct JobOut {
    i_a: [f64; MAX_JOINTS],
    flags: [u32; MAX_JOINTS],
    tau_f_nm: [f64; MAX_JOINTS],
    tau_f_model_nm: [f64; MAX_JOINTS],
    active: u64,
}

/// What the two RT threads share.
pub(super) struct Rendezvous {
    /// Job counter: bumped by the main thread to post a job (the futex word the helper parks on).
    epoch: AtomicU32,
    /// Epoch whose results are in `job_out`.
    done: AtomicU32,
    /// Epoch after which the helper no longer touches `job_in` or the joints.
    idle: AtomicU32,
    /// The helper is parked (or about to park) on `epoch`: the main thread must wake it.
    parked: AtomicU32,
    /// Epoch of the last job claimed — by the helper, or by the main thread running it itself.
    /// Every job is claimed before the next is posted, so a claim is `epoch − 1 → epoch`.
    claimed: AtomicU32,
    /// Tests: the helper waits before claiming while set (a helper that wakes late, on demand).
    #[cfg(test)]
    pub(super) hold: AtomicBool,
    /// End the helper (set before a last epoch bump).
    stop: AtomicBool,
    job_in: std::cell::UnsafeCell<JobIn>,
    job_out: std::cell::UnsafeCell<JobOut>,
}

// SAFETY: `job_in` is written by the main thread only while `idle == epoch` (the helper is not
// reading it) and read by the helper only between seeing a new `epoch` and storing `idle`; `job_out`
// is written by the helper only before it stores `done` and read by the main thread only after
// loading that `done` and before the next post. The epochs are Release/Acquire (SeqCst with
// `parked`), which orders every access. The joints behind `JobIn::joints` are `Send` (checked
// below) and touched by one thread at a time under the same rule.
unsafe impl Sync for Rendezvous {}
unsafe impl Send for Rendezvous {}

const _: fn() = || {
    fn send<T: Send>() {}
    send::<JointRt>();
};

/// `FUTEX_WAIT_PRIVATE` on `word` while it equals `expected`, at most `timeout_ns`.
fn futex_wait(word: &AtomicU32, expected: u32, timeout_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (timeout_ns / 1_000_000_000) as _,
        tv_nsec: (timeout_ns % 1_000_000_000) as _,
    };
    // SAFETY: `word` is a live, aligned u32; `ts` is a valid relative timeout. Spurious returns
    // (EAGAIN, EINTR, ETIMEDOUT) are fine: the caller re-checks the word.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAIT | libc::FUTEX_PRIVATE_FLAG,
            expected,
            &ts as *const libc::timespec,
            std::ptr::null::<u32>(),
            0u32,
        );
    }
}

/// `FUTEX_WAKE_PRIVATE`: wakes every waiter on `word`.
fn futex_wake(word: &AtomicU32) {
    // SAFETY: `word` is a live, aligned u32.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAKE | libc::FUTEX_PRIVATE_FLAG,
            i32::MAX,
        );
    }
}

/// How long a join spins before it yields the CPU between checks (the other thread may be waiting
/// for this CPU) [ns].
const JOIN_SPIN_NS: u64 = 50_000;

/// Spins until `word` holds `want` or the clock passes `by_ns` (after [`JOIN_SPIN_NS`] with a
/// `sched_yield` between checks); whether it got there.
#[inline]
fn spin_until_eq(word: &AtomicU32, want: u32, by_ns: u64) -> bool {
    let yield_after = monotonic_ns().saturating_add(JOIN_SPIN_NS);
    loop {
        if word.load(Ordering::Acquire) == want {
            return true;
        }
        let now = monotonic_ns();
        if now >= by_ns {
            return word.load(Ordering::Acquire) == want;
        }
        if now >= yield_after {
            std::thread::yield_now();
        } else {
            std::hint::spin_loop();
        }
    }
}

/// How the two RT threads run: budgets and the prefetch policy (from `[loop]`).
#[derive(Debug, Clone, Copy)]
pub struct CrewPlan {
    /// Loop period [ns].
    pub period_ns: u64,
    /// The join waits for the helper until this long after the wake [ns]: ¾ period in frictiond
    /// (clock trigger), `lockstep_timeout_ms` under lockstep (no deadline: a simulation waits).
    pub budget_ns: u64,
    /// A helper still holding the previous (late) job is waited for at most this long after the
    /// wake before this tick goes on without it [ns]: [`HELPER_RELEASE_GRACE_NS`] (clock trigger),
    /// `budget_ns` under lockstep.
    pub release_ns: u64,
    /// `[loop] prefetch`.
    pub prefetch: Prefetch,
    /// `[loop] prefetch_lead_us` [ns].
    pub lead_ns: u64,
    /// Lockstep trigger: no deadlines (the helper parks between jobs; `lead` acts as `after`).
    pub lockstep: bool,
}

impl CrewPlan {
    /// The plan `[loop]` asks for.
    pub fn of(config: &Config) -> Self {
        let l = &config.raw.loop_;
        let period_ns = config.period_ns();
        let lockstep = l.trigger == Trigger::Lockstep;
        let budget_ns = if lockstep {
            l.lockstep_timeout_ms.saturating_mul(1_000_000)
        } else {
            period_ns / 4 * 3
        };
        Self {
            period_ns,
            budget_ns,
            release_ns: if lockstep {
                budget_ns
            } else {
                HELPER_RELEASE_GRACE_NS.min(budget_ns)
            },
            prefetch: l.prefetch,
            lead_ns: l.prefetch_lead_us.saturating_mul(1000),
            lockstep,
        }
    }
}

/// The second RT thread of `[loop] rt_threads = 2` and the main thread's side of the join.
pub struct Crew {
    pub(super) ren: Arc<Rendezvous>,
    thread: Option<std::thread::JoinHandle<HelperReport>>,
    plan: CrewPlan,
    /// Epoch of the last job posted.
    posted: u32,
    /// A posted job the helper has not released (`idle != posted`).
    busy: bool,
    /// Ticks whose helper half was not done in time.
    late: u64,
    /// Ticks whose helper half this thread ran itself (the helper had not picked the job up).
    stolen: u64,
}

impl std::fmt::Debug for Crew {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Crew")
            .field("plan", &self.plan)
            .field("posted", &self.posted)
            .field("busy", &self.busy)
            .field("late", &self.late)
            .field("stolen", &self.stolen)
            .finish()
    }
}

impl Crew {
    /// Starts the helper thread with the RT settings `rt` (set-up: allocates). Returns the
    /// settings it was granted (`STATUS_*`) and the refusals, or why it could not start.
    pub fn spawn(plan: CrewPlan, rt: ThreadRt) -> std::io::Result<(Self, u32, Vec<RtRefusal>)> {
        let ren = Arc::new(Rendezvous {
            epoch: AtomicU32::new(0),
            done: AtomicU32::new(0),
            idle: AtomicU32::new(0),
            parked: AtomicU32::new(0),
            claimed: AtomicU32::new(0),
            #[cfg(test)]
            hold: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            job_in: std::cell::UnsafeCell::new(JobIn {
                joints: std::ptr::null_mut(),
                n: 0,
                inputs: Inputs {
                    states: Latest::new(JointStates::zeroed()),
                    request: Latest::new(TorqueRequest::zeroed()),
                },
                fresh: Freshness {
                    state_stale: true,
                    request_stale: true,
                },
                enabled_now: 0,
                prev_active: 0,
                on_stale: OnStale::Zero,
                deadline_ns: 0,
                count_allocs: false,
            }),
            job_out: std::cell::UnsafeCell::new(JobOut {
                i_a: [0.0; MAX_JOINTS],
                flags: [0; MAX_JOINTS],
                tau_f_nm: [0.0; MAX_JOINTS],
                tau_f_model_nm: [0.0; MAX_JOINTS],
                active: 0,
            }),
        });
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        let r = ren.clone();
        let thread = std::thread::Builder::new()
            .name("frictiond-rt2".into())
            .stack_size(2 << 20)
            .spawn(move || {
                let mut refused = Vec::new();
                let flags = apply_thread_rt(rt, &mut refused);
                prefault_stack();
                let _ = tx.send((flags, refused));
                helper_main(&r, plan, flags)
            })?;
        let (flags, refused) = rx
            .recv()
            .map_err(|_| std::io::Error::other("the helper RT thread ended during set-up"))?;
        Ok((
            Self {
                ren,
                thread: Some(thread),
                plan,
                posted: 0,
                busy: false,
                late: 0,
                stolen: 0,
            },
            flags,
            refused,
        ))
    }

    /// Ticks whose helper half was not done within the budget (published as 0 A + FLAG_STALE).
    pub fn late_ticks(&self) -> u64 {
        self.late
    }

    /// Ticks whose helper half the main RT thread computed itself because the helper had not
    /// started it when the main half was done (same outputs; the tick took longer).
    pub fn stolen_ticks(&self) -> u64 {
        self.stolen
    }

    /// Waits (spinning, until `by_ns`) for the helper to release its last job; `true` when it has
    /// (then the parameters may be swapped and a new job posted).
    #[inline]
    pub fn release(&mut self, by_ns: u64) -> bool {
        if self.busy && spin_until_eq(&self.ren.idle, self.posted, by_ns) {
            self.busy = false;
        }
        !self.busy
    }

    /// Task 3 on two threads: posts `p.joints[p.split..]` to the helper, computes
    /// `p.joints[..p.split]` here, joins (until `wake_ns` + the budget) and merges by joint index.
    /// Output bit for bit that of [`compute`](super::compute). Returns whether the helper's half was on time; if
    /// not, its enabled joints are 0 A with `FLAG_STALE` (disabled ones `FLAG_DISABLED`) and get a
    /// bumpless reset when they are back. `deadline_ns` is the tick's deadline (0 under lockstep).
    #[allow(clippy::too_many_arguments)] // compute's arguments plus the tick's times
    #[inline]
    pub fn compute(
        &mut self,
        p: &mut Params,
        inp: &Inputs,
        fresh: Freshness,
        prev_active: &mut u64,
        cmd: &mut MotorCurrentCommand,
        tau_f_out: &mut [f64; MAX_JOINTS],
        wake_ns: u64,
        deadline_ns: u64,
    ) -> bool {
        let by_ns = wake_ns.saturating_add(self.plan.budget_ns);
        let release_by_ns = wake_ns.saturating_add(self.plan.release_ns);
        let cx = TickCtx::begin(p, inp, fresh, *prev_active, cmd);
        let n = p.joints.len();
        let split = p.split.min(n);
        // Raw halves: the helper may still hold a late job's half (then it is not reposted and
        // this thread never touches it); `as_mut_ptr` creates no reference to the whole buffer.
        let base = p.joints.as_mut_ptr();
        let posted = split < n && self.release(release_by_ns) && {
            // SAFETY: the helper is idle (released the previous job), so it reads nothing here.
            let job = unsafe { &mut *self.ren.job_in.get() };
            // SAFETY: `split <= n`: the pointer stays inside (or one past) the joints buffer.
            job.joints = unsafe { base.add(split) };
            job.n = n - split;
            job.inputs = *inp;
            job.fresh = fresh;
            job.enabled_now = cx.enabled_now;
            job.prev_active = cx.prev_active;
            job.on_stale = cx.on_stale;
            job.deadline_ns = deadline_ns;
            job.count_allocs = alloc_count::counting();
            self.posted = self.posted.wrapping_add(1);
            self.busy = true;
            self.ren.epoch.store(self.posted, Ordering::SeqCst);
            if self.ren.parked.load(Ordering::SeqCst) != 0 {
                futex_wake(&self.ren.epoch);
            }
            true
        };
        // SAFETY: `joints[..split]` is this thread's half; the helper only ever gets `[split..]`.
        let mine = unsafe { std::slice::from_raw_parts_mut(base, split) };
        let mut active = compute_joints(
            mine,
            &cx,
            &mut cmd.i_ref_a,
            &mut cmd.flags,
            tau_f_out,
            &mut cmd.tau_f_model_nm,
        );
        // The helper has not claimed the job: run its half here (it will never touch this job).
        let stolen = posted
            && self.ren.done.load(Ordering::Acquire) != self.posted
            && self
                .ren
                .claimed
                .compare_exchange(
                    self.posted.wrapping_sub(1),
                    self.posted,
                    Ordering::AcqRel,
                    Ordering::Acquire,
                )
                .is_ok();
        let mut bits = p.helper_mask;
        if stolen {
            self.busy = false;
            self.stolen += 1;
            // SAFETY: the claim is ours, so the helper never reads this job or `joints[split..]`;
            // `split < n` because a job was posted.
            let theirs = unsafe { std::slice::from_raw_parts_mut(base.add(split), n - split) };
            *prev_active = active
                | compute_joints(
                    theirs,
                    &cx,
                    &mut cmd.i_ref_a,
                    &mut cmd.flags,
                    tau_f_out,
                    &mut cmd.tau_f_model_nm,
                );
            return true;
        }
        let on_time = posted && spin_until_eq(&self.ren.done, self.posted, by_ns);
        if on_time {
            // SAFETY: `done == posted` (Acquire): the helper finished writing `job_out`.
            let out = unsafe { &*self.ren.job_out.get() };
            while bits != 0 {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                cmd.i_ref_a[k] = out.i_a[k];
                cmd.flags[k] = out.flags[k];
                tau_f_out[k] = out.tau_f_nm[k];
                cmd.tau_f_model_nm[k] = out.tau_f_model_nm[k];
            }
            active |= out.active;
        } else {
            while bits != 0 {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let flag = if cx.enabled_now & (1 << k) != 0 {
                    FLAG_STALE
                } else {
                    FLAG_DISABLED
                };
                cmd.i_ref_a[k] = 0.0;
                cmd.flags[k] = flag;
                tau_f_out[k] = 0.0;
                cmd.tau_f_model_nm[k] = 0.0;
            }
            if split < n {
                self.late += 1;
            }
        }
        *prev_active = active;
        on_time || split >= n
    }

    /// Whether the helper holds a job it has not released (its joints must not be touched).
    pub fn busy(&self) -> bool {
        self.busy
    }

    /// Stops and joins the helper (waits for its current job); its report.
    pub fn stop(mut self) -> HelperReport {
        self.stop_inner().unwrap_or_default()
    }

    fn stop_inner(&mut self) -> Option<HelperReport> {
        let t = self.thread.take()?;
        self.ren.stop.store(true, Ordering::SeqCst);
        self.ren.epoch.fetch_add(1, Ordering::SeqCst);
        futex_wake(&self.ren.epoch);
        t.join().ok()
    }
}

impl Drop for Crew {
    fn drop(&mut self) {
        // The helper may hold pointers into the caller's parameters: it ends before they can go.
        let _ = self.stop_inner();
    }
}

/// Walks the networks of `joints` into cache, last joint first (so the first ones computed are the
/// most recently fetched). Allocation-free.
#[inline]
pub fn prefetch_joints(joints: &[JointRt]) {
    for j in joints.iter().rev() {
        j.model.prefetch();
    }
}

/// The helper thread's loop: wait for a job (timer to the next deadline, spin, then park), compute
/// its half, report `done`, prefetch per the plan, report `idle`.
fn helper_main(ren: &Rendezvous, plan: CrewPlan, rt_flags: u32) -> HelperReport {
    let usage_start = ThreadUsage::now();
    let mut seen = 0u32;
    let mut wake_at_ns = 0u64;
    let mut jobs = 0u64;
    loop {
        if wake_at_ns != 0 {
            sleep_until_ns(wake_at_ns);
        }
        let mut spin_end = monotonic_ns() + HELPER_SPIN_NS;
        let epoch = loop {
            let e = ren.epoch.load(Ordering::Acquire);
            if e != seen {
                break e;
            }
            if monotonic_ns() < spin_end {
                std::hint::spin_loop();
                continue;
            }
            ren.parked.store(1, Ordering::SeqCst);
            if ren.epoch.load(Ordering::SeqCst) == seen {
                futex_wait(&ren.epoch, seen, HELPER_PARK_NS);
            }
            ren.parked.store(0, Ordering::SeqCst);
            spin_end = 0;
        };
        if ren.stop.load(Ordering::SeqCst) {
            break;
        }
        seen = epoch;
        #[cfg(test)]
        while ren.hold.load(Ordering::Acquire) && !ren.stop.load(Ordering::Acquire) {
            std::hint::spin_loop();
        }
        if ren
            .claimed
            .compare_exchange(
                epoch.wrapping_sub(1),
                epoch,
                Ordering::AcqRel,
                Ordering::Acquire,
            )
            .is_err()
        {
            // The main thread ran this job itself: nothing of it is ours. Wait for the next post.
            wake_at_ns = 0;
            continue;
        }
        jobs += 1;
        // SAFETY: a new epoch: the main thread wrote the job and will not touch it (or the joints
        // it points to) until `idle == seen`.
        let job = unsafe { &*ren.job_in.get() };
        alloc_count::set_counting(job.count_allocs);
        // SAFETY: `joints[..n]` is the helper's half of live parameters, kept alive and untouched by
        // the main thread until `idle == seen`.
        let joints = unsafe { std::slice::from_raw_parts_mut(job.joints, job.n) };
        // SAFETY: the main thread reads `job_out` only after `done == seen`.
        let out = unsafe { &mut *ren.job_out.get() };
        let cx = TickCtx {
            st: &job.inputs.states.value,
            rq: &job.inputs.request.value,
            enabled_now: job.enabled_now,
            fresh: job.fresh,
            on_stale: job.on_stale,
            prev_active: job.prev_active,
        };
        out.active = compute_joints(
            joints,
            &cx,
            &mut out.i_a,
            &mut out.flags,
            &mut out.tau_f_nm,
            &mut out.tau_f_model_nm,
        );
        ren.done.store(seen, Ordering::Release);
        let next_ns = if plan.lockstep || job.deadline_ns == 0 {
            0
        } else {
            job.deadline_ns + plan.period_ns
        };
        match plan.prefetch {
            Prefetch::Off => {}
            Prefetch::After => prefetch_joints(joints),
            Prefetch::Lead => {
                if next_ns > plan.lead_ns {
                    sleep_until_ns(next_ns - plan.lead_ns);
                }
                prefetch_joints(joints);
            }
        }
        ren.idle.store(seen, Ordering::Release);
        wake_at_ns = if next_ns == 0 {
            0
        } else {
            next_ns.saturating_sub(HELPER_EARLY_NS).max(1)
        };
    }
    alloc_count::set_counting(false);
    let (policy, priority) = sched_of_self();
    HelperReport {
        rt_flags,
        policy,
        priority,
        jobs,
        usage: ThreadUsage::now().since(usage_start),
    }
}
