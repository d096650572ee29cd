//! A client of a running frictiond's runtime control service (`<prefix>/control`, iceoryx2
//! request–response): per joint, get the values in use and set one of `kfc`,
//! `max_output_friction`, `max_curr`, `compensation` (`on` / `off`), `ood`, `model` (the name of
//! one of the joint's preloaded models), written as in the config.
//!
//! It is `frictionless_shm_types::control`'s [`ControlClient`] and payloads as `frictl ctl` and the
//! Python package use them: the daemon checks every value by its config's rules; this module has no
//! checks, codes or names of its own beyond copying its answer into [`fl_control_state`].
//!
//! An [`fl_control`] is bound to the thread that opened it (iceoryx2's ports are single-threaded):
//! a call from another thread is refused with `FL_STATUS_INVALID_ARGUMENT`. Each call allocates and
//! waits for the daemon's answer (at most the handle's timeout): not for a real-time thread.

use std::ffi::{CString, c_char};
use std::path::Path;
use std::sync::OnceLock;
use std::thread::ThreadId;
use std::time::Duration;

use frictionless_shm_types::control::{
    CONTROL_BAD_REQUEST, CONTROL_BUSY, CONTROL_KEYS, CONTROL_MESSAGE_BYTES, CONTROL_OK,
    CONTROL_REFUSED, CONTROL_TEXT_BYTES, CONTROL_WRITES_DISABLED, ControlClient, ControlRequest,
    ControlResponse, access_refusal, ood_mode_name,
};
use frictionless_shm_types::{Ipc, IpcConfig, ShmError};

use crate::{Fail, arg, arg_mut, arg_str, fl_status, guard};

/// Bytes of [`fl_control_state::model`]: the daemon's 64-byte name field plus a NUL.
pub const FL_CONTROL_NAME_CAPACITY: usize = 65;
/// Bytes of [`fl_control_state::message`]: the daemon's 256-byte message field plus a NUL.
pub const FL_CONTROL_MESSAGE_CAPACITY: usize = 257;
/// Bytes of [`fl_control_state::models`]: the daemon's 256-byte list, each name NUL-terminated,
/// plus the empty name that ends the list.
pub const FL_CONTROL_MODELS_CAPACITY: usize = 258;
/// Number of runtime keys, the length of [`fl_control_state::set_since_ns`].
pub const FL_CONTROL_N_KEYS: usize = 6;

/// Index of `kfc` in [`fl_control_state::set_since_ns`] ([`fl_control_key_name`] names each).
pub const FL_CONTROL_KEY_KFC: u32 = 0;
/// Index of `max_output_friction`.
pub const FL_CONTROL_KEY_MAX_OUTPUT_FRICTION: u32 = 1;
/// Index of `max_curr`.
pub const FL_CONTROL_KEY_MAX_CURR: u32 = 2;
/// Index of `compensation`.
pub const FL_CONTROL_KEY_COMPENSATION: u32 = 3;
/// Index of `ood`.
pub const FL_CONTROL_KEY_OOD: u32 = 4;
/// Index of `model`.
pub const FL_CONTROL_KEY_MODEL: u32 = 5;

/// [`fl_control_state::control_status`]: done (a set applies from the daemon's next tick on).
pub const FL_CONTROL_OK: u32 = 0;
/// The value breaks a rule, or the joint, key or model is unknown (the message names it).
pub const FL_CONTROL_REFUSED: u32 = 1;
/// Runtime writes are disabled by the daemon's config (`[control] writes = false`).
pub const FL_CONTROL_WRITES_DISABLED: u32 = 2;
/// The daemon's queue to its RT thread is full; try again.
pub const FL_CONTROL_BUSY: u32 = 3;
/// The request itself is malformed.
pub const FL_CONTROL_BAD_REQUEST: u32 = 4;

/// [`fl_control_state::ood_mode`]: out-of-distribution monitoring off ([`fl_ood_mode_name`]).
pub const FL_OOD_OFF: u32 = 0;
/// Out-of-distribution inputs are flagged.
pub const FL_OOD_FLAG: u32 = 1;
/// Out-of-distribution inputs fall back to the joint's static model.
pub const FL_OOD_STATIC: u32 = 2;

// The literals above are what cbindgen can write into the header; they are the transport's values.
const _: () = {
    assert!(FL_CONTROL_NAME_CAPACITY == CONTROL_TEXT_BYTES + 1);
    assert!(FL_CONTROL_MESSAGE_CAPACITY == CONTROL_MESSAGE_BYTES + 1);
    assert!(FL_CONTROL_MODELS_CAPACITY == CONTROL_MESSAGE_BYTES + 2);
    assert!(FL_CONTROL_N_KEYS == CONTROL_KEYS.len());
    assert!(FL_CONTROL_KEY_MODEL as usize == CONTROL_KEYS.len() - 1);
    assert!(FL_CONTROL_OK == CONTROL_OK);
    assert!(FL_CONTROL_REFUSED == CONTROL_REFUSED);
    assert!(FL_CONTROL_WRITES_DISABLED == CONTROL_WRITES_DISABLED);
    assert!(FL_CONTROL_BUSY == CONTROL_BUSY);
    assert!(FL_CONTROL_BAD_REQUEST == CONTROL_BAD_REQUEST);
};

/// The iceoryx2 node name of every handle.
const NODE_NAME: &str = "libfrictionless-control";

/// A connection to one frictiond deployment's control service. Opaque; bound to the thread that
/// opened it.
pub struct fl_control {
    // Declared before `ipc`: the port is dropped before its node.
    client: ControlClient,
    ipc: Ipc,
    owner: ThreadId,
    timeout: Duration,
}

/// One joint's values in use in the daemon, as its answer carries them (filled by
/// [`fl_control_get`] and [`fl_control_set`]). The texts are NUL-terminated UTF-8 copies: the
/// struct owns everything and may be copied freely.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct fl_control_state {
    /// The daemon's status, `FL_CONTROL_*` (`FL_CONTROL_OK` unless the call returned
    /// `FL_STATUS_REFUSED`).
    pub control_status: u32,
    /// The joint's payload index (`UINT32_MAX`, and every value 0, when the joint is unknown).
    pub joint_index: u32,
    /// Parameter generation the values belong to (+1 per reload; a reload drops runtime values).
    pub generation: u64,
    /// CLOCK_MONOTONIC time [ns] at which this generation's file was loaded.
    pub generation_since_ns: u64,
    /// kfc in use.
    pub kfc: f64,
    /// max_output_friction [Nm] in use (infinite: no clip).
    pub max_output_friction_nm: f64,
    /// max_curr [A] in use.
    pub max_curr_a: f64,
    /// Whether compensation is on.
    pub compensation: bool,
    /// OOD mode, `FL_OOD_*`.
    pub ood_mode: u32,
    /// Kind code of the active model (`fl_model_kind_name` names it).
    pub model_kind: u8,
    /// Name of the active model: `default` (the joint's own `friction_model`), an alternate's
    /// `name`, or `none`.
    pub model: [c_char; FL_CONTROL_NAME_CAPACITY],
    /// The active model runs from the tick after this many ticks completed (0 = since the load).
    pub model_since_tick: u64,
    /// Number of names in `models`.
    pub n_models: u32,
    /// The joint's preloaded model names (`default`, its alternates in file order, `none`), each
    /// NUL-terminated, one after the other; an empty name ends the list. A last name `…` means the
    /// daemon's list did not fit its answer.
    pub models: [c_char; FL_CONTROL_MODELS_CAPACITY],
    /// Per key (`FL_CONTROL_KEY_*`): CLOCK_MONOTONIC time [ns] of the runtime set in use, 0 = the
    /// file's value.
    pub set_since_ns: [u64; FL_CONTROL_N_KEYS],
    /// The daemon's message: `ok`, what a set did, or for a refusal the joint, key, value and the
    /// rule it breaks.
    pub message: [c_char; FL_CONTROL_MESSAGE_CAPACITY],
}

/// Copies `s` NUL-terminated into `dst` (cut at a character boundary if it does not fit).
fn put(dst: &mut [c_char], s: &str) {
    let mut n = s.len().min(dst.len() - 1);
    while !s.is_char_boundary(n) {
        n -= 1;
    }
    for (d, &b) in dst.iter_mut().zip(&s.as_bytes()[..n]) {
        *d = b as c_char;
    }
    dst[n..].fill(0);
}

impl From<&ControlResponse> for fl_control_state {
    fn from(r: &ControlResponse) -> Self {
        let mut s = fl_control_state {
            control_status: r.status,
            joint_index: r.joint_index,
            generation: r.generation,
            generation_since_ns: r.generation_since_ns,
            kfc: r.kfc,
            max_output_friction_nm: r.max_output_friction_nm,
            max_curr_a: r.max_curr_a,
            compensation: r.compensation != 0,
            ood_mode: r.ood_mode,
            model_kind: u8::try_from(r.model_kind).unwrap_or(u8::MAX),
            model: [0; FL_CONTROL_NAME_CAPACITY],
            model_since_tick: r.model_since_tick,
            n_models: 0,
            models: [0; FL_CONTROL_MODELS_CAPACITY],
            set_since_ns: r.set_since_ns,
            message: [0; FL_CONTROL_MESSAGE_CAPACITY],
        };
        put(&mut s.model, r.model());
        put(&mut s.message, r.message());
        let mut at = 0;
        for name in r.models() {
            // The list fits by the capacities' definition; stop rather than cut a name if not.
            if at + name.len() + 2 > FL_CONTROL_MODELS_CAPACITY {
                break;
            }
            put(&mut s.models[at..at + name.len() + 1], name);
            at += name.len() + 1;
            s.n_models += 1;
        }
        s
    }
}

/// The failure of an iceoryx2 step: `FL_STATUS_INVALID_ARGUMENT` for a name iceoryx2 refuses,
/// else `FL_STATUS_IPC`; who may connect when another user owns the root path.
fn ipc_fail(what: &str, cfg: &IpcConfig, e: &ShmError) -> Fail {
    let line = fl_core::error_line(e);
    match (e, access_refusal(cfg)) {
        (ShmError::InvalidName { .. }, _) => {
            Fail::owned(fl_status::InvalidArgument, format!("{what}: {line}"))
        }
        (_, Some(why)) => Fail::owned(fl_status::Ipc, format!("{what}: {why} ({line})")),
        (_, None) => Fail::owned(fl_status::Ipc, format!("{what}: {line}")),
    }
}

/// Opens a client of the control service of the frictiond deployment `service_prefix` (its
/// `[backend] service_prefix`) under the iceoryx2 root `root_path` (its `[backend] root_path`;
/// NULL: iceoryx2's default) and stores the handle in `*out`. Each call through it waits at most
/// `timeout_ms` (≥ 1) for the daemon's answer. Opening does not need the daemon to be running; a
/// call without one fails at once with `FL_STATUS_IPC`.
///
/// Errors: NULL (`out`, `service_prefix`), non-UTF-8 text, `timeout_ms` = 0 or a name iceoryx2
/// refuses: `FL_STATUS_INVALID_ARGUMENT`; iceoryx2 failing (e.g. the root path belongs to another
/// user; the message says who may connect): `FL_STATUS_IPC`. The handle belongs to the calling
/// thread; close it with [`fl_control_close`] from that thread. Allocates.
///
/// # Safety
/// `service_prefix` and `root_path` are NULL or NUL-terminated strings; `out` is NULL or points to
/// writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_control_open(
    service_prefix: *const c_char,
    root_path: *const c_char,
    timeout_ms: u32,
    out: *mut *mut fl_control,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_control_open: `out` is NULL") }?;
        // SAFETY: caller contract.
        let prefix = unsafe {
            arg_str(
                service_prefix,
                "fl_control_open: `service_prefix` is NULL",
                "fl_control_open: `service_prefix` is not valid UTF-8",
            )
        }?;
        let root = if root_path.is_null() {
            None
        } else {
            // SAFETY: caller contract; non-null.
            Some(unsafe {
                arg_str(
                    root_path,
                    "fl_control_open: `root_path` is NULL",
                    "fl_control_open: `root_path` is not valid UTF-8",
                )
            }?)
        };
        if timeout_ms == 0 {
            return Err(Fail::fixed(
                fl_status::InvalidArgument,
                "fl_control_open: `timeout_ms` = 0: expected at least 1 ms",
            ));
        }
        let cfg = IpcConfig::new(root.map(Path::new), prefix);
        let ipc = Ipc::open(&cfg, NODE_NAME).map_err(|e| ipc_fail("fl_control_open", &cfg, &e))?;
        let client = ipc
            .control_client()
            .map_err(|e| ipc_fail("fl_control_open", &cfg, &e))?;
        *out = Box::into_raw(Box::new(fl_control {
            client,
            ipc,
            owner: std::thread::current().id(),
            timeout: Duration::from_millis(u64::from(timeout_ms)),
        }));
        Ok(())
    })
}

/// The handle behind `ctl` if this thread owns it.
///
/// # Safety
/// `ctl` is NULL or a live handle.
unsafe fn owned<'a>(ctl: *const fl_control, what: &'static str) -> Result<&'a fl_control, Fail> {
    // SAFETY: caller contract.
    let c = unsafe { arg(ctl, what) }?;
    if std::thread::current().id() != c.owner {
        return Err(Fail::fixed(
            fl_status::InvalidArgument,
            "fl_control: the handle is used from a thread other than the one that opened it \
             (iceoryx2's ports are single-threaded; open one handle per thread)",
        ));
    }
    Ok(c)
}

/// Sends `req` about `joint` and copies the answer into `out`; a refusal is `FL_STATUS_REFUSED`
/// with `out` filled.
fn call(
    c: &fl_control,
    what: &str,
    joint: &str,
    req: &ControlRequest,
    out: &mut fl_control_state,
) -> Result<(), Fail> {
    let r = c
        .client
        .call(req, c.timeout)
        .map_err(|e| ipc_fail(&format!("{what}: joint `{joint}`"), c.ipc.config(), &e))?;
    *out = fl_control_state::from(&r);
    if r.status != CONTROL_OK {
        return Err(Fail::owned(
            fl_status::Refused,
            format!("{what}: frictiond refused: {}", r.message()),
        ));
    }
    Ok(())
}

/// Reads joint `joint`'s values in use (`[[joint]] name`) into `*out`. An unknown joint is
/// `FL_STATUS_REFUSED` (the message lists the configured ones) with `*out` holding the answer; no
/// daemon, or no answer within the timeout: `FL_STATUS_IPC`. Blocks up to the handle's timeout;
/// allocates.
///
/// # Safety
/// `ctl` is NULL or a live handle; `joint` is NULL or a NUL-terminated string; `out` is NULL or
/// points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_control_get(
    ctl: *mut fl_control,
    joint: *const c_char,
    out: *mut fl_control_state,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let c = unsafe { owned(ctl, "fl_control_get: `ctl` is NULL") }?;
        // SAFETY: caller contract.
        let joint = unsafe {
            arg_str(
                joint,
                "fl_control_get: `joint` is NULL",
                "fl_control_get: `joint` is not valid UTF-8",
            )
        }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_control_get: `out` is NULL") }?;
        let req = ControlRequest::get(joint).ok_or_else(|| {
            Fail::owned(
                fl_status::InvalidArgument,
                format!(
                    "fl_control_get: joint `{joint}` is longer than {CONTROL_TEXT_BYTES} bytes"
                ),
            )
        })?;
        call(c, "fl_control_get", joint, &req, out)
    })
}

/// Sets `key` of joint `joint` to `value`, written as in the config (`kfc` `0.5`, `compensation`
/// `off`, `model` `scv_b`, …); the daemon checks it by its config's rules and applies it from its
/// next tick until a reload. `*out` receives the joint's values after the set. A refused value (the
/// message names the joint, key, value and rule; also an unknown joint, key or model, writes
/// disabled, the daemon's queue full) is `FL_STATUS_REFUSED` with `*out` holding the daemon's
/// answer (`control_status`, `message`, the values still in use); no daemon or no answer within the
/// timeout: `FL_STATUS_IPC`. Blocks up to the handle's timeout; allocates.
///
/// # Safety
/// `ctl` is NULL or a live handle; `joint`, `key`, `value` are NULL or NUL-terminated strings;
/// `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_control_set(
    ctl: *mut fl_control,
    joint: *const c_char,
    key: *const c_char,
    value: *const c_char,
    out: *mut fl_control_state,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let c = unsafe { owned(ctl, "fl_control_set: `ctl` is NULL") }?;
        // SAFETY (the three texts): caller contract.
        let joint = unsafe {
            arg_str(
                joint,
                "fl_control_set: `joint` is NULL",
                "fl_control_set: `joint` is not valid UTF-8",
            )
        }?;
        // SAFETY: caller contract.
        let key = unsafe {
            arg_str(
                key,
                "fl_control_set: `key` is NULL",
                "fl_control_set: `key` is not valid UTF-8",
            )
        }?;
        // SAFETY: caller contract.
        let value = unsafe {
            arg_str(
                value,
                "fl_control_set: `value` is NULL",
                "fl_control_set: `value` is not valid UTF-8",
            )
        }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_control_set: `out` is NULL") }?;
        let req = ControlRequest::set(joint, key, value).ok_or_else(|| {
            Fail::owned(
                fl_status::InvalidArgument,
                format!(
                    "fl_control_set: joint `{joint}`, key `{key}` and value `{value}` must each \
                     fit {CONTROL_TEXT_BYTES} bytes"
                ),
            )
        })?;
        call(c, "fl_control_set", joint, &req, out)
    })
}

/// Closes `ctl` (its iceoryx2 port and node). Does nothing for NULL. From a thread other than the
/// one that opened it: `FL_STATUS_INVALID_ARGUMENT` and the handle stays open (close it from its
/// thread).
///
/// # Safety
/// `ctl` is NULL or a live handle; after `FL_STATUS_OK` it is dead.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_control_close(ctl: *mut fl_control) -> fl_status {
    guard(|| {
        if ctl.is_null() {
            return Ok(());
        }
        // SAFETY: caller contract; non-null.
        unsafe { owned(ctl, "fl_control_close: `ctl` is NULL") }?;
        // SAFETY: a live handle comes from `Box::into_raw` in `fl_control_open`; this thread owns it.
        drop(unsafe { Box::from_raw(ctl) });
        Ok(())
    })
}

/// The name of key index `index` (`FL_CONTROL_KEY_*`: `"kfc"`, …, `"model"`), static and
/// NUL-terminated; NULL for `index ≥ FL_CONTROL_N_KEYS`.
#[unsafe(no_mangle)]
pub extern "C" fn fl_control_key_name(index: u32) -> *const c_char {
    static NAMES: OnceLock<Vec<CString>> = OnceLock::new();
    let names = NAMES.get_or_init(|| {
        CONTROL_KEYS
            .iter()
            .filter_map(|k| CString::new(*k).ok())
            .collect()
    });
    names
        .get(index as usize)
        .map_or(std::ptr::null(), |n| n.as_ptr())
}

/// The name of OOD mode `code` (`FL_OOD_*`: `"off"`, `"flag"`, `"static"`, the config's values),
/// static and NUL-terminated; NULL for a code no mode has.
#[unsafe(no_mangle)]
pub extern "C" fn fl_ood_mode_name(code: u32) -> *const c_char {
    static NAMES: OnceLock<Vec<CString>> = OnceLock::new();
    let names = NAMES.get_or_init(|| {
        (0..)
            .map(ood_mode_name)
            .take_while(|n| *n != "?")
            .filter_map(|n| CString::new(n).ok())
            .collect()
    });
    names
        .get(code as usize)
        .map_or(std::ptr::null(), |n| n.as_ptr())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::CStr;
    use std::ptr;

    fn last() -> String {
        // SAFETY: fl_last_error never returns NULL and the buffer is NUL-terminated.
        unsafe { CStr::from_ptr(crate::fl_last_error()) }
            .to_string_lossy()
            .into_owned()
    }

    fn names(p: impl Fn(u32) -> *const c_char) -> Vec<String> {
        (0..)
            .map(p)
            .take_while(|n| !n.is_null())
            // SAFETY: a non-NULL result is a static NUL-terminated string.
            .map(|n| unsafe { CStr::from_ptr(n) }.to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn key_and_ood_names_are_the_transports() {
        assert_eq!(names(|i| fl_control_key_name(i)), CONTROL_KEYS);
        assert_eq!(names(|i| fl_ood_mode_name(i)), ["off", "flag", "static"]);
        for (code, want) in [
            (FL_OOD_OFF, "off"),
            (FL_OOD_FLAG, "flag"),
            (FL_OOD_STATIC, "static"),
        ] {
            assert_eq!(ood_mode_name(code), want);
        }
        for (index, key) in [
            (FL_CONTROL_KEY_KFC, "kfc"),
            (FL_CONTROL_KEY_MAX_OUTPUT_FRICTION, "max_output_friction"),
            (FL_CONTROL_KEY_MAX_CURR, "max_curr"),
            (FL_CONTROL_KEY_COMPENSATION, "compensation"),
            (FL_CONTROL_KEY_OOD, "ood"),
            (FL_CONTROL_KEY_MODEL, "model"),
        ] {
            assert_eq!(CONTROL_KEYS[index as usize], key);
        }
    }

    /// The answer's texts become NUL-terminated copies; the model list one name per entry, cut
    /// lists keeping their `…`.
    #[test]
    fn a_response_is_copied_whole() {
        let text = |a: &[c_char]| {
            // SAFETY: `put` NUL-terminates within the array.
            unsafe { CStr::from_ptr(a.as_ptr()) }
                .to_str()
                .unwrap()
                .to_owned()
        };
        let list = |s: &fl_control_state| {
            let mut v = Vec::new();
            let mut at = 0;
            while s.models[at] != 0 {
                let n = text(&s.models[at..]);
                at += n.len() + 1;
                v.push(n);
            }
            v
        };
        let mut r =
            ControlResponse::with(CONTROL_REFUSED, "joint `k`: `kfc` = 3: must be in [0, 2]");
        r.kfc = 0.4;
        r.model_kind = 2;
        r.set_since_ns[FL_CONTROL_KEY_KFC as usize] = 17;
        frictionless_shm_types::control::put_text(&mut r.model, &"m".repeat(CONTROL_TEXT_BYTES));
        r.set_models(["default", "scv_b", "none"]);
        let s = fl_control_state::from(&r);
        assert_eq!(s.control_status, FL_CONTROL_REFUSED);
        assert_eq!((s.kfc, s.model_kind, s.set_since_ns[0]), (0.4, 2, 17));
        assert_eq!(text(&s.message), r.message());
        assert_eq!(text(&s.model), "m".repeat(CONTROL_TEXT_BYTES));
        assert_eq!(
            (s.n_models, list(&s)),
            (3, vec!["default".to_owned(), "scv_b".into(), "none".into()])
        );
        // The longest list the daemon sends fits, `…` included.
        let long = "n".repeat(60);
        r.set_models(std::iter::repeat_n(long.as_str(), 10));
        let s = fl_control_state::from(&r);
        let got = list(&s);
        assert_eq!(got.len(), s.n_models as usize);
        assert_eq!(got, r.models().collect::<Vec<_>>());
        assert_eq!(got.last().map(String::as_str), Some("…"));
        let mut full = ControlResponse::with(CONTROL_OK, "ok");
        full.models.fill(b'a');
        full.models[1..]
            .iter_mut()
            .step_by(2)
            .for_each(|b| *b = b',');
        let s = fl_control_state::from(&full);
        assert_eq!(s.n_models, 128);
        assert_eq!(list(&s), full.models().collect::<Vec<_>>());
    }

    #[test]
    fn bad_arguments_are_refused_naming_them() {
        let prefix = c"fl_capi_args";
        let dir = std::env::temp_dir().join(format!("fl_capi_args_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let root = CString::new(dir.to_str().unwrap()).unwrap();
        // Longer than iceoryx2's service names allow.
        let too_long = CString::new("x".repeat(300)).unwrap();
        let bad = [0xff_u8, 0xfe, 0];
        let bad = bad.as_ptr() as *const c_char;
        let mut st = std::mem::MaybeUninit::<fl_control_state>::zeroed();
        // SAFETY (whole test): valid or NULL pointers as each case says; the handle is closed here.
        unsafe {
            let mut c = ptr::null_mut();
            for (status, args, what) in [
                (
                    fl_status::NullPointer,
                    (ptr::null(), root.as_ptr(), 100),
                    "`service_prefix` is NULL",
                ),
                (
                    fl_status::InvalidArgument,
                    (bad, root.as_ptr(), 100),
                    "`service_prefix` is not valid UTF-8",
                ),
                (
                    fl_status::InvalidArgument,
                    (prefix.as_ptr(), bad, 100),
                    "`root_path` is not valid UTF-8",
                ),
                (
                    fl_status::InvalidArgument,
                    (prefix.as_ptr(), root.as_ptr(), 0),
                    "`timeout_ms` = 0",
                ),
                (
                    fl_status::InvalidArgument,
                    (too_long.as_ptr(), root.as_ptr(), 100),
                    "service name",
                ),
            ] {
                assert_eq!(
                    fl_control_open(args.0, args.1, args.2, &mut c),
                    status,
                    "{what}"
                );
                assert!(last().contains(what), "{what}: {}", last());
                assert!(c.is_null());
            }
            assert_eq!(
                fl_control_open(prefix.as_ptr(), root.as_ptr(), 100, ptr::null_mut()),
                fl_status::NullPointer
            );
            assert_eq!(
                fl_control_open(prefix.as_ptr(), root.as_ptr(), 100, &mut c),
                fl_status::Ok,
                "{}",
                last()
            );
            let out = st.as_mut_ptr();
            let long = CString::new("j".repeat(CONTROL_TEXT_BYTES + 1)).unwrap();
            let check = |got: fl_status, status: fl_status, what: &str| {
                assert_eq!(got, status, "{what}");
                assert!(last().contains(what), "{what}: {}", last());
            };
            let a = c"a".as_ptr();
            let kfc = c"kfc".as_ptr();
            let null = ptr::null();
            use fl_status::{InvalidArgument as Invalid, NullPointer as Null};
            check(
                fl_control_get(ptr::null_mut(), a, out),
                Null,
                "`ctl` is NULL",
            );
            check(fl_control_get(c, null, out), Null, "`joint` is NULL");
            check(fl_control_get(c, a, ptr::null_mut()), Null, "`out` is NULL");
            check(
                fl_control_get(c, bad, out),
                Invalid,
                "`joint` is not valid UTF-8",
            );
            check(
                fl_control_get(c, long.as_ptr(), out),
                Invalid,
                "longer than 64 bytes",
            );
            check(fl_control_set(c, a, null, kfc, out), Null, "`key` is NULL");
            check(
                fl_control_set(c, a, kfc, bad, out),
                Invalid,
                "`value` is not valid UTF-8",
            );
            let what = "must each fit 64 bytes";
            check(fl_control_set(c, a, kfc, long.as_ptr(), out), Invalid, what);
            // Another thread may neither call nor close the handle.
            let addr = c as usize;
            let (get, close, msg) = std::thread::spawn(move || {
                let c = addr as *mut fl_control;
                let mut s = std::mem::MaybeUninit::<fl_control_state>::zeroed();
                let get = fl_control_get(c, c"a".as_ptr(), s.as_mut_ptr());
                let close = fl_control_close(c);
                (get, close, last())
            })
            .join()
            .unwrap();
            assert_eq!(
                (get, close),
                (fl_status::InvalidArgument, fl_status::InvalidArgument)
            );
            assert!(msg.contains("other than the one that opened it"), "{msg}");
            assert_eq!(fl_control_close(c), fl_status::Ok);
            assert_eq!(fl_control_close(ptr::null_mut()), fl_status::Ok);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
