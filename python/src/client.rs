//! A client of a running `frictiond` over iceoryx2: [`DaemonClient`] publishes `JointStates` and
//! `TorqueRequest` and reads `MotorCurrentCommand` and `DaemonStatus`, through the service
//! functions of `frictionless-shm-types` (so names, payload types and QoS are the daemon's).
//!
//! What it is: a plant / controller / monitor seat in the daemon's services, for tests, notebooks
//! and prototypes. What it is not: a real-time loop (every call goes through Python), a daemon, or a
//! second definition of the payloads — the Python dataclasses mirror the `#[repr(C)]` types field by
//! field and the conversion is here.
//!
//! iceoryx2 ports are not `Send`, so the client is bound to the thread that created it (PyO3
//! `unsendable`). Publishers are opened on first use: a client that only reads takes no publisher
//! slot (frictionless-shm-types allows two per service).

use std::path::PathBuf;
use std::time::Duration;

use frictionless_shm_types::control::{
    CONTROL_KEYS, CONTROL_OK, ControlClient, ControlRequest, ControlResponse, access_refusal,
    ood_mode_name,
};
use frictionless_shm_types::{
    DaemonStatus, Histogram, Inbox, Ipc, IpcConfig, JointStates, MAX_JOINTS, MotorCurrentCommand,
    Outbox, TorqueRequest,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{IpcError, message};

/// CLOCK_MONOTONIC [ns], the clock of every `stamp_ns`.
#[pyfunction]
pub fn monotonic_ns() -> u64 {
    frictionless_shm_types::monotonic_ns()
}

fn ipc_err(e: impl std::error::Error + 'static) -> PyErr {
    IpcError::new_err(message(&e))
}

fn duration(timeout_s: f64) -> PyResult<Duration> {
    Duration::try_from_secs_f64(timeout_s).map_err(|_| {
        PyValueError::new_err(format!(
            "timeout_s = {timeout_s}: expected a finite number ≥ 0"
        ))
    })
}

/// Copies `v` (length `n`) into the first `n` elements of `dst`.
fn fill<T: Copy>(
    what: &str,
    dst: &mut [T; MAX_JOINTS],
    v: Option<Vec<T>>,
    n: usize,
) -> PyResult<()> {
    if let Some(v) = v {
        if v.len() != n {
            return Err(PyValueError::new_err(format!(
                "{what} has {} values, n_joints is {n}",
                v.len()
            )));
        }
        dst[..n].copy_from_slice(&v);
    }
    Ok(())
}

fn check_n(n_joints: usize) -> PyResult<()> {
    if n_joints > MAX_JOINTS {
        return Err(PyValueError::new_err(format!(
            "n_joints = {n_joints}: at most {MAX_JOINTS}"
        )));
    }
    Ok(())
}

fn histogram<'py>(py: Python<'py>, h: &Histogram) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("counts", h.counts.to_vec())?;
    d.set_item("total", h.total)?;
    d.set_item("max_ns", h.max_ns)?;
    d.set_item("mean_ns", h.mean_ns())?;
    d.set_item("p50_upper_ns", h.quantile_upper_ns(0.5))?;
    d.set_item("p99_upper_ns", h.quantile_upper_ns(0.99))?;
    Ok(d)
}

fn command_dict<'py>(py: Python<'py>, c: &MotorCurrentCommand) -> PyResult<Bound<'py, PyDict>> {
    let n = (c.n_joints as usize).min(MAX_JOINTS);
    let d = PyDict::new(py);
    d.set_item("seq", c.seq)?;
    d.set_item("stamp_ns", c.stamp_ns)?;
    d.set_item("state_stamp_ns", c.state_stamp_ns)?;
    d.set_item("state_seq", c.state_seq)?;
    d.set_item("valid_mask", c.valid_mask)?;
    d.set_item("n_joints", c.n_joints)?;
    d.set_item("i_ref_a", c.i_ref_a[..n].to_vec())?;
    d.set_item("flags", c.flags[..n].to_vec())?;
    d.set_item("tau_f_model_nm", c.tau_f_model_nm[..n].to_vec())?;
    Ok(d)
}

fn status_dict<'py>(py: Python<'py>, s: &DaemonStatus) -> PyResult<Bound<'py, PyDict>> {
    let n = (s.n_joints as usize).min(MAX_JOINTS);
    let d = PyDict::new(py);
    d.set_item("seq", s.seq)?;
    d.set_item("stamp_ns", s.stamp_ns)?;
    d.set_item("ticks", s.ticks)?;
    d.set_item("missed_deadlines", s.missed_deadlines)?;
    d.set_item("stale_ticks", s.stale_ticks)?;
    d.set_item("generation", s.generation)?;
    d.set_item("input_age_ns", s.input_age_ns)?;
    d.set_item("period_ns", s.period_ns)?;
    d.set_item("flags", s.flags)?;
    d.set_item("n_joints", s.n_joints)?;
    d.set_item("lateness", histogram(py, &s.lateness)?)?;
    d.set_item("compute", histogram(py, &s.compute)?)?;
    d.set_item("input_age", histogram(py, &s.input_age)?)?;
    d.set_item("tau_f_hat_nm", s.tau_f_hat_nm[..n].to_vec())?;
    d.set_item("i_ref_a", s.i_ref_a[..n].to_vec())?;
    d.set_item("joint_flags", s.joint_flags[..n].to_vec())?;
    let kinds: Vec<u32> = s.model_kind[..n].iter().map(|&k| u32::from(k)).collect();
    d.set_item("model_kind", kinds)?;
    let b = PyDict::new(py);
    let c = &s.bus;
    b.set_item("kind", c.bus_kind().map_or("unknown", |k| k.name()))?;
    b.set_item("links", c.links)?;
    b.set_item("rx_messages", c.rx_messages)?;
    b.set_item("tx_messages", c.tx_messages)?;
    b.set_item("tx_dropped", c.tx_dropped)?;
    b.set_item("error_reports", c.error_reports)?;
    b.set_item("link_down", c.link_down)?;
    b.set_item("io_errors", c.io_errors)?;
    b.set_item("stale_feedback_mask", c.stale_feedback_mask)?;
    let detail = PyDict::new(py);
    for (name, v) in c.named_detail() {
        detail.set_item(name, v)?;
    }
    b.set_item("detail", detail)?;
    d.set_item("bus", b)?;
    Ok(d)
}

/// One iceoryx2 node in a frictiond deployment's services.
#[pyclass(unsendable, module = "frictionless._native")]
pub struct DaemonClient {
    ipc: Ipc,
    states: Option<Outbox<JointStates>>,
    request: Option<Outbox<TorqueRequest>>,
    cmd: Inbox<MotorCurrentCommand>,
    status: Inbox<DaemonStatus>,
    control: Option<ControlClient>,
    states_seq: u64,
    request_seq: u64,
}

/// A [`ControlResponse`] as a dict (`set_since_ns`: per key, `None` = the file's value).
fn control_dict<'py>(
    py: Python<'py>,
    joint: &str,
    r: &ControlResponse,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("joint", joint)?;
    d.set_item("index", r.joint_index)?;
    d.set_item("generation", r.generation)?;
    d.set_item("generation_since_ns", r.generation_since_ns)?;
    d.set_item("kfc", r.kfc)?;
    d.set_item("max_output_friction", r.max_output_friction_nm)?;
    d.set_item("max_curr", r.max_curr_a)?;
    d.set_item("compensation", r.compensation != 0)?;
    d.set_item("ood", ood_mode_name(r.ood_mode))?;
    d.set_item("model", r.model())?;
    d.set_item(
        "model_kind",
        u8::try_from(r.model_kind)
            .ok()
            .and_then(frictionless::model::ModelKind::from_code)
            .map_or("?", |k| k.name()),
    )?;
    d.set_item("model_since_tick", r.model_since_tick)?;
    d.set_item("models", r.models().collect::<Vec<_>>())?;
    let since = PyDict::new(py);
    for (k, t) in CONTROL_KEYS.iter().zip(r.set_since_ns) {
        since.set_item(*k, (t != 0).then_some(t))?;
    }
    d.set_item("set_since_ns", since)?;
    d.set_item("message", r.message())?;
    Ok(d)
}

#[pymethods]
impl DaemonClient {
    /// Opens a node named `node_name` in the deployment `service_prefix` (frictiond's
    /// `[backend] service_prefix`) under the iceoryx2 root `root_path` (`None`: iceoryx2's default).
    #[new]
    #[pyo3(signature = (service_prefix = "frictionless", root_path = None, node_name = "frictionless-py"))]
    fn new(service_prefix: &str, root_path: Option<PathBuf>, node_name: &str) -> PyResult<Self> {
        let cfg = IpcConfig::new(root_path.as_deref(), service_prefix);
        // Another user's deployment: say who may connect instead of iceoryx2's error alone.
        let ipc = Ipc::open(&cfg, node_name).map_err(|e| match access_refusal(&cfg) {
            Some(why) => IpcError::new_err(format!("{why} ({})", message(&e))),
            None => ipc_err(e),
        })?;
        let cmd = ipc
            .motor_current_command()
            .and_then(|c| c.inbox())
            .map_err(ipc_err)?;
        let status = ipc
            .daemon_status()
            .and_then(|c| c.inbox())
            .map_err(ipc_err)?;
        Ok(Self {
            ipc,
            states: None,
            request: None,
            cmd,
            status,
            control: None,
            states_seq: 0,
            request_seq: 0,
        })
    }

    /// The service prefix.
    #[getter]
    fn service_prefix(&self) -> String {
        self.ipc.config().service_prefix.clone()
    }

    /// Whether frictiond's status publisher is up (it is the last port the daemon opens).
    fn daemon_up(&self) -> PyResult<bool> {
        let ch = self.ipc.daemon_status().map_err(ipc_err)?;
        Ok(ch.publisher_count() > 0)
    }

    /// Publishes one `JointStates` (arrays of length `n_joints`; missing ones keep the zeroed
    /// payload's values: 0, τ_meas and temperature NaN). `seq` / `stamp_ns` default to this client's
    /// next sequence number and now. Returns `(seq, stamp_ns)`.
    #[pyo3(signature = (
        n_joints, s_rad = None, sdot_rad_s = None, theta_motor_rad = None, omega_motor_rad_s = None,
        current_a = None, tau_meas_nm = None, temperature_c = None, fault_flags = None,
        seq = None, stamp_ns = None
    ))]
    #[allow(clippy::too_many_arguments)]
    fn publish_states(
        &mut self,
        n_joints: usize,
        s_rad: Option<Vec<f64>>,
        sdot_rad_s: Option<Vec<f64>>,
        theta_motor_rad: Option<Vec<f64>>,
        omega_motor_rad_s: Option<Vec<f64>>,
        current_a: Option<Vec<f64>>,
        tau_meas_nm: Option<Vec<f64>>,
        temperature_c: Option<Vec<f64>>,
        fault_flags: Option<Vec<u32>>,
        seq: Option<u64>,
        stamp_ns: Option<u64>,
    ) -> PyResult<(u64, u64)> {
        check_n(n_joints)?;
        let mut js = JointStates::zeroed();
        js.n_joints = n_joints as u32;
        fill("s_rad", &mut js.s_rad, s_rad, n_joints)?;
        fill("sdot_rad_s", &mut js.sdot_rad_s, sdot_rad_s, n_joints)?;
        fill(
            "theta_motor_rad",
            &mut js.theta_motor_rad,
            theta_motor_rad,
            n_joints,
        )?;
        fill(
            "omega_motor_rad_s",
            &mut js.omega_motor_rad_s,
            omega_motor_rad_s,
            n_joints,
        )?;
        fill("current_a", &mut js.current_a, current_a, n_joints)?;
        fill("tau_meas_nm", &mut js.tau_meas_nm, tau_meas_nm, n_joints)?;
        fill(
            "temperature_c",
            &mut js.temperature_c,
            temperature_c,
            n_joints,
        )?;
        fill("fault_flags", &mut js.fault_flags, fault_flags, n_joints)?;
        js.seq = seq.unwrap_or(self.states_seq + 1);
        js.stamp_ns = stamp_ns.unwrap_or_else(frictionless_shm_types::monotonic_ns);
        if self.states.is_none() {
            let out = self
                .ipc
                .joint_states()
                .and_then(|c| c.outbox())
                .map_err(ipc_err)?;
            self.states = Some(out);
        }
        if let Some(out) = &self.states {
            out.publish(&js)
                .map_err(|e| IpcError::new_err(format!("{}: {e}", out.name())))?;
        }
        self.states_seq = js.seq;
        Ok((js.seq, js.stamp_ns))
    }

    /// Publishes one `TorqueRequest`: desired joint torques τ_des [Nm] (length = n_joints), the
    /// enable bit set, and the `seq` of the state it answers (`state_seq`, 0 = none; a lockstep
    /// daemon waits for it). `seq` / `stamp_ns` default as in `publish_states`. Returns `(seq,
    /// stamp_ns)`.
    #[pyo3(signature = (tau_des_nm, enable_mask, state_seq = 0, seq = None, stamp_ns = None))]
    fn publish_request(
        &mut self,
        tau_des_nm: Vec<f64>,
        enable_mask: u64,
        state_seq: u64,
        seq: Option<u64>,
        stamp_ns: Option<u64>,
    ) -> PyResult<(u64, u64)> {
        let n = tau_des_nm.len();
        check_n(n)?;
        let mut rq = TorqueRequest::zeroed();
        rq.n_joints = n as u32;
        rq.enable_mask = enable_mask;
        rq.state_seq = state_seq;
        rq.tau_des_nm[..n].copy_from_slice(&tau_des_nm);
        rq.seq = seq.unwrap_or(self.request_seq + 1);
        rq.stamp_ns = stamp_ns.unwrap_or_else(frictionless_shm_types::monotonic_ns);
        if self.request.is_none() {
            let out = self
                .ipc
                .torque_request()
                .and_then(|c| c.outbox())
                .map_err(ipc_err)?;
            self.request = Some(out);
        }
        if let Some(out) = &self.request {
            out.publish(&rq)
                .map_err(|e| IpcError::new_err(format!("{}: {e}", out.name())))?;
        }
        self.request_seq = rq.seq;
        Ok((rq.seq, rq.stamp_ns))
    }

    /// The newest `MotorCurrentCommand` as a dict, waiting up to `timeout_s` for one to arrive
    /// (0: only what is already there); `None` if none arrived.
    #[pyo3(signature = (timeout_s = 0.0))]
    fn command<'py>(
        &self,
        py: Python<'py>,
        timeout_s: f64,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let c = self
            .cmd
            .wait_latest(duration(timeout_s)?)
            .map_err(|e| IpcError::new_err(format!("{}: {e}", self.cmd.name())))?;
        c.map(|c| command_dict(py, &c)).transpose()
    }

    /// The newest `DaemonStatus` as a dict, waiting up to `timeout_s`; `None` if none arrived.
    #[pyo3(signature = (timeout_s = 0.0))]
    fn status<'py>(&self, py: Python<'py>, timeout_s: f64) -> PyResult<Option<Bound<'py, PyDict>>> {
        let s = self
            .status
            .wait_latest(duration(timeout_s)?)
            .map_err(|e| IpcError::new_err(format!("{}: {e}", self.status.name())))?;
        s.map(|s| status_dict(py, &s)).transpose()
    }

    /// A joint's values in the running daemon (`<prefix>/control` get), waiting up to `timeout_s`
    /// for the answer. Raises `ValueError` when the daemon refuses (unknown joint).
    #[pyo3(signature = (joint, timeout_s = 2.0))]
    fn control_get<'py>(
        &mut self,
        py: Python<'py>,
        joint: &str,
        timeout_s: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let req = ControlRequest::get(joint)
            .ok_or_else(|| PyValueError::new_err("joint name longer than 64 bytes"))?;
        let r = self.control_call(&req, timeout_s)?;
        control_dict(py, joint, &r)
    }

    /// Sets `key` (`kfc`, `max_output_friction`, `max_curr`, `compensation` = `on`/`off`, `ood`,
    /// `model` = a name of the joint's `models`) of `joint` to `value` (written as in the config) in the running daemon; applied from its
    /// next tick until a reload. Returns the joint's values; raises `ValueError` with the daemon's
    /// message (which names the rule) when refused.
    #[pyo3(signature = (joint, key, value, timeout_s = 2.0))]
    fn control_set<'py>(
        &mut self,
        py: Python<'py>,
        joint: &str,
        key: &str,
        value: &str,
        timeout_s: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let req = ControlRequest::set(joint, key, value)
            .ok_or_else(|| PyValueError::new_err("joint, key and value must each fit 64 bytes"))?;
        let r = self.control_call(&req, timeout_s)?;
        control_dict(py, joint, &r)
    }
}

impl DaemonClient {
    fn control_call(&mut self, req: &ControlRequest, timeout_s: f64) -> PyResult<ControlResponse> {
        if self.control.is_none() {
            self.control = Some(self.ipc.control_client().map_err(ipc_err)?);
        }
        let c = self.control.as_ref().expect("just opened");
        let r = c.call(req, duration(timeout_s)?).map_err(ipc_err)?;
        if r.status != CONTROL_OK {
            return Err(PyValueError::new_err(r.message().to_owned()));
        }
        Ok(r)
    }
}
