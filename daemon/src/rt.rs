//! THE RT TICK: the time-triggered control thread, top to bottom in one module.
//!
//! What this module **is**: the dedicated loop thread. Set-up (allowed to allocate and log): open the
//! backend (iceoryx2 node and ports are `!Send`, so they are created here), apply RT settings
//! (timer slack, CPU affinity, SCHED_FIFO, mlockall — each verified, refusals reported), pre-fault
//! the stack. Then, every tick, one path for both triggers (`[loop] trigger`):
//!
//! 0. wait — `clock`: until the next absolute CLOCK_MONOTONIC deadline (`clock_nanosleep` with
//!    `TIMER_ABSTIME`); `lockstep`: until a joint state newer than the last processed one has
//!    arrived and, with `lockstep_wait_request`, the [`TorqueRequest`] whose `state_seq` answers
//!    it (or `lockstep_timeout_ms` passed: the tick runs anyway and the missing input is stale);
//! 1. [`Inputs::poll`]: newest [`JointStates`] and [`TorqueRequest`] (latest value), freshness by
//!    `seq` and `stamp_ns` (lockstep: by `seq` and the timeout, since its time is not wall time);
//! 2. parameter hand-over: `try_recv` a new `Box<Params>` (built off-thread), send the old one back
//!    to be freed off-thread;
//! 3. [`compute`]: per joint, enable edge → reset (bumpless), model estimate, out-of-training-range
//!    check of the newest sample (`FLAG_OUT_OF_RANGE`; under `ood = "static"` the estimate ramps to
//!    the joint's static model, see [`crate::params::OodRt`]), control law
//!    ([`frictionless::law`], its [`LawFlags`] mapped to the ABI's `FLAG_*` by [`abi_flags`]),
//!    stale/fault/NaN handling → [`MotorCurrentCommand`];
//! 4. publish (+ notify); record lateness / compute time / input age in fixed histograms and the
//!    out-of-range ticks per joint;
//!    publish [`DaemonStatus`] every `status_every_ticks`; advance the heartbeat.
//!
//! With `[loop] rt_threads = 2`, step 3 is [`Crew::compute`]: the joints were split at load into two
//! halves balanced by weight bytes ([`Params::split_threads`]); this thread posts the second half to
//! the helper thread (its loop, `helper_main`, is in this module too), computes the first with the
//! same [`compute_joints`], waits for the helper (bounded: ¾ period after the wake, under lockstep
//! `lockstep_timeout_ms`; else its joints are published as 0 A + `FLAG_STALE`) and merges by joint
//! index — bit for bit the output of one thread. Step 2 hands parameters over only while the helper holds no job. With `[loop] prefetch`,
//! each thread walks its half's network weights into cache after publishing (`"after"`) or
//! `prefetch_lead_us` before the next deadline (`"lead"`, inside step 0's sleep).
//!
//! [`run`] reads top to bottom as these steps, each a named function or method in this module
//! (`wait_for_tick`, `ParamSlot::hand_over`, `Freshness::judge`, [`compute`], `Telemetry::record`
//! / `Telemetry::publish`, `next_deadline`), then `publish_stop` on the way out.
//!
//! Lockstep has no deadline: its lateness histograms stay empty and `missed_deadlines` stays 0;
//! compute time and input age (plant publish → daemon wake) are recorded as usual. A joint whose
//! PINN history is not full yet carries `FLAG_WARMING_UP`.
//!
//! No allocation, no locks, no logging, no blocking syscall other than the wait in step 0. The
//! only heap allocation is inside iceoryx2's `loan` (one 48-byte `Box` per published sample,
//! measured); it is wrapped in [`crate::alloc_count::exempt`] so the allocation test can tell it apart.
//!
//! What it is **not**: no config parsing, no signals, no systemd (the supervisor in `main.rs`).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError};

use frictionless::features::JointSample;
use frictionless::law::{LawFlags, LawInput, LawOutput};
use frictionless::model::{FrictionModel, JointModel};
use frictionless_shm_types::{
    DaemonStatus, FAULT_FEEDBACK_STALE, FLAG_CURRENT_SATURATED, FLAG_DISABLED, FLAG_FAULT,
    FLAG_FRICTION_CLIPPED, FLAG_NON_FINITE, FLAG_OUT_OF_RANGE, FLAG_STALE, FLAG_WARMING_UP,
    JointStates, MAX_JOINTS, MotorCurrentCommand, STATUS_CPU_PINNED, STATUS_INPUT_STALE,
    STATUS_MEMORY_LOCKED, STATUS_SCHED_FIFO, STATUS_STOPPING, TorqueRequest, monotonic_ns,
    sleep_until_ns,
};

use crate::alloc_count;
use crate::backend::{AnyBackend, Backend, BackendError};
use crate::config::{BackendKind, Config, OnStale, Prefetch, Trigger};
use crate::params::{JointRt, Params};

/// State shared between the RT thread and the supervisor (atomics only).
#[derive(Debug, Default)]
pub struct Shared {
    /// Set by the supervisor to end the loop (zero currents are published on the way out).
    pub stop: AtomicBool,
    /// Ticks completed (the heartbeat the watchdog checks).
    pub heartbeat: AtomicU64,
    /// Missed deadlines (whole periods skipped).
    pub missed: AtomicU64,
    /// p99 wake lateness upper bound [ns] (updated with each status publish).
    pub lateness_p99_ns: AtomicU64,
    /// Max wake lateness [ns].
    pub lateness_max_ns: AtomicU64,
    /// Generation of the parameters in use.
    pub generation: AtomicU64,
    /// RT settings granted (`STATUS_*` bits).
    pub rt_flags: AtomicU32,
    /// Ticks during which RT-thread allocations were counted.
    pub counted_ticks: AtomicU64,
    /// Whether the last tick's input (joint states or torque request) was stale.
    pub input_stale: AtomicBool,
    /// Stale episodes so far (fresh → stale transitions, the start counting as one): the supervisor
    /// logs entries and recoveries from this and [`Shared::input_stale`] (the RT thread never logs).
    pub stale_episodes: AtomicU64,
    /// Ticks whose helper half (`rt_threads = 2`) was late and published as 0 A + `FLAG_STALE`.
    pub helper_late: AtomicU64,
}

/// Newest value of one input with its freshness.
#[derive(Debug, Clone, Copy)]
pub struct Latest<T> {
    /// The value (meaningful only when `have`).
    pub value: T,
    /// Whether any value arrived yet.
    pub have: bool,
    /// Tick at which a new `seq` last arrived.
    pub new_at_tick: u64,
}

impl<T: Copy> Latest<T> {
    fn new(zero: T) -> Self {
        Self {
            value: zero,
            have: false,
            new_at_tick: 0,
        }
    }

    fn update(&mut self, v: Option<T>, tick: u64) {
        if let Some(v) = v {
            self.value = v;
            self.have = true;
            self.new_at_tick = tick;
        }
    }

    /// Stale: none yet, no new sample for more than `after` ticks, or stamp older than `after`
    /// periods.
    fn stale(&self, tick: u64, now_ns: u64, stamp_ns: u64, after: u64, period_ns: u64) -> bool {
        self.stale_by_ticks(tick, after)
            || now_ns.saturating_sub(stamp_ns) > after.saturating_mul(period_ns)
    }

    /// Stale by the sequence rule only: none yet, or no new sample for more than `after` ticks.
    fn stale_by_ticks(&self, tick: u64, after: u64) -> bool {
        !self.have || tick.saturating_sub(self.new_at_tick) > after
    }

    /// Whether a new sample arrived during tick `tick` (since the previous tick's poll).
    fn new_in(&self, tick: u64) -> bool {
        self.have && self.new_at_tick == tick
    }
}

/// Task 1: the inputs.
#[derive(Debug, Clone, Copy)]
pub struct Inputs {
    /// Joint states.
    pub states: Latest<JointStates>,
    /// Torque request.
    pub request: Latest<TorqueRequest>,
}

impl Inputs {
    /// Drains the backend (latest value) for this tick. Receive errors keep the old value.
    pub fn poll(&mut self, b: &mut impl Backend, tick: u64) {
        self.states.update(b.read_states().ok().flatten(), tick);
        self.request.update(b.read_request().ok().flatten(), tick);
    }
}

/// Per-tick freshness verdict.
#[derive(Debug, Clone, Copy)]
pub struct Freshness {
    /// Joint states stale.
    pub state_stale: bool,
    /// Torque request stale.
    pub request_stale: bool,
}

/// Task 3: computes the command for one tick on the calling thread, every joint. Pure apart from
/// the models' and laws' own state. (With `[loop] rt_threads = 2` the loop runs [`Crew::compute`]
/// instead, which runs the same [`compute_joints`] on two threads.)
///
/// `prev_active` holds the joints that ran the normal (model + law) path last tick: a joint entering
/// it — enable edge, or first fresh state after a stale/fault gap — gets a bumpless reset (model
/// history and law state), since its history no longer describes the last ticks.
#[inline]
pub fn compute(
    p: &mut Params,
    inp: &Inputs,
    fresh: Freshness,
    prev_active: &mut u64,
    cmd: &mut MotorCurrentCommand,
    tau_f_out: &mut [f64; MAX_JOINTS],
) {
    let cx = TickCtx::begin(p, inp, fresh, *prev_active, cmd);
    *prev_active = compute_joints(
        &mut p.joints,
        &cx,
        &mut cmd.i_ref_a,
        &mut cmd.flags,
        tau_f_out,
    );
}

/// What every joint of one tick reads, the same on both RT threads.
#[derive(Debug, Clone, Copy)]
pub struct TickCtx<'a> {
    st: &'a JointStates,
    rq: &'a TorqueRequest,
    enabled_now: u64,
    fresh: Freshness,
    on_stale: OnStale,
    prev_active: u64,
}

impl<'a> TickCtx<'a> {
    /// The tick's enable mask and the command's header (valid mask, joint count, state stamp/seq).
    #[inline]
    fn begin(
        p: &Params,
        inp: &'a Inputs,
        fresh: Freshness,
        prev_active: u64,
        cmd: &mut MotorCurrentCommand,
    ) -> Self {
        let st = &inp.states.value;
        let rq = &inp.request.value;
        let enabled_now = if inp.request.have {
            rq.enable_mask & p.configured_mask
        } else {
            0
        };
        cmd.valid_mask = enabled_now;
        cmd.n_joints = p.joints.len() as u32;
        cmd.state_stamp_ns = if inp.states.have { st.stamp_ns } else { 0 };
        cmd.state_seq = if inp.states.have { st.seq } else { 0 };
        Self {
            st,
            rq,
            enabled_now,
            fresh,
            on_stale: p.on_stale,
            prev_active,
        }
    }
}

/// Task 3 for a set of joints (all of them, or one RT thread's half): per joint, enable edge →
/// reset, model, range check, law, stale/fault/NaN handling, written at the joint's index into
/// `i_a`, `flags` and `tau_f_out`. Returns the bits of the joints that ran the normal path.
#[inline]
pub fn compute_joints(
    joints: &mut [JointRt],
    cx: &TickCtx<'_>,
    i_a: &mut [f64; MAX_JOINTS],
    flags: &mut [u32; MAX_JOINTS],
    tau_f_out: &mut [f64; MAX_JOINTS],
) -> u64 {
    let (st, rq, fresh) = (cx.st, cx.rq, cx.fresh);
    let mut active = 0u64;
    for j in joints.iter_mut() {
        let k = j.index;
        let bit = 1u64 << k;
        let out = if cx.enabled_now & bit == 0 {
            JointOut::zero(FLAG_DISABLED)
        } else if fresh.request_stale || (k as u32) >= rq.n_joints {
            JointOut::zero(FLAG_STALE)
        } else if fresh.state_stale
            || (k as u32) >= st.n_joints
            || st.fault_flags[k] == FAULT_FEEDBACK_STALE
        {
            // Whole-state staleness, or this joint's drive fell silent on a field bus (the CAN
            // backend marks it with FAULT_FEEDBACK_STALE alone): the configured safe output. A
            // drive fault reported alongside wins (the fault branch below).
            match cx.on_stale {
                OnStale::Zero => JointOut::zero(FLAG_STALE),
                OnStale::StaticModel => {
                    JointOut::from_law(j.law.feed_forward_only(rq.tau_des_nm[k]), FLAG_STALE)
                }
            }
        } else if st.fault_flags[k] & !FAULT_FEEDBACK_STALE != 0 {
            j.law.reset();
            JointOut::zero(FLAG_FAULT)
        } else {
            let sample = JointSample {
                s_rad: st.s_rad[k],
                sdot_rad_s: st.sdot_rad_s[k],
                theta_motor_rad: st.theta_motor_rad[k],
                omega_motor_rad_s: st.omega_motor_rad_s[k],
                temperature_c: st.temperature_c[k],
            };
            if cx.prev_active & bit == 0 {
                // Bumpless enable: fresh history and filter state.
                j.model.reset(&sample);
                j.law.reset();
                j.ood.reset();
            }
            active |= bit;
            let model_nm = j.model.estimate(&sample);
            // Out of the training range: flagged, counted (Telemetry::record) and, with a static
            // model configured, blended to it over the ramp.
            let ood = j.ood.out_of_range(&j.model, &sample);
            let f = j.ood.blend(model_nm, ood, &sample);
            let o = j.law.step(&LawInput {
                tau_des_nm: rq.tau_des_nm[k],
                friction_nm: f,
                sdot_rad_s: sample.sdot_rad_s,
                tau_meas_nm: st.tau_meas_nm[k],
            });
            let warming = if warming_up(&j.model) {
                FLAG_WARMING_UP
            } else {
                0
            };
            let ood_flag = if ood { FLAG_OUT_OF_RANGE } else { 0 };
            JointOut::from_law(o, warming | ood_flag)
        };
        i_a[k] = out.i_a;
        flags[k] = out.flags;
        tau_f_out[k] = out.tau_f_hat_nm;
    }
    active
}

/// Whether a PINN joint's feature history is not full yet (its estimate is a warm-up 0 under
/// `hold_zero`, or partly zero-padded under `zero_pad`). Static models never warm up.
#[inline]
pub fn warming_up(m: &JointModel) -> bool {
    match m {
        JointModel::Pinn(p) => !p.history().is_full(),
        _ => false,
    }
}

/// The ABI's `FLAG_*` bits of one tick of the law (the bit values are the ABI's, unchanged).
#[inline]
pub fn abi_flags(f: LawFlags) -> u32 {
    let mut bits = 0;
    if f.friction_clipped {
        bits |= FLAG_FRICTION_CLIPPED;
    }
    if f.current_saturated {
        bits |= FLAG_CURRENT_SATURATED;
    }
    if f.non_finite {
        bits |= FLAG_NON_FINITE;
    }
    bits
}

/// One joint's slot of the command for this tick.
#[derive(Debug, Clone, Copy)]
struct JointOut {
    i_a: f64,
    tau_f_hat_nm: f64,
    flags: u32,
}

impl JointOut {
    /// Zero current, no compensation, `flags`.
    #[inline]
    fn zero(flags: u32) -> Self {
        Self {
            i_a: 0.0,
            tau_f_hat_nm: 0.0,
            flags,
        }
    }

    /// The law's output with its flags mapped to the ABI, plus `extra` `FLAG_*` bits.
    #[inline]
    fn from_law(o: LawOutput, extra: u32) -> Self {
        Self {
            i_a: o.i_a,
            tau_f_hat_nm: o.tau_f_hat_nm,
            flags: abi_flags(o.flags) | extra,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Two RT threads (`[loop] rt_threads = 2`): the helper thread and its deterministic join.
//
// Protocol (no locks, no allocation): the main RT thread writes a job (`JobIn`: the helper's joints
// as a raw slice of the current `Params`, a copy of the inputs, the tick's context) only while the
// helper is idle, then bumps `epoch` (and wakes the helper with a futex only if it parked; the
// helper's timer wakes it `HELPER_EARLY_NS` before the deadline, so it is normally spinning). Whoever
// first moves `claimed` from the previous epoch to the posted one runs the job: the helper when it
// picks the job up, or the main thread itself when it has finished its own half and the helper has
// not started (a helper whose timer wake came late on a busy or virtualised CPU), so a late wake
// costs time, never outputs. The helper computes its half into `JobOut`, stores the epoch in `done`
// (results ready), prefetches if configured, then stores it in `idle` (it no longer touches the job
// or the joints); a helper that lost the claim touches neither. The main thread computes its own
// half, then steals the job or spins for `done` until ¾ period after the wake (lockstep:
// `lockstep_timeout_ms`), merges the helper's joints by index and publishes. Parameters are handed over (reload) only while the helper is idle,
// so it never sees a half-swapped set; a helper that is late gets its joints published as 0 A +
// FLAG_STALE, is not given a new job until idle (the next tick waits at most
// `HELPER_RELEASE_GRACE_NS` for that, lockstep its full budget), and its joints get a bumpless reset
// afterwards.
// ---------------------------------------------------------------------------------------------

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
    active: u64,
}

/// What the two RT threads share.
struct Rendezvous {
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
    hold: AtomicBool,
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

/// The second RT thread of `[loop] rt_threads = 2` and the main thread's side of the join.
pub struct Crew {
    ren: Arc<Rendezvous>,
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
    /// Output bit for bit that of [`compute`]. Returns whether the helper's half was on time; if
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
        let mut active = compute_joints(mine, &cx, &mut cmd.i_ref_a, &mut cmd.flags, tau_f_out);
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
            *prev_active =
                active | compute_joints(theirs, &cx, &mut cmd.i_ref_a, &mut cmd.flags, tau_f_out);
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
        out.active = compute_joints(joints, &cx, &mut out.i_a, &mut out.flags, &mut out.tau_f_nm);
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
struct RtGrant {
    /// Granted `STATUS_*` flags.
    flags: u32,
    /// The open `/dev/cpu_dma_latency` holding the PM QoS request (dropped = released).
    _pm_qos: Option<std::fs::File>,
    /// The PM QoS value read back from `/dev/cpu_dma_latency` [µs], when held.
    pm_qos_us: Option<i32>,
}

/// `[loop] cpu_dma_latency_us`: writes the bound to `/dev/cpu_dma_latency` and keeps the file open
/// (the kernel drops the request on close), then reads the effective value back.
fn hold_cpu_dma_latency(us: u32) -> std::io::Result<(std::fs::File, i32)> {
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
fn apply_rt_settings(cfg: &Config) -> Result<RtGrant, RtSetupError> {
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
fn apply_thread_rt(t: ThreadRt, refused: &mut Vec<RtRefusal>) -> u32 {
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
fn prefault_stack() {
    let mut buf = [0u8; 256 * 1024];
    for k in (0..buf.len()).step_by(4096) {
        buf[k] = 1;
    }
    std::hint::black_box(&mut buf);
}

/// How a lockstep wait ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LockstepWake {
    /// A new state (and, if required, its request) arrived.
    Inputs,
    /// `lockstep_timeout_ms` passed first: the tick runs anyway with what it has.
    TimedOut,
    /// The supervisor asked to stop.
    Stop,
}

/// Longest single block inside a lockstep wait, so a stop request is seen promptly [ns].
const LOCKSTEP_STOP_POLL_NS: u64 = 20_000_000;

/// The lockstep trigger's wait (the only step that differs from the clock trigger): polls the
/// inputs into `inputs` (as tick `tick`) until a joint state newer than the last processed one
/// has arrived and — if `wait_request` — a request whose `state_seq` equals that state's `seq`;
/// blocks on the backend between polls (on the listener of the input still missing). No
/// allocation (per-listener `timed_wait`, not a WaitSet, which allocates per wake-up).
fn wait_lockstep(
    b: &mut impl Backend,
    inputs: &mut Inputs,
    tick: u64,
    stop: &AtomicBool,
    wait_request: bool,
    timeout_ns: u64,
) -> LockstepWake {
    let end = monotonic_ns().saturating_add(timeout_ns);
    loop {
        inputs.poll(b, tick);
        let new_state = inputs.states.new_in(tick);
        let answered = !wait_request
            || (inputs.request.have && inputs.request.value.state_seq == inputs.states.value.seq);
        if new_state && answered {
            return LockstepWake::Inputs;
        }
        if stop.load(Ordering::Relaxed) {
            return LockstepWake::Stop;
        }
        let now = monotonic_ns();
        if now >= end {
            return LockstepWake::TimedOut;
        }
        let slice = (end - now).min(LOCKSTEP_STOP_POLL_NS);
        let waited = if new_state {
            b.wait_request(slice)
        } else {
            b.wait_input(slice)
        };
        if waited.is_err() {
            // A failing listener must not turn this into a busy loop.
            sleep_until_ns(monotonic_ns() + 100_000);
        }
    }
}

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

/// The calling thread's scheduling policy and priority.
fn sched_of_self() -> (i32, i32) {
    let mut pol = 0;
    // SAFETY: valid out-pointers for the calling thread.
    let mut sp: libc::sched_param = unsafe { std::mem::zeroed() };
    unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut pol, &mut sp) };
    (pol, sp.sched_priority)
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

/// Loop constants, read from `[loop]` once before the first tick.
#[derive(Debug, Clone, Copy)]
struct LoopPlan {
    period_ns: u64,
    status_every: u64,
    /// First tick whose allocations are counted (`ready_after_ticks`).
    count_from_tick: u64,
    lockstep: bool,
    wait_request: bool,
    lockstep_timeout_ns: u64,
}

impl LoopPlan {
    fn of(config: &Config) -> Self {
        let l = &config.raw.loop_;
        Self {
            period_ns: config.period_ns(),
            status_every: l.status_every_ticks,
            count_from_tick: l.ready_after_ticks,
            lockstep: l.trigger == Trigger::Lockstep,
            wait_request: l.lockstep_wait_request,
            lockstep_timeout_ns: l.lockstep_timeout_ms.saturating_mul(1_000_000),
        }
    }
}

/// Set-up on the RT thread: opens the backend (its iceoryx2 ports are `!Send`), applies the RT
/// settings, starts the helper thread of `rt_threads = 2` (same priority and memory locking,
/// `helper_cpu`; its refusals count like the main thread's), pre-faults the stack and reports the
/// outcome through `started`. `None` if set-up failed (the error went to `started`).
fn start(
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

/// The main RT thread's half, `p.joints[..p.split]`, without a reference to the helper's half
/// (which a late helper may still hold).
#[inline]
pub fn main_half(p: &Params) -> &[JointRt] {
    joints_prefix(p, p.split)
}

/// `joints[..n]` of `p` without a reference to the rest of the buffer (the helper may hold
/// `joints[split..]`).
#[inline]
fn joints_prefix(p: &Params, n: usize) -> &[JointRt] {
    // SAFETY: `as_ptr` creates no reference to the buffer; `n` is clamped to the length; the
    // prefix is not mutated while the returned borrow of `p` lives.
    unsafe { std::slice::from_raw_parts(p.joints.as_ptr(), n.min(p.joints.len())) }
}

/// Step 0 of the clock trigger: sleeps until `deadline_ns`; with `prefetch = "lead"` it wakes
/// `lead_ns` earlier to walk `joints` (this thread's half) into cache first (skipped when that
/// moment has passed).
#[inline]
pub fn sleep_to_deadline(deadline_ns: u64, prefetch: Prefetch, lead_ns: u64, joints: &[JointRt]) {
    if prefetch == Prefetch::Lead && deadline_ns > lead_ns {
        let at = deadline_ns - lead_ns;
        if monotonic_ns() < at {
            sleep_until_ns(at);
            prefetch_joints(joints);
        }
    }
    sleep_until_ns(deadline_ns);
}

/// After publishing: with `prefetch = "after"` (or `"lead"` under lockstep, which has no
/// deadline to lead) walks `joints` (this thread's half) into cache.
#[inline]
pub fn prefetch_after_publish(plan: &CrewPlan, joints: &[JointRt]) {
    if plan.prefetch == Prefetch::After || (plan.prefetch == Prefetch::Lead && plan.lockstep) {
        prefetch_joints(joints);
    }
}

/// How steps 0–1 of a tick ended.
#[derive(Debug, Clone, Copy)]
enum Wake {
    /// Run the tick: woken at `wake_ns`; `timed_out` if the lockstep wait gave up on an input.
    Tick { wake_ns: u64, timed_out: bool },
    /// The supervisor asked to stop.
    Stop,
}

/// Steps 0 and 1: waits for the trigger (clock deadline or lockstep inputs), then the inputs are
/// polled for tick `tick`.
#[inline]
#[allow(clippy::too_many_arguments)] // the wait's inputs, called once per tick
fn wait_for_tick(
    plan: &LoopPlan,
    crew_plan: &CrewPlan,
    own_joints: &[JointRt],
    backend: &mut AnyBackend,
    inputs: &mut Inputs,
    tick: u64,
    deadline_ns: u64,
    stop: &AtomicBool,
) -> Wake {
    if plan.lockstep {
        let timed_out = match wait_lockstep(
            backend,
            inputs,
            tick,
            stop,
            plan.wait_request,
            plan.lockstep_timeout_ns,
        ) {
            LockstepWake::Inputs => false,
            LockstepWake::TimedOut => true,
            LockstepWake::Stop => return Wake::Stop,
        };
        Wake::Tick {
            wake_ns: monotonic_ns(),
            timed_out,
        }
    } else {
        sleep_to_deadline(
            deadline_ns,
            crew_plan.prefetch,
            crew_plan.lead_ns,
            own_joints,
        );
        let wake_ns = monotonic_ns();
        if stop.load(Ordering::Relaxed) {
            return Wake::Stop;
        }
        inputs.poll(backend, tick);
        Wake::Tick {
            wake_ns,
            timed_out: false,
        }
    }
}

/// Step 2: the parameters in use and the hand-over with the supervisor. Old sets go back to be
/// freed off-thread, never here; while one cannot be sent back (queue full) no new set is taken.
struct ParamSlot {
    params: Box<Params>,
    parked_old: Option<Box<Params>>,
    rx_params: Receiver<Box<Params>>,
    tx_old: SyncSender<Box<Params>>,
}

impl ParamSlot {
    /// Takes a new parameter set if one is waiting; `true` if it did.
    #[inline]
    fn hand_over(&mut self) -> bool {
        if let Some(old) = self.parked_old.take()
            && let Err(std::sync::mpsc::TrySendError::Full(old)) = self.tx_old.try_send(old)
        {
            self.parked_old = Some(old);
        }
        if self.parked_old.is_some() {
            return false;
        }
        match self.rx_params.try_recv() {
            Ok(new) => {
                let old = std::mem::replace(&mut self.params, new);
                if let Err(std::sync::mpsc::TrySendError::Full(old)) = self.tx_old.try_send(old) {
                    self.parked_old = Some(old);
                }
                true
            }
            Err(TryRecvError::Empty | TryRecvError::Disconnected) => false,
        }
    }
}

impl Freshness {
    /// Step 3a: whether this tick's state and request are stale. Clock trigger: by `seq` and by
    /// stamp age against the wake time. Lockstep: its time is not wall time, so there is no
    /// stamp-age rule; its stand-in is the timeout — an input that did not arrive within
    /// `lockstep_timeout_ms` (`timed_out`) is stale at once.
    #[inline]
    fn judge(
        plan: &LoopPlan,
        inputs: &Inputs,
        tick: u64,
        wake_ns: u64,
        timed_out: bool,
        stale_after: u64,
    ) -> Self {
        let (st, rq) = (&inputs.states, &inputs.request);
        if plan.lockstep {
            let answered = !plan.wait_request || rq.value.state_seq == st.value.seq;
            Self {
                state_stale: st.stale_by_ticks(tick, stale_after)
                    || (timed_out && !st.new_in(tick)),
                request_stale: rq.stale_by_ticks(tick, stale_after)
                    || (timed_out && !(rq.new_in(tick) && answered)),
            }
        } else {
            Self {
                state_stale: st.stale(
                    tick,
                    wake_ns,
                    st.value.stamp_ns,
                    stale_after,
                    plan.period_ns,
                ),
                request_stale: rq.stale(
                    tick,
                    wake_ns,
                    rq.value.stamp_ns,
                    stale_after,
                    plan.period_ns,
                ),
            }
        }
    }
}

/// Step 4's statistics: the status snapshot being filled and the fine lateness histogram.
#[derive(Debug)]
struct Telemetry {
    status: DaemonStatus,
    stale_ticks: u64,
    lateness_fine: FineHistogram,
}

impl Telemetry {
    /// Records one tick: wake lateness (clock trigger only: lockstep has no deadline), compute
    /// time, input age, staleness, out-of-range joints.
    #[allow(clippy::too_many_arguments)] // one tick's pieces, called once
    #[inline]
    fn record(
        &mut self,
        plan: &LoopPlan,
        inputs: &Inputs,
        cmd: &MotorCurrentCommand,
        fresh: Freshness,
        wake_ns: u64,
        deadline_ns: u64,
        done_ns: u64,
    ) {
        let s = &mut self.status;
        if !plan.lockstep {
            let late = wake_ns.saturating_sub(deadline_ns);
            s.lateness.record(late);
            self.lateness_fine.record(late);
        }
        s.compute.record(done_ns.saturating_sub(wake_ns));
        if inputs.states.have {
            let age = wake_ns.saturating_sub(inputs.states.value.stamp_ns);
            s.input_age.record(age);
            s.input_age_ns = age;
        }
        if fresh.state_stale {
            self.stale_ticks += 1;
        }
        for (n, &flags) in s.out_of_range_ticks.iter_mut().zip(&cmd.flags) {
            if flags & FLAG_OUT_OF_RANGE != 0 {
                *n += 1;
            }
        }
    }

    /// Publishes the [`DaemonStatus`] snapshot after `ticks` ticks and mirrors the lateness
    /// quantiles into `shared`.
    #[allow(clippy::too_many_arguments)] // one snapshot from the tick's pieces, called once
    #[inline]
    fn publish(
        &mut self,
        backend: &mut AnyBackend,
        shared: &Shared,
        params: &Params,
        joints: &[JointRt],
        cmd: &MotorCurrentCommand,
        tau_f: &[f64; MAX_JOINTS],
        state_stale: bool,
        (ticks, missed, rt_flags): (u64, u64, u32),
        now_ns: u64,
    ) {
        let s = &mut self.status;
        s.seq += 1;
        s.stamp_ns = now_ns;
        s.ticks = ticks;
        s.missed_deadlines = missed;
        s.stale_ticks = self.stale_ticks;
        s.n_joints = params.joints.len() as u32;
        s.flags = rt_flags | if state_stale { STATUS_INPUT_STALE } else { 0 };
        for j in joints {
            s.model_kind[j.index] = crate::params::kind_code(&j.model);
        }
        s.tau_f_hat_nm = *tau_f;
        s.i_ref_a = cmd.i_ref_a;
        s.joint_flags = cmd.flags;
        let _ = backend.publish_status(s);
        shared
            .lateness_p99_ns
            .store(s.lateness.quantile_upper_ns(0.99), Ordering::Relaxed);
        shared
            .lateness_max_ns
            .store(s.lateness.max_ns, Ordering::Relaxed);
    }
}

/// The next absolute deadline after `deadline_ns` and the number of whole periods skipped to
/// reach it: missed periods are skipped, not caught up in a burst (clock trigger; lockstep has no
/// deadline and skips nothing).
#[inline]
fn next_deadline(plan: &LoopPlan, deadline_ns: u64, now_ns: u64) -> (u64, u64) {
    let next = deadline_ns + plan.period_ns;
    if plan.lockstep || now_ns < next {
        return (next, 0);
    }
    let skipped = (now_ns - next) / plan.period_ns + 1;
    (next + skipped * plan.period_ns, skipped)
}

/// Stopping: zero current on every configured joint, published a few times so latest-value readers
/// see it, then a last status with `STATUS_STOPPING`.
fn publish_stop(
    backend: &mut AnyBackend,
    cmd: &mut MotorCurrentCommand,
    status: &mut DaemonStatus,
    configured_mask: u64,
    period_ns: u64,
) {
    cmd.valid_mask = configured_mask;
    cmd.i_ref_a = [0.0; MAX_JOINTS];
    cmd.flags = [0; MAX_JOINTS];
    status.flags |= STATUS_STOPPING;
    for _ in 0..3 {
        cmd.seq = cmd.seq.wrapping_add(1);
        cmd.stamp_ns = monotonic_ns();
        let _ = backend.publish_command(cmd);
        sleep_until_ns(monotonic_ns() + period_ns);
    }
    status.seq += 1;
    status.stamp_ns = monotonic_ns();
    status.i_ref_a = [0.0; MAX_JOINTS];
    let _ = backend.publish_status(status);
}

/// The RT thread's body. Returns when `shared.stop` is set (after publishing zero currents), with
/// the loop statistics; `None` if set-up failed (reported through `started`).
pub fn run(setup: RtSetup) -> Option<RtSummary> {
    let RtSetup {
        config,
        params,
        rx_params,
        tx_old,
        shared,
        started,
        count_allocs,
    } = setup;
    // `grant` is held until this function returns (the PM QoS request lives while its file is open).
    let (mut backend, grant, mut crew) = start(&config, &shared, &started)?;
    let rt_flags = grant.flags;
    let plan = LoopPlan::of(&config);
    let crew_plan = CrewPlan::of(&config);

    let mut slot = ParamSlot {
        params,
        parked_old: None,
        rx_params,
        tx_old,
    };
    let mut inputs = Inputs {
        states: Latest::new(JointStates::zeroed()),
        request: Latest::new(TorqueRequest::zeroed()),
    };
    let mut cmd = MotorCurrentCommand::zeroed();
    let mut tele = Telemetry {
        status: DaemonStatus::zeroed(),
        stale_ticks: 0,
        lateness_fine: FineHistogram::new(),
    };
    tele.status.period_ns = plan.period_ns;
    tele.status.flags = rt_flags;
    let mut tau_f = [0.0f64; MAX_JOINTS];
    let mut prev_active = 0u64;
    let mut missed = 0u64;
    let mut tick = 0u64;
    let mut was_stale = false;
    // SAFETY: gettid/sched_getcpu have no preconditions.
    let tid = unsafe { libc::gettid() };
    let cpu_start = unsafe { libc::sched_getcpu() };
    let usage_start = ThreadUsage::now();
    let mut deadline = monotonic_ns() + plan.period_ns;

    loop {
        if count_allocs && tick == plan.count_from_tick {
            alloc_count::set_counting(true);
        }

        // 0. wait (the only step that differs between the triggers) and 1. inputs
        let Wake::Tick { wake_ns, timed_out } = wait_for_tick(
            &plan,
            &crew_plan,
            main_half(&slot.params),
            &mut backend,
            &mut inputs,
            tick,
            deadline,
            &shared.stop,
        ) else {
            break;
        };

        // 2. parameter hand-over (only while the helper holds no job: it never sees a half-swapped
        // set; the new set's joints were split at build)
        let helper_free = crew
            .as_mut()
            .is_none_or(|c| c.release(wake_ns.saturating_add(crew_plan.release_ns)));
        if helper_free && slot.hand_over() {
            prev_active = 0; // every enabled joint gets a bumpless reset
            let generation = slot.params.generation;
            shared.generation.store(generation, Ordering::Relaxed);
            tele.status.generation = generation;
        }

        // 3. compute
        let stale_after = slot.params.stale_after_ticks;
        let fresh = Freshness::judge(&plan, &inputs, tick, wake_ns, timed_out, stale_after);
        let stale_now = fresh.state_stale || fresh.request_stale;
        if stale_now != was_stale {
            was_stale = stale_now;
            if stale_now {
                shared.stale_episodes.fetch_add(1, Ordering::Relaxed);
            }
            shared.input_stale.store(stale_now, Ordering::Relaxed);
        }
        match crew.as_mut() {
            None => compute(
                &mut slot.params,
                &inputs,
                fresh,
                &mut prev_active,
                &mut cmd,
                &mut tau_f,
            ),
            Some(c) => {
                let tick_deadline = if plan.lockstep { 0 } else { deadline };
                let on_time = c.compute(
                    &mut slot.params,
                    &inputs,
                    fresh,
                    &mut prev_active,
                    &mut cmd,
                    &mut tau_f,
                    wake_ns,
                    tick_deadline,
                );
                if !on_time {
                    shared.helper_late.store(c.late_ticks(), Ordering::Relaxed);
                }
            }
        }
        cmd.seq = cmd.seq.wrapping_add(1);
        cmd.stamp_ns = monotonic_ns();

        // 4. output, telemetry, heartbeat
        let _ = backend.publish_command(&cmd);
        let done = monotonic_ns();
        prefetch_after_publish(&crew_plan, main_half(&slot.params));
        tele.record(&plan, &inputs, &cmd, fresh, wake_ns, deadline, done);
        tick += 1;
        if tick.is_multiple_of(plan.status_every) {
            // A late helper still holds its half: only this thread's joints are read.
            let readable = match &crew {
                Some(c) if c.busy() => slot.params.split,
                _ => slot.params.joints.len(),
            };
            tele.publish(
                &mut backend,
                &shared,
                &slot.params,
                joints_prefix(&slot.params, readable),
                &cmd,
                &tau_f,
                fresh.state_stale,
                (tick, missed, rt_flags),
                done,
            );
        }
        shared.heartbeat.store(tick, Ordering::Relaxed);

        let skipped;
        (deadline, skipped) = next_deadline(&plan, deadline, monotonic_ns());
        if skipped > 0 {
            missed += skipped;
            shared.missed.store(missed, Ordering::Relaxed);
        }
    }
    alloc_count::set_counting(false);
    let usage = ThreadUsage::now().since(usage_start);
    let helper_late = crew.as_ref().map_or(0, Crew::late_ticks);
    let helper_stolen = crew.as_ref().map_or(0, Crew::stolen_ticks);
    // The helper ends (after its current job) before the parameters can be freed.
    let helper = crew.take().map(Crew::stop);
    let (policy, priority) = sched_of_self();
    let thread = RtThreadReport {
        tid,
        rt_flags,
        policy,
        priority,
        cpu_start,
        // SAFETY: no preconditions.
        cpu_end: unsafe { libc::sched_getcpu() },
        pm_qos_us: grant.pm_qos_us,
        usage,
    };
    if count_allocs {
        shared
            .counted_ticks
            .store(tick.saturating_sub(plan.count_from_tick), Ordering::Relaxed);
    }

    publish_stop(
        &mut backend,
        &mut cmd,
        &mut tele.status,
        slot.params.configured_mask,
        plan.period_ns,
    );
    drop(slot); // stopping: allocation rules no longer apply (a parked old set is freed here)
    Some(RtSummary {
        ticks: tick,
        missed,
        lockstep: plan.lockstep,
        lateness: tele.lateness_fine,
        status: Box::new(tele.status),
        thread,
        helper,
        helper_late,
        helper_stolen,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use frictionless_shm_types::{FLAG_NON_FINITE, FLAG_STALE};

    /// A CPU index beyond CPU_SETSIZE (the config refuses it; a `Config` built in code
    /// may not) is an affinity refusal, not a panic in `CPU_SET`.
    #[test]
    fn out_of_range_cpu_is_refused_without_panicking() {
        let text = "[backend]\nkind = \"shm\"\n[[joint]]\nname = \"a\"\nindex = 0\ngear_ratio = 1.0\nkt = 0.1\nmax_curr = 1.0\nfriction_model = \"none\"\n";
        let mut cfg = crate::config::parse(std::path::Path::new("t.toml"), text).unwrap();
        for cpu in [libc::CPU_SETSIZE as usize, usize::MAX] {
            cfg.raw.loop_.cpu = Some(cpu);
            let c = cfg.clone();
            let grant = std::thread::spawn(move || apply_rt_settings(&c).map(|g| g.flags))
                .join()
                .expect("no panic")
                .expect("refusals are not fatal without require_rt");
            assert_eq!(grant & STATUS_CPU_PINNED, 0, "cpu {cpu}");
        }
    }

    fn params(on_stale: &str) -> Box<Params> {
        let text = format!(
            r#"
[backend]
kind = "shm"
[safety]
on_stale = "{on_stale}"
[[joint]]
name = "a"
index = 2
gear_ratio = -100.0
kt = 0.1
max_curr = 5.0
kfc = 1.0
lpf = {{ order = 1, cutoff_hz = 50.0 }}
friction_model = "cv"
kc = 1.0
ka = 1000.0
kv = 0.0
"#
        );
        let cfg = crate::config::parse(std::path::Path::new("t.toml"), &text).unwrap();
        crate::params::build(&cfg, 0).unwrap()
    }

    fn inputs(tau: f64, v: f64) -> Inputs {
        let mut st = JointStates::zeroed();
        st.n_joints = 3;
        st.sdot_rad_s[2] = v;
        let mut rq = TorqueRequest::zeroed();
        rq.n_joints = 3;
        rq.enable_mask = 1 << 2;
        rq.tau_des_nm[2] = tau;
        Inputs {
            states: Latest {
                value: st,
                have: true,
                new_at_tick: 0,
            },
            request: Latest {
                value: rq,
                have: true,
                new_at_tick: 0,
            },
        }
    }

    const FRESH: Freshness = Freshness {
        state_stale: false,
        request_stale: false,
    };

    fn run(p: &mut Params, inp: &Inputs, f: Freshness, prev: &mut u64) -> MotorCurrentCommand {
        let mut cmd = MotorCurrentCommand::zeroed();
        let mut tau_f = [0.0; MAX_JOINTS];
        compute(p, inp, f, prev, &mut cmd, &mut tau_f);
        cmd
    }

    #[test]
    fn enable_edge_resets_the_filter_and_masks_follow_the_request() {
        let mut p = params("zero");
        let mut prev = 0;
        let inp = inputs(0.0, 1.0);
        let first = run(&mut p, &inp, FRESH, &mut prev).i_ref_a[2];
        assert_eq!(prev, 1 << 2);
        let second = run(&mut p, &inp, FRESH, &mut prev).i_ref_a[2];
        assert!(second.abs() > first.abs(), "LPF rising: {first} → {second}");
        // Disable: 0 A, not valid, flagged.
        let mut off = inputs(0.0, 1.0);
        off.request.value.enable_mask = 0;
        let c = run(&mut p, &off, FRESH, &mut prev);
        assert_eq!(
            (c.valid_mask, c.i_ref_a[2], c.flags[2]),
            (0, 0.0, FLAG_DISABLED)
        );
        // Re-enable: the filter starts again from 0 (same first value as at the start).
        let again = run(&mut p, &inp, FRESH, &mut prev).i_ref_a[2];
        assert_eq!(again, first);
    }

    #[test]
    fn stale_fault_and_nan_paths() {
        let mut p = params("static_model");
        let mut prev = 0;
        let inp = inputs(2.0, 1.0);
        let stale = Freshness {
            state_stale: true,
            request_stale: false,
        };
        let c = run(&mut p, &inp, stale, &mut prev);
        assert_eq!(c.flags[2], FLAG_STALE);
        assert!((c.i_ref_a[2] - 2.0 / (0.1 * -100.0)).abs() < 1e-12);
        let both = Freshness {
            state_stale: true,
            request_stale: true,
        };
        assert_eq!(run(&mut p, &inp, both, &mut prev).i_ref_a[2], 0.0);
        let mut fault = inputs(2.0, 1.0);
        fault.states.value.fault_flags[2] = 1;
        let c = run(&mut p, &fault, FRESH, &mut prev);
        assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_FAULT));
        let mut nan = inputs(2.0, 1.0);
        nan.states.value.sdot_rad_s[2] = f64::NAN;
        let c = run(&mut p, &nan, FRESH, &mut prev);
        assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_NON_FINITE));
        // No request ever received: nothing valid.
        let mut none = inputs(2.0, 1.0);
        none.request.have = false;
        assert_eq!(run(&mut p, &none, FRESH, &mut prev).valid_mask, 0);
    }

    /// `n` joints at indices 0, 3, 6, …: PINNs of different sizes and dtypes (seeded random
    /// weights), CV and SCV models; the law with a filter and clamps.
    fn mixed_params(n: usize, rt_threads: u8) -> Box<Params> {
        use crate::params::{JointRt, OodRt};
        use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
        use frictionless::filter::CausalButterworth;
        use frictionless::friction::{CvParams, ScvParams};
        use frictionless::law::{Gains, JointLaw};
        use frictionless::mlp::StorageDtype;
        use frictionless::model::PinnEstimator;
        use frictionless::random::{RandomMlpSpec, seeded_mlp};
        use frictionless::units::GearRatio;
        use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
        let r = -100.0;
        let joints = (0..n)
            .map(|k| {
                let model = match k % 4 {
                    0 | 1 => {
                        let features = FeatureSpec {
                            set: FeatureSet::DeltaThetaJointVel,
                            history: 4 + k % 3,
                            temperature: false,
                        };
                        let width = 16 + 8 * (k % 5);
                        let file = ModelFile {
                            meta: ModelMeta {
                                joint_name: format!("j{k}"),
                                gear_ratio: GearRatio::new(r).unwrap(),
                                kt_nm_per_a: 0.1,
                                features,
                                scv: None,
                                training: TrainingMeta::unknown("rt test", 0),
                            },
                            dtype: [StorageDtype::F32, StorageDtype::F16, StorageDtype::Bf16]
                                [k % 3],
                            mlp: seeded_mlp(
                                &RandomMlpSpec::new(&[features.n_inputs(), width, width, 1]),
                                k as u64,
                            )
                            .unwrap(),
                        };
                        let policy = if k % 2 == 0 {
                            WarmupPolicy::HoldZero
                        } else {
                            WarmupPolicy::ZeroPad
                        };
                        JointModel::Pinn(Box::new(
                            PinnEstimator::from_model_file(&file, policy).unwrap(),
                        ))
                    }
                    2 => JointModel::Cv(CvParams {
                        kc: 1.0,
                        ka: 50.0,
                        kv: 0.3,
                    }),
                    _ => JointModel::Scv(ScvParams {
                        kc: 1.0,
                        ka: 2.78,
                        kv: 0.29,
                        ks: 6.0,
                        vs: 0.13,
                        alpha: 0.6,
                    }),
                };
                let gains = Gains {
                    kt_nm_per_a: 0.1,
                    gear_ratio: r,
                    kfc: 0.8,
                    kp: 0.1,
                    ki: 0.5,
                    max_curr_a: 4.0,
                    max_output_friction_nm: 3.0,
                    joint_velocity_threshold_rad_s: 0.05,
                    dt_s: 1e-3,
                };
                JointRt {
                    index: 3 * k,
                    model,
                    law: JointLaw::new(
                        gains,
                        Some(CausalButterworth::design(2, 30.0, 1000.0).unwrap()),
                    ),
                    ood: OodRt::off(),
                }
            })
            .collect();
        let configured_mask = (0..n).fold(0u64, |m, k| m | 1 << (3 * k));
        let mut p = Box::new(Params {
            generation: 0,
            joints,
            stale_after_ticks: 5,
            on_stale: OnStale::StaticModel,
            configured_mask,
            split: 0,
            helper_mask: 0,
        });
        p.split_threads(rt_threads);
        p
    }

    /// Tick `t`'s inputs for joints at 0, 3, 6, …: moving states, NaN samples, faults, enable
    /// toggles and stale stretches.
    fn changing_inputs(n: usize, t: u64) -> (Inputs, Freshness) {
        let mut st = JointStates::zeroed();
        let mut rq = TorqueRequest::zeroed();
        st.n_joints = (3 * n) as u32;
        rq.n_joints = (3 * n) as u32;
        st.seq = t;
        rq.enable_mask = u64::MAX;
        for k in 0..n {
            let i = 3 * k;
            let x = (t as f64 * 0.013 + k as f64).sin();
            st.s_rad[i] = 0.3 * x;
            st.sdot_rad_s[i] = 0.8 * (t as f64 * 0.007 + k as f64 * 0.5).cos();
            st.theta_motor_rad[i] = -100.0 * st.s_rad[i] + 0.02 * x;
            st.omega_motor_rad_s[i] = -100.0 * st.sdot_rad_s[i];
            st.tau_meas_nm[i] = 2.0 * x;
            rq.tau_des_nm[i] = 3.0 * x;
            if (t + k as u64).is_multiple_of(97) {
                st.sdot_rad_s[i] = f64::NAN;
            }
            if (t / 50 + k as u64).is_multiple_of(7) {
                rq.enable_mask &= !(1 << i);
            }
            if (t + 3 * k as u64) % 211 == 5 {
                st.fault_flags[i] = 1;
            }
        }
        let fresh = Freshness {
            state_stale: t % 400 >= 390,
            request_stale: t % 900 >= 895,
        };
        let inp = Inputs {
            states: Latest {
                value: st,
                have: true,
                new_at_tick: t,
            },
            request: Latest {
                value: rq,
                have: t > 3,
                new_at_tick: t,
            },
        };
        (inp, fresh)
    }

    fn test_crew(budget_ns: u64) -> Crew {
        let plan = CrewPlan {
            period_ns: 1_000_000,
            budget_ns,
            release_ns: budget_ns,
            prefetch: Prefetch::After,
            lead_ns: 0,
            lockstep: true,
        };
        Crew::spawn(plan, ThreadRt::default()).unwrap().0
    }

    #[test]
    fn two_threads_give_the_one_thread_output_bit_for_bit() {
        let n = 11;
        let mut one = mixed_params(n, 1);
        let mut two = mixed_params(n, 2);
        assert_eq!(one.split, n);
        assert!(two.split > 0 && two.split < n, "split {}", two.split);
        assert_ne!(two.helper_mask, 0);
        assert_eq!(two.helper_mask & !two.configured_mask, 0);
        // A budget no scheduler delay reaches: the helper is never late here.
        let mut crew = test_crew(60_000_000_000);
        let (mut prev1, mut prev2) = (0u64, 0u64);
        let (mut c1, mut c2) = (MotorCurrentCommand::zeroed(), MotorCurrentCommand::zeroed());
        let (mut f1, mut f2) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        let mut nonzero = 0;
        for t in 0..3000 {
            let (inp, fresh) = changing_inputs(n, t);
            compute(&mut one, &inp, fresh, &mut prev1, &mut c1, &mut f1);
            let wake = monotonic_ns();
            assert!(crew.compute(&mut two, &inp, fresh, &mut prev2, &mut c2, &mut f2, wake, 0));
            assert_eq!(prev1, prev2, "tick {t}");
            assert_eq!(
                (c1.valid_mask, c1.n_joints, c1.state_seq),
                (c2.valid_mask, c2.n_joints, c2.state_seq)
            );
            for k in 0..MAX_JOINTS {
                assert_eq!(
                    c1.i_ref_a[k].to_bits(),
                    c2.i_ref_a[k].to_bits(),
                    "tick {t} joint {k}"
                );
                assert_eq!(c1.flags[k], c2.flags[k], "tick {t} joint {k}");
                assert_eq!(f1[k].to_bits(), f2[k].to_bits(), "tick {t} joint {k}");
                nonzero += usize::from(c1.i_ref_a[k] != 0.0);
            }
        }
        assert_eq!(crew.late_ticks(), 0);
        assert!(nonzero > 10_000, "the joints were driven: {nonzero}");
        let stolen = crew.stolen_ticks();
        let h = crew.stop();
        assert_eq!(
            h.jobs + stolen,
            3000,
            "every job ran once, on one thread or the other"
        );
    }

    #[test]
    fn a_helper_that_has_not_started_loses_its_half_to_the_main_thread_same_outputs() {
        let n = 9;
        let mut one = mixed_params(n, 1);
        let mut two = mixed_params(n, 2);
        // No budget to wait for the helper at all: only the claim keeps its joints from going stale.
        let mut crew = test_crew(0);
        let (mut prev1, mut prev2) = (0u64, 0u64);
        let (mut c1, mut c2) = (MotorCurrentCommand::zeroed(), MotorCurrentCommand::zeroed());
        let (mut f1, mut f2) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        crew.ren.hold.store(true, Ordering::Release);
        for t in 0..600 {
            if t == 300 {
                // The helper wakes up: from here on it may claim jobs again (or lose them).
                crew.ren.hold.store(false, Ordering::Release);
            }
            let (inp, fresh) = changing_inputs(n, t);
            compute(&mut one, &inp, fresh, &mut prev1, &mut c1, &mut f1);
            let on_time = crew.compute(
                &mut two,
                &inp,
                fresh,
                &mut prev2,
                &mut c2,
                &mut f2,
                monotonic_ns(),
                0,
            );
            if t < 300 {
                assert!(
                    on_time,
                    "tick {t}: a held helper's half is run here, never late"
                );
                assert_eq!(crew.stolen_ticks(), t + 1);
            }
            if !on_time {
                // Claimed by the helper and not done within a zero budget: the stale path (tested
                // below); its joints restart bumplessly afterwards and are no longer comparable.
                break;
            }
            assert_eq!(prev1, prev2, "tick {t}");
            for k in 0..MAX_JOINTS {
                assert_eq!(
                    c1.i_ref_a[k].to_bits(),
                    c2.i_ref_a[k].to_bits(),
                    "tick {t} joint {k}"
                );
                assert_eq!(c1.flags[k], c2.flags[k], "tick {t} joint {k}");
                assert_eq!(f1[k].to_bits(), f2[k].to_bits(), "tick {t} joint {k}");
            }
        }
        assert!(crew.stolen_ticks() >= 300);
        drop(crew);
    }

    #[test]
    fn a_late_helper_marks_its_joints_stale_and_never_hangs() {
        let n = 8;
        let mut one = mixed_params(n, 1);
        let mut two = mixed_params(n, 2);
        let helper_mask = two.helper_mask;
        // No budget at all: the join gives up as soon as this thread's half is done.
        let mut crew = test_crew(0);
        let (mut prev1, mut prev2) = (0u64, 0u64);
        let (mut c1, mut c2) = (MotorCurrentCommand::zeroed(), MotorCurrentCommand::zeroed());
        let (mut f1, mut f2) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        let mut late = 0;
        for t in 0..500 {
            let (inp, fresh) = changing_inputs(n, t);
            compute(&mut one, &inp, fresh, &mut prev1, &mut c1, &mut f1);
            let on_time = crew.compute(
                &mut two,
                &inp,
                fresh,
                &mut prev2,
                &mut c2,
                &mut f2,
                monotonic_ns(),
                0,
            );
            for k in 0..MAX_JOINTS {
                if helper_mask & (1 << k) != 0 && !on_time {
                    assert_eq!(c2.i_ref_a[k], 0.0, "tick {t} joint {k}");
                    let want = if c2.valid_mask & (1 << k) != 0 {
                        FLAG_STALE
                    } else {
                        FLAG_DISABLED
                    };
                    assert_eq!(c2.flags[k], want, "tick {t} joint {k}");
                } else if helper_mask & (1 << k) == 0 {
                    // This thread's joints are never affected by the helper.
                    assert_eq!(
                        c1.i_ref_a[k].to_bits(),
                        c2.i_ref_a[k].to_bits(),
                        "tick {t} joint {k}"
                    );
                }
            }
            late += usize::from(!on_time);
        }
        assert_eq!(crew.late_ticks(), late as u64);
        drop(crew); // joins the helper before the parameters go
    }

    #[test]
    fn the_split_balances_weight_bytes_and_keeps_index_order() {
        let p = mixed_params(12, 2);
        let bytes = |js: &[JointRt]| js.iter().map(|j| j.model.weight_bytes()).sum::<usize>();
        let (a, b) = (bytes(&p.joints[..p.split]), bytes(&p.joints[p.split..]));
        let heaviest = p
            .joints
            .iter()
            .map(|j| j.model.weight_bytes())
            .max()
            .unwrap();
        assert!(a.abs_diff(b) <= heaviest, "{a} vs {b}");
        for half in [&p.joints[..p.split], &p.joints[p.split..]] {
            assert!(half.windows(2).all(|w| w[0].index < w[1].index));
        }
        let mut all: Vec<usize> = p.joints.iter().map(|j| j.index).collect();
        all.sort_unstable();
        assert_eq!(all, (0..12).map(|k| 3 * k).collect::<Vec<_>>());
        let q = mixed_params(12, 1);
        assert_eq!((q.split, q.helper_mask), (12, 0));
    }

    #[test]
    fn fine_histogram_quantiles_have_1us_resolution() {
        let mut h = FineHistogram::new();
        assert_eq!(h.quantile_upper_ns(0.5), 0, "empty");
        // 1.5 µs, 2.5 µs, …, 100.5 µs: value i lands in bucket [i, i+1) µs.
        for us in 1..=100u64 {
            h.record(us * 1000 + 500);
        }
        assert_eq!(h.quantile_upper_ns(0.5), 51_000);
        assert_eq!(h.quantile_upper_ns(0.99), 100_000);
        assert_eq!(h.quantile_upper_ns(1.0), 100_500, "capped by the max");
        h.record(1_000_000_000);
        assert_eq!((h.overflow, h.total, h.max_ns), (1, 101, 1_000_000_000));
        assert_eq!(h.quantile_upper_ns(1.0), 1_000_000_000);
        let s = RtSummary {
            ticks: 101,
            missed: 0,
            lockstep: false,
            lateness: h,
            status: Box::new(DaemonStatus::zeroed()),
            thread: RtThreadReport {
                policy: libc::SCHED_FIFO,
                priority: 80,
                usage: ThreadUsage {
                    minflt: 3,
                    ..ThreadUsage::default()
                },
                ..RtThreadReport::default()
            },
            helper: None,
            helper_late: 0,
            helper_stolen: 0,
        }
        .report();
        assert!(s.contains("trigger=clock\n"), "{s}");
        assert!(s.contains("lateness_p50_ns=52000\n"), "{s}");
        assert!(s.contains("lateness_max_ns=1000000000\n"), "{s}");
        assert!(s.contains("rt_policy=SCHED_FIFO\nrt_priority=80\n"), "{s}");
        assert!(s.contains("rt_minflt=3\nrt_majflt=0\n"), "{s}");
        assert!(s.contains("rt_pm_qos_us=none\n"), "{s}");
        // 1.5 … 100.5 µs once each, then 1 s in the overflow.
        let hist: String = (1..=100).map(|us| format!("{us}:1,")).collect();
        assert!(
            s.contains(&format!(
                "lateness_overflow=1\nlateness_hist_us={}\n",
                hist.trim_end_matches(',')
            )),
            "{s}"
        );
    }

    #[test]
    fn cpu_dma_latency_is_held_and_read_back_or_the_refusal_is_an_error() {
        match hold_cpu_dma_latency(0) {
            // While our request is open the effective bound is the minimum of all: 0.
            Ok((_file, got_us)) => assert_eq!(got_us, 0),
            Err(e) => assert!(
                matches!(
                    e.kind(),
                    std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::NotFound
                ),
                "{e}"
            ),
        }
    }

    #[test]
    fn thread_usage_sees_this_threads_page_faults_and_sleeps() {
        let before = ThreadUsage::now();
        // A fresh mapping (mmap at this size): every first touch of a page faults.
        let mut v = vec![0u8; (1 << 20) + 64 * 4096];
        for k in (0..v.len()).step_by(4096) {
            v[k] = 1;
        }
        std::hint::black_box(&mut v);
        std::thread::sleep(std::time::Duration::from_millis(1));
        let d = ThreadUsage::now().since(before);
        assert!(d.minflt >= 64, "{d:?}");
        assert!(d.nvcsw >= 1, "a sleep is a voluntary switch: {d:?}");
    }

    #[test]
    fn a_silent_field_bus_drive_gets_the_on_stale_output_not_a_fault() {
        let mut prev = 0;
        let mut inp = inputs(2.0, 1.0);
        inp.states.value.fault_flags[2] = FAULT_FEEDBACK_STALE;
        let mut p = params("static_model");
        let c = run(&mut p, &inp, FRESH, &mut prev);
        assert_eq!(c.flags[2], FLAG_STALE);
        assert!((c.i_ref_a[2] - 2.0 / (0.1 * -100.0)).abs() < 1e-12);
        let mut p = params("zero");
        let c = run(&mut p, &inp, FRESH, &mut prev);
        assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_STALE));
        // Any other fault bit still wins over staleness.
        inp.states.value.fault_flags[2] |= frictionless_shm_types::FAULT_DRIVE;
        let c = run(&mut p, &inp, FRESH, &mut prev);
        assert_eq!((c.i_ref_a[2], c.flags[2]), (0.0, FLAG_FAULT));
    }

    #[test]
    fn law_flags_map_to_the_abi_bits() {
        assert_eq!(abi_flags(LawFlags::NONE), 0);
        let all = LawFlags {
            friction_clipped: true,
            current_saturated: true,
            non_finite: true,
        };
        assert_eq!(
            abi_flags(all),
            FLAG_FRICTION_CLIPPED | FLAG_CURRENT_SATURATED | FLAG_NON_FINITE
        );
        let clipped = LawFlags {
            friction_clipped: true,
            ..LawFlags::NONE
        };
        assert_eq!(abi_flags(clipped), FLAG_FRICTION_CLIPPED);
    }

    #[test]
    fn freshness_by_seq_age_and_stamp_age() {
        let mut l = Latest::new(0u8);
        assert!(l.stale(0, 0, 0, 5, 1000), "nothing received yet");
        l.update(Some(1), 10);
        assert!(!l.stale(15, 10_000, 9_000, 5, 1000));
        assert!(
            l.stale(16, 10_000, 9_000, 5, 1000),
            "no new sample for 6 ticks"
        );
        assert!(l.stale(11, 20_000, 9_000, 5, 1000), "stamp 11 periods old");
    }
}
