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
//!    to be freed off-thread; then (2b, [`apply_runtime_sets`]) the runtime changes waiting in
//!    their bounded queue, checked off-thread (`frictiond_config::runtime`), applied to their
//!    joint — a change is visible from this tick on; one checked against a replaced parameter
//!    generation is dropped;
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
//! the helper thread (its loop, `helper_main`, is in `crew`), computes the first with the
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
//! This file is the tick: [`run`] and every step it calls. What is not the tick lives in three
//! submodules, re-exported here: `crew` (the helper thread of `rt_threads = 2`, its job hand-over
//! and join, with their `unsafe`), `rt_setup` (opening the backend and the RT settings of each
//! thread: affinity, SCHED_FIFO, mlockall, PM QoS, the pre-faulted stack) and `stats` (the fine
//! lateness histogram, thread usage and the exit report).
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

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError};

use frictionless::features::JointSample;
use frictionless::law::{LawFlags, LawInput, LawOutput};
use frictionless::model::{FrictionModel, JointModel};
use frictionless_shm_types::{
    DaemonStatus, FAULT_FEEDBACK_STALE, FLAG_CURRENT_SATURATED, FLAG_DISABLED, FLAG_FAULT,
    FLAG_FRICTION_CLIPPED, FLAG_NON_FINITE, FLAG_OUT_OF_RANGE, FLAG_STALE, FLAG_WARMING_UP,
    JointStates, MAX_JOINTS, MotorCurrentCommand, STATUS_INPUT_STALE, STATUS_STOPPING,
    TorqueRequest, monotonic_ns, sleep_until_ns,
};

use crate::alloc_count;
use crate::backend::{AnyBackend, Backend};
use crate::config::{Config, OnStale, Prefetch, Trigger};
use crate::params::{JointRt, Params};
use crate::runtime::RuntimeSet;

mod crew;
mod rt_setup;
mod stats;
#[cfg(test)]
mod tests;
mod thread_rt;

pub use crew::{Crew, CrewPlan, HELPER_RELEASE_GRACE_NS, prefetch_joints};
use rt_setup::start;
pub use rt_setup::{RtSetup, RtSetupError};
pub use stats::{FineHistogram, HelperReport, RtSummary, RtThreadReport, ThreadUsage};
use thread_rt::sched_of_self;
pub use thread_rt::{RtRefusal, ThreadRt};

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
    /// Runtime changes applied at a tick boundary (step 2b).
    pub control_applied: AtomicU64,
    /// Runtime changes dropped because a reload replaced the parameters they were checked against.
    pub control_dropped: AtomicU64,
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
        &mut cmd.tau_f_model_nm,
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
/// `i_a`, `flags`, `tau_f_out` (the law's τ̂_F, after kfc, clip and filter) and `model_out` (the
/// estimate the law was given). Returns the bits of the joints that ran the normal path.
#[inline]
pub fn compute_joints(
    joints: &mut [JointRt],
    cx: &TickCtx<'_>,
    i_a: &mut [f64; MAX_JOINTS],
    flags: &mut [u32; MAX_JOINTS],
    tau_f_out: &mut [f64; MAX_JOINTS],
    model_out: &mut [f64; MAX_JOINTS],
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
            } else if j.model_switched {
                // A model switched in at run time starts fresh; the law's state is kept.
                j.model.reset(&sample);
            }
            j.model_switched = false;
            active |= bit;
            let model_nm = j.model.estimate(&sample);
            // Out of the training range: flagged, counted (Telemetry::record) and, with a static
            // model configured, blended to it over the ramp.
            let ood = j.ood.out_of_range(&j.model, &sample);
            let f = j.ood.blend(model_nm, ood, &sample);
            let o = j.law.step(&LawInput {
                tau_des_nm: rq.tau_des_nm[k],
                // Compensation switched off at run time: the model runs on, the law gets 0.
                friction_nm: if j.compensation { f } else { 0.0 },
                sdot_rad_s: sample.sdot_rad_s,
                tau_meas_nm: st.tau_meas_nm[k],
            });
            let warming = if warming_up(&j.model) {
                FLAG_WARMING_UP
            } else {
                0
            };
            let ood_flag = if ood { FLAG_OUT_OF_RANGE } else { 0 };
            JointOut {
                tau_f_model_nm: f,
                ..JointOut::from_law(o, warming | ood_flag)
            }
        };
        i_a[k] = out.i_a;
        flags[k] = out.flags;
        tau_f_out[k] = out.tau_f_hat_nm;
        model_out[k] = out.tau_f_model_nm;
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
    /// The estimate the law was given (0 off the model path).
    tau_f_model_nm: f64,
    flags: u32,
}

impl JointOut {
    /// Zero current, no compensation, `flags`.
    #[inline]
    fn zero(flags: u32) -> Self {
        Self {
            i_a: 0.0,
            tau_f_hat_nm: 0.0,
            tau_f_model_nm: 0.0,
            flags,
        }
    }

    /// The law's output with its flags mapped to the ABI, plus `extra` `FLAG_*` bits.
    #[inline]
    fn from_law(o: LawOutput, extra: u32) -> Self {
        Self {
            i_a: o.i_a,
            tau_f_hat_nm: o.tau_f_hat_nm,
            tau_f_model_nm: 0.0,
            flags: abi_flags(o.flags) | extra,
        }
    }
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

/// Most runtime changes applied in one tick (the rest wait for the next: the step stays bounded).
pub const MAX_RUNTIME_SETS_PER_TICK: usize = 64;

/// Step 2b: applies up to [`MAX_RUNTIME_SETS_PER_TICK`] waiting runtime changes to `p` (allocation-
/// and lock-free: `try_recv` on a bounded queue of `Copy` values). A change for another generation
/// than `p`'s (a reload came in between) or a joint index `p` does not have is dropped. Returns
/// `(applied, dropped)`.
#[inline]
pub fn apply_runtime_sets(p: &mut Params, rx: &Receiver<RuntimeSet>) -> (u64, u64) {
    let (mut applied, mut dropped) = (0, 0);
    for _ in 0..MAX_RUNTIME_SETS_PER_TICK {
        let Ok(set) = rx.try_recv() else { break };
        let joint = if set.generation == p.generation {
            p.joints.iter_mut().find(|j| j.index == set.joint_index)
        } else {
            None
        };
        match joint {
            Some(j) => {
                j.apply(set.change);
                applied += 1;
            }
            None => dropped += 1,
        }
    }
    (applied, dropped)
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
        s.control_applied = shared.control_applied.load(Ordering::Relaxed);
        s.control_dropped = shared.control_dropped.load(Ordering::Relaxed);
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
    cmd.tau_f_model_nm = [0.0; MAX_JOINTS];
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
        rx_control,
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
        // 2b. runtime changes, at the same boundary (never while the helper holds its half)
        if helper_free {
            let (applied, dropped) = apply_runtime_sets(&mut slot.params, &rx_control);
            if applied > 0 {
                shared.control_applied.fetch_add(applied, Ordering::Relaxed);
            }
            if dropped > 0 {
                shared.control_dropped.fetch_add(dropped, Ordering::Relaxed);
            }
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
