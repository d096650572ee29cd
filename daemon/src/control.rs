//! The supervisor's side of runtime control (`<prefix>/control`): answers get and set requests,
//! checks a set by the file's rules ([`crate::runtime::check`]), queues it for the RT thread
//! (bounded, `try_send`: the supervisor never blocks on it) and keeps the values in use with the
//! time each was set, for gets.
//!
//! What this module **is**: the answer to one request, off the RT thread (it allocates and logs).
//! What it is **not**: the transport (`frictionless_shm_types::control`) or the application of a
//! change (step 2b of the tick, `rt::apply_runtime_sets`).
//!
//! Precedence: the file's values hold from a load or reload on; a set replaces one value until the
//! next reload, which restores every value to the (new) file's ([`ControlState::reset`]).

use std::sync::mpsc::{SyncSender, TrySendError};
use std::time::{Duration, Instant};

use frictionless_shm_types::control::{
    CONTROL_BAD_REQUEST, CONTROL_BUSY, CONTROL_KEYS, CONTROL_OK, CONTROL_OP_GET, CONTROL_OP_SET,
    CONTROL_REFUSED, CONTROL_WRITES_DISABLED, ControlRequest, ControlResponse, put_text, text,
};

use crate::config::{Config, OodMode};
use crate::runtime::{Change, RuntimeSet, check, model_kind, model_names};

/// One joint's values in use and when each was set at run time (0 = the file's).
#[derive(Debug, Clone)]
struct JointValues {
    kfc: f64,
    max_output_friction_nm: f64,
    max_curr_a: f64,
    compensation: bool,
    ood: OodMode,
    /// Slot of the active model ([`model_names`]' order).
    model_slot: usize,
    /// Ticks completed when the model set was queued (0 = the file's).
    model_since_tick: u64,
    set_since_ns: [u64; CONTROL_KEYS.len()],
}

/// Log lines per [`LOG_WINDOW`] at most; the rest are counted into the next line.
const LOG_LINES_PER_WINDOW: u32 = 20;
/// The window of [`LOG_LINES_PER_WINDOW`].
const LOG_WINDOW: Duration = Duration::from_secs(1);

/// What gets report: per joint of the file in use, its values; the generation and its load time.
#[derive(Debug, Clone)]
pub struct ControlState {
    generation: u64,
    since_ns: u64,
    joints: Vec<JointValues>,
    log_window: Option<Instant>,
    log_lines: u32,
    unlogged: u64,
}

fn ood_code(m: OodMode) -> u32 {
    match m {
        OodMode::Off => 0,
        OodMode::Flag => 1,
        OodMode::Static => 2,
    }
}

impl ControlState {
    /// The file's values of `cfg` (generation `generation`, loaded at `now_ns`).
    pub fn new(cfg: &Config, generation: u64, now_ns: u64) -> Self {
        let mut s = Self {
            generation,
            since_ns: now_ns,
            joints: Vec::new(),
            log_window: None,
            log_lines: 0,
            unlogged: 0,
        };
        s.reset(cfg, generation, now_ns);
        s
    }

    /// A reload: every value back to the file's.
    pub fn reset(&mut self, cfg: &Config, generation: u64, now_ns: u64) {
        self.generation = generation;
        self.since_ns = now_ns;
        self.joints = cfg
            .raw
            .joint
            .iter()
            .map(|j| JointValues {
                kfc: j.kfc,
                max_output_friction_nm: j.max_output_friction,
                max_curr_a: j.max_curr,
                compensation: true,
                ood: j.ood,
                model_slot: 0,
                model_since_tick: 0,
                set_since_ns: [0; CONTROL_KEYS.len()],
            })
            .collect();
    }

    /// The parameter generation the values belong to.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Answers `req` against `cfg` (the file in use). A valid set is queued on `tx` for the RT
    /// thread; `writes` is `[control] writes`; `ticks` the RT thread's ticks completed so far (a
    /// queued set applies from the next one). Logs sets and refusals (rate-limited).
    pub fn answer(
        &mut self,
        cfg: &Config,
        writes: bool,
        req: &ControlRequest,
        tx: &SyncSender<RuntimeSet>,
        now_ns: u64,
        ticks: u64,
    ) -> ControlResponse {
        let (Some(joint), Some(key), Some(value)) =
            (text(&req.joint), text(&req.key), text(&req.value))
        else {
            return ControlResponse::with(CONTROL_BAD_REQUEST, "request text is not UTF-8");
        };
        let Some(pos) = cfg.raw.joint.iter().position(|j| j.name == joint) else {
            let names: Vec<&str> = cfg.raw.joint.iter().map(|j| j.name.as_str()).collect();
            let msg = format!(
                "joint `{joint}`: no such joint (configured: {})",
                names.join(", ")
            );
            return ControlResponse::with(CONTROL_REFUSED, &msg);
        };
        match req.op {
            CONTROL_OP_GET => self.view(cfg, pos, CONTROL_OK, "ok"),
            CONTROL_OP_SET if !writes => {
                let msg = format!(
                    "joint `{joint}`: `{key}` = {value}: runtime writes are disabled ([control] writes = false in {})",
                    cfg.file.display()
                );
                self.log(true, &format!("refused: {msg}"));
                self.view(cfg, pos, CONTROL_WRITES_DISABLED, &msg)
            }
            CONTROL_OP_SET => match check(cfg, self.generation, joint, key, value) {
                Err(refusal) => {
                    let msg = refusal.to_string();
                    self.log(true, &format!("refused: {msg}"));
                    self.view(cfg, pos, CONTROL_REFUSED, &msg)
                }
                Ok(set) => match tx.try_send(set) {
                    Ok(()) => {
                        self.record(pos, set.change, now_ns, ticks);
                        let msg = format!(
                            "joint `{joint}`: `{key}` = {value}: applied from the next tick (generation {})",
                            self.generation
                        );
                        self.log(false, &msg);
                        self.view(cfg, pos, CONTROL_OK, &msg)
                    }
                    Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                        let msg = format!(
                            "joint `{joint}`: `{key}` = {value}: the RT thread's queue is full, try again"
                        );
                        self.log(true, &msg);
                        self.view(cfg, pos, CONTROL_BUSY, &msg)
                    }
                },
            },
            op => ControlResponse::with(CONTROL_BAD_REQUEST, &format!("unknown op {op}")),
        }
    }

    /// Logs a set (`warn`: a refusal) — at most [`LOG_LINES_PER_WINDOW`] lines per
    /// [`LOG_WINDOW`], so a client that sets every millisecond cannot flood the journal; the lines
    /// left out are counted into the next one.
    fn log(&mut self, warn: bool, msg: &str) {
        let now = Instant::now();
        if self
            .log_window
            .is_none_or(|t| now.duration_since(t) >= LOG_WINDOW)
        {
            self.log_window = Some(now);
            self.log_lines = 0;
        }
        if self.log_lines >= LOG_LINES_PER_WINDOW {
            self.unlogged += 1;
            return;
        }
        self.log_lines += 1;
        let more = std::mem::take(&mut self.unlogged);
        let more = if more > 0 {
            format!(" ({more} earlier control requests not logged)")
        } else {
            String::new()
        };
        if warn {
            tracing::warn!("control: {msg}{more}");
        } else {
            tracing::info!("control: {msg}{more}");
        }
    }

    fn record(&mut self, pos: usize, change: Change, now_ns: u64, ticks: u64) {
        let v = &mut self.joints[pos];
        match change {
            Change::Kfc(x) => v.kfc = x,
            Change::MaxOutputFriction(x) => v.max_output_friction_nm = x,
            Change::MaxCurr(x) => v.max_curr_a = x,
            Change::Compensation(on) => v.compensation = on,
            Change::Ood(m) => v.ood = m,
            Change::Model(slot) => {
                v.model_slot = slot;
                v.model_since_tick = ticks;
            }
        }
        if let Some(k) = CONTROL_KEYS.iter().position(|&k| k == change.key()) {
            v.set_since_ns[k] = now_ns;
        }
    }

    fn view(&self, cfg: &Config, pos: usize, status: u32, msg: &str) -> ControlResponse {
        let v = &self.joints[pos];
        let mut r = ControlResponse::with(status, msg);
        r.joint_index = cfg.raw.joint[pos].index as u32;
        r.generation = self.generation;
        r.generation_since_ns = self.since_ns;
        r.kfc = v.kfc;
        r.max_output_friction_nm = v.max_output_friction_nm;
        r.max_curr_a = v.max_curr_a;
        r.compensation = u32::from(v.compensation);
        r.ood_mode = ood_code(v.ood);
        r.model_kind = u32::from(model_kind(cfg, pos, v.model_slot).code());
        r.set_since_ns = v.set_since_ns;
        let names = model_names(cfg, pos);
        // The names fit: the config's rule keeps them shorter than the field.
        put_text(
            &mut r.model,
            names.get(v.model_slot).copied().unwrap_or("?"),
        );
        r.model_since_tick = v.model_since_tick;
        r.set_models(names);
        r
    }
}
