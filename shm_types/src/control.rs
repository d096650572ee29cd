//! Runtime control of a running frictiond over iceoryx2 request–response (`<prefix>/control`):
//! the request and response payloads and the two ports ([`ControlServer`] in the daemon,
//! [`ControlClient`] in `frictl ctl`, tests and bindings).
//!
//! One request names one joint and, for a set, one `KEY=VALUE` (keys as in the config: `kfc`,
//! `max_output_friction`, `max_curr`, `compensation`, `ood`, and `model`: the name of one of the
//! joint's preloaded models); the response carries the status, a message naming the rule a refused
//! value breaks, and the joint's values in use.

use std::fmt::Debug;
use std::time::{Duration, Instant};

use iceoryx2::port::client::Client;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;

use crate::{Ipc, IpcConfig, MAX_NODES, ShmError, ipc_err};

/// Bytes of each text field of a [`ControlRequest`] (UTF-8, NUL-padded).
pub const CONTROL_TEXT_BYTES: usize = 64;
/// Bytes of [`ControlResponse::message`] (UTF-8, NUL-padded, cut at a character boundary).
pub const CONTROL_MESSAGE_BYTES: usize = 256;

/// [`ControlRequest::op`]: read the joint's values.
pub const CONTROL_OP_GET: u32 = 1;
/// [`ControlRequest::op`]: set one key of the joint.
pub const CONTROL_OP_SET: u32 = 2;

/// [`ControlResponse::status`]: done (a set is applied from the RT thread's next tick on).
pub const CONTROL_OK: u32 = 0;
/// [`ControlResponse::status`]: the value breaks a rule (the message names it).
pub const CONTROL_REFUSED: u32 = 1;
/// [`ControlResponse::status`]: runtime writes are disabled by the config (`[control] writes`).
pub const CONTROL_WRITES_DISABLED: u32 = 2;
/// [`ControlResponse::status`]: the queue to the RT thread is full; try again.
pub const CONTROL_BUSY: u32 = 3;
/// [`ControlResponse::status`]: the request itself is malformed (op, text).
pub const CONTROL_BAD_REQUEST: u32 = 4;

/// The keys, in the order of [`ControlResponse::set_since_ns`].
pub const CONTROL_KEYS: [&str; 6] = [
    "kfc",
    "max_output_friction",
    "max_curr",
    "compensation",
    "ood",
    "model",
];

/// A request to the daemon (client → daemon).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::ControlRequest_v1")]
pub struct ControlRequest {
    /// [`CONTROL_OP_GET`] or [`CONTROL_OP_SET`].
    pub op: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Joint name (`[[joint]] name`).
    pub joint: [u8; CONTROL_TEXT_BYTES],
    /// Key (set only).
    pub key: [u8; CONTROL_TEXT_BYTES],
    /// Value as written in the config (set only).
    pub value: [u8; CONTROL_TEXT_BYTES],
}

/// The daemon's answer (daemon → client).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::ControlResponse_v2")]
pub struct ControlResponse {
    /// `CONTROL_OK`, `CONTROL_REFUSED`, …
    pub status: u32,
    /// The joint's payload index (`u32::MAX` when the joint is unknown).
    pub joint_index: u32,
    /// Parameter generation the values belong to (+1 per reload; a reload drops runtime values).
    pub generation: u64,
    /// CLOCK_MONOTONIC time [ns] at which this generation's file was loaded.
    pub generation_since_ns: u64,
    /// kfc in use.
    pub kfc: f64,
    /// max_output_friction [Nm] in use.
    pub max_output_friction_nm: f64,
    /// max_curr [A] in use.
    pub max_curr_a: f64,
    /// Compensation switch: 1 on, 0 off.
    pub compensation: u32,
    /// OOD mode: 0 off, 1 flag, 2 static.
    pub ood_mode: u32,
    /// Active model kind (`frictionless::model::ModelKind::code`).
    pub model_kind: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Per key of [`CONTROL_KEYS`]: CLOCK_MONOTONIC time [ns] of the runtime set in use, 0 = the
    /// file's value.
    pub set_since_ns: [u64; CONTROL_KEYS.len()],
    /// Name of the active model (`default`: the joint's own `friction_model`, an alternate's
    /// `name`, or `none`; UTF-8, NUL-padded).
    pub model: [u8; CONTROL_TEXT_BYTES],
    /// The active model runs from the tick after this many ticks completed (`DaemonStatus::ticks`
    /// counts the same ticks): the ticks completed when its set was queued, 0 = since the load.
    pub model_since_tick: u64,
    /// The joint's model names (`default`, its alternates in file order, `none`), comma-separated
    /// (UTF-8, NUL-padded; cut at a name boundary, ending in `…` when they do not fit).
    pub models: [u8; CONTROL_MESSAGE_BYTES],
    /// Human-readable result (a refusal names the joint, key, value and rule).
    pub message: [u8; CONTROL_MESSAGE_BYTES],
}

/// Writes `s` NUL-padded into `dst`; `false` if it does not fit (or holds a NUL).
pub fn put_text(dst: &mut [u8], s: &str) -> bool {
    if s.len() > dst.len() || s.contains('\0') {
        return false;
    }
    dst.fill(0);
    dst[..s.len()].copy_from_slice(s.as_bytes());
    true
}

/// The text of a NUL-padded field (`None` if not UTF-8).
pub fn text(src: &[u8]) -> Option<&str> {
    let end = src.iter().position(|&b| b == 0).unwrap_or(src.len());
    std::str::from_utf8(&src[..end]).ok()
}

impl ControlRequest {
    /// A get of `joint`'s values; `None` if the name does not fit.
    pub fn get(joint: &str) -> Option<Self> {
        let mut r = Self::zeroed();
        r.op = CONTROL_OP_GET;
        put_text(&mut r.joint, joint).then_some(r)
    }

    /// A set of `key = value` on `joint`; `None` if a text does not fit.
    pub fn set(joint: &str, key: &str, value: &str) -> Option<Self> {
        let mut r = Self::zeroed();
        r.op = CONTROL_OP_SET;
        (put_text(&mut r.joint, joint)
            && put_text(&mut r.key, key)
            && put_text(&mut r.value, value))
        .then_some(r)
    }

    /// All zeros.
    pub fn zeroed() -> Self {
        Self {
            op: 0,
            reserved: 0,
            joint: [0; CONTROL_TEXT_BYTES],
            key: [0; CONTROL_TEXT_BYTES],
            value: [0; CONTROL_TEXT_BYTES],
        }
    }
}

impl ControlResponse {
    /// All zeros with `status` and `message` (cut at a character boundary to fit).
    pub fn with(status: u32, message: &str) -> Self {
        let mut r = Self {
            status,
            joint_index: u32::MAX,
            generation: 0,
            generation_since_ns: 0,
            kfc: 0.0,
            max_output_friction_nm: 0.0,
            max_curr_a: 0.0,
            compensation: 0,
            ood_mode: 0,
            model_kind: 0,
            reserved: 0,
            set_since_ns: [0; CONTROL_KEYS.len()],
            model: [0; CONTROL_TEXT_BYTES],
            model_since_tick: 0,
            models: [0; CONTROL_MESSAGE_BYTES],
            message: [0; CONTROL_MESSAGE_BYTES],
        };
        let mut end = message.len().min(CONTROL_MESSAGE_BYTES);
        while !message.is_char_boundary(end) {
            end -= 1;
        }
        r.message[..end].copy_from_slice(&message.as_bytes()[..end]);
        r
    }

    /// The message text.
    pub fn message(&self) -> &str {
        text(&self.message).unwrap_or("")
    }

    /// The active model's name.
    pub fn model(&self) -> &str {
        text(&self.model).unwrap_or("")
    }

    /// The joint's model names, as listed in [`ControlResponse::models`].
    pub fn models(&self) -> impl Iterator<Item = &str> {
        text(&self.models)
            .unwrap_or("")
            .split(',')
            .filter(|n| !n.is_empty())
    }

    /// Sets [`ControlResponse::models`] from `names`: as many whole names as fit, then `…`.
    pub fn set_models<'a>(&mut self, names: impl IntoIterator<Item = &'a str>) {
        let mut out = String::new();
        for n in names {
            let sep = usize::from(!out.is_empty());
            if out.len() + sep + n.len() + ",…".len() > CONTROL_MESSAGE_BYTES {
                out.push_str(",…");
                break;
            }
            if sep == 1 {
                out.push(',');
            }
            out.push_str(n);
        }
        put_text(&mut self.models, &out);
    }
}

/// Name of the OOD mode code of [`ControlResponse::ood_mode`].
pub fn ood_mode_name(code: u32) -> &'static str {
    match code {
        0 => "off",
        1 => "flag",
        2 => "static",
        _ => "?",
    }
}

type RrFactory = iceoryx2::service::port_factory::request_response::PortFactory<
    ipc::Service,
    ControlRequest,
    (),
    ControlResponse,
    (),
>;

/// The daemon's end: answers requests without blocking ([`ControlServer::serve`]).
pub struct ControlServer {
    name: String,
    server: Server<ipc::Service, ControlRequest, (), ControlResponse, ()>,
}

/// A client's end: one request, one response ([`ControlClient::call`]).
pub struct ControlClient {
    name: String,
    client: Client<ipc::Service, ControlRequest, (), ControlResponse, ()>,
}

impl Debug for ControlServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlServer")
            .field("name", &self.name)
            .finish()
    }
}

impl Debug for ControlClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlClient")
            .field("name", &self.name)
            .finish()
    }
}

impl Ipc {
    fn control_service(&self) -> Result<(String, RrFactory), ShmError> {
        let name = format!("{}/control", self.config.service_prefix);
        let sn = ServiceName::new(&name).map_err(|e| ShmError::InvalidName {
            what: "service name",
            value: name.clone(),
            reason: format!("{e:?}"),
        })?;
        let f = self
            .node
            .service_builder(&sn)
            .request_response::<ControlRequest, ControlResponse>()
            .max_servers(1)
            .max_clients(MAX_NODES)
            .max_nodes(MAX_NODES)
            .max_active_requests_per_client(1)
            .max_response_buffer_size(1)
            .open_or_create()
            .map_err(|e| ipc_err("open request-response service", &name, e))?;
        Ok((name, f))
    }

    /// `<prefix>/control`, the daemon's end (one server per prefix).
    pub fn control_server(&self) -> Result<ControlServer, ShmError> {
        let (name, f) = self.control_service()?;
        // Never block the daemon's supervisor on a client that does not read its answers.
        let server = f
            .server_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| ipc_err("create server", &name, e))?;
        Ok(ControlServer { name, server })
    }

    /// `<prefix>/control`, a client's end.
    pub fn control_client(&self) -> Result<ControlClient, ShmError> {
        let (name, f) = self.control_service()?;
        let client = f
            .client_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| ipc_err("create client", &name, e))?;
        Ok(ControlClient { name, client })
    }
}

impl ControlServer {
    /// Answers every waiting request with `answer`; returns how many. Never blocks.
    pub fn serve(
        &self,
        mut answer: impl FnMut(&ControlRequest) -> ControlResponse,
    ) -> Result<usize, ShmError> {
        let mut n = 0;
        while let Some(active) = self
            .server
            .receive()
            .map_err(|e| ipc_err("receive request", &self.name, e))?
        {
            let response = answer(&active);
            active
                .send_copy(response)
                .map_err(|e| ipc_err("send response", &self.name, e))?;
            n += 1;
        }
        Ok(n)
    }
}

impl ControlClient {
    /// Sends `request` and waits up to `timeout` for the answer (polling every 1 ms).
    pub fn call(
        &self,
        request: &ControlRequest,
        timeout: Duration,
    ) -> Result<ControlResponse, ShmError> {
        let pending = self
            .client
            .send_copy(*request)
            .map_err(|e| ipc_err("send request", &self.name, e))?;
        if pending.number_of_server_connections() == 0 {
            return Err(ShmError::Ipc {
                op: "send request",
                service: self.name.clone(),
                reason: "no server (is frictiond running with this prefix and root path?)".into(),
            });
        }
        let until = Instant::now() + timeout;
        loop {
            if let Some(r) = pending
                .receive()
                .map_err(|e| ipc_err("receive response", &self.name, e))?
            {
                return Ok(*r);
            }
            if Instant::now() >= until {
                return Err(ShmError::Ipc {
                    op: "wait for response",
                    service: self.name.clone(),
                    reason: format!(
                        "no answer within {} ms (is frictiond running with this prefix and root path?)",
                        timeout.as_millis()
                    ),
                });
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

/// Why this process cannot use `cfg`'s control service when another user owns the iceoryx2 root
/// path: iceoryx2 creates its service files, node entries and shared-memory segments readable and
/// writable by their creator's user only (0600; directories 0750), so only frictiond's own user
/// (or root) can open its services. `None` when this process is root or owns the root path (or it
/// does not exist yet). A client calls it when opening the service failed, to replace iceoryx2's
/// error with one that says who may connect.
pub fn access_refusal(cfg: &IpcConfig) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions and cannot fail.
    let euid = unsafe { libc::geteuid() };
    if euid == 0 {
        return None;
    }
    let root = match &cfg.root_path {
        Some(p) => p.clone(),
        None => {
            let c = iceoryx2::config::Config::default();
            std::path::PathBuf::from(c.global.root_path().to_string())
        }
    };
    let owner = std::fs::metadata(&root).ok()?.uid();
    (owner != euid).then(|| {
        format!(
            "permission denied: the control service `{}/control` under {} belongs to uid {owner} (frictiond's user), this process runs as uid {euid}; only frictiond's user may send control requests (run the client as that user, e.g. `sudo -u` it)",
            cfg.service_prefix,
            root.display()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texts_round_trip_and_refuse_what_does_not_fit() {
        let r = ControlRequest::set("l_knee", "kfc", "0.7").unwrap();
        assert_eq!(r.op, CONTROL_OP_SET);
        assert_eq!(
            (text(&r.joint), text(&r.key), text(&r.value)),
            (Some("l_knee"), Some("kfc"), Some("0.7"))
        );
        assert_eq!(text(&ControlRequest::get("a").unwrap().key), Some(""));
        assert!(ControlRequest::get(&"j".repeat(CONTROL_TEXT_BYTES + 1)).is_none());
        assert!(ControlRequest::set("a", "k\0", "1").is_none());
        assert!(ControlRequest::get(&"j".repeat(CONTROL_TEXT_BYTES)).is_some());
        // A long message is cut at a character boundary, never mid-character.
        let long = "é".repeat(CONTROL_MESSAGE_BYTES);
        let m = ControlResponse::with(CONTROL_REFUSED, &long);
        assert_eq!(m.message().len(), CONTROL_MESSAGE_BYTES);
        assert!(m.message().chars().all(|c| c == 'é'));
        assert_eq!(ood_mode_name(2), "static");
        // Model names: whole names only, `…` when the list does not fit.
        let mut m = ControlResponse::with(CONTROL_OK, "ok");
        m.set_models(["default", "scv_b", "none"]);
        assert_eq!(m.models().collect::<Vec<_>>(), ["default", "scv_b", "none"]);
        let long = "n".repeat(60);
        m.set_models(std::iter::repeat_n(long.as_str(), 10));
        let names: Vec<&str> = m.models().collect();
        assert_eq!(names.last(), Some(&"…"));
        assert!(names[..names.len() - 1].iter().all(|n| *n == long));
    }
}
