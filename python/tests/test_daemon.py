"""The frictiond client against a REAL `frictiond` process over iceoryx2.

The test is the plant and the controller: it publishes `JointStates` and `TorqueRequest` in
lockstep (the daemon processes exactly the states sent), reads `MotorCurrentCommand` and
`DaemonStatus`, and checks each current against the control law computed here — τ̂_F of the PINN
joint from `frictionless.Estimator` fed the same samples, of the CV joint from the formula — as in
the daemon's own end-to-end test (`daemon/tests/daemon_pinn.rs`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import numpy as np
import pytest

import frictionless as fl
from conftest import random_layers

R0, KT0, KFC0, MAX_I0 = -100.0, 0.157, 0.8, 50.0
R1, KT1, KFC1, MAX_I1 = 160.0, 0.0665, 0.85, 3.0
CV = dict(kc=8.1, ka=50.84, kv=5.55)
H = 10


def config(prefix, root, model):
    return f"""
[backend]
kind = "shm"
service_prefix = "{prefix}"
root_path = "{root}"

[loop]
period_us = 1000
status_every_ticks = 5
ready_after_ticks = 5
trigger = "lockstep"
lockstep_wait_request = true
lockstep_timeout_ms = 10000

[safety]
stale_after_ticks = 20
on_stale = "zero"

[[joint]]
name = "knee"
index = 0
gear_ratio = {R0!r}
kt = {KT0!r}
max_curr = {MAX_I0!r}
kfc = {KFC0!r}
friction_model = "pinn"
model = "{model}"
warmup = "hold_zero"

[[joint]]
name = "ankle"
index = 1
gear_ratio = {R1!r}
kt = {KT1!r}
max_curr = {MAX_I1!r}
kfc = {KFC1!r}
friction_model = "cv"
kc = {CV["kc"]!r}
ka = {CV["ka"]!r}
kv = {CV["kv"]!r}

[[joint.alternate]]
name = "scv_b"
friction_model = "scv"
kc = 1.0
ka = 40.0
kv = 3.0
ks = 2.0
vs = 0.1
alpha = 0.8
"""


def current_ref(tau, f, kfc, kt, r, max_i):
    """The law without clip gate, filter or feedback: i = (τ_des + kfc·f)/(kt·r), clamped."""
    return float(np.clip((tau + kfc * f) / (kt * r), -max_i, max_i))


def sample(k):
    t = k * 1e-3
    s = 0.3 * np.sin(3 * t)
    sdot = 0.9 * np.cos(3 * t)
    return s, sdot, R0 * s + 0.02 * np.sin(7 * t) + 1.5, R0 * sdot + 0.14 * np.cos(7 * t)


@pytest.fixture
def daemon(frictiond, tmp_path):
    model_path = tmp_path / "knee.fwt"
    model = fl.write_fwt(model_path, random_layers([2 * H, 16, 12, 1], seed=1, amp=0.6),
                         joint="knee", gear_ratio=R0, kt=KT0)
    (tmp_path / "iox").mkdir()
    prefix = f"flpy_{os.getpid()}_{time.monotonic_ns() % 1_000_000_000}"
    cfg = tmp_path / "frictiond.toml"
    cfg.write_text(config(prefix, tmp_path / "iox", model_path.name))
    log = open(tmp_path / "frictiond.log", "w+")
    proc = subprocess.Popen([str(frictiond), "--config", str(cfg)], stdout=subprocess.DEVNULL,
                            stderr=log, env={**os.environ, "RUST_LOG": "info"})
    try:
        yield proc, prefix, tmp_path / "iox", model, log
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        log.close()


def test_commands_follow_the_law_and_status_reports(daemon):
    proc, prefix, root, model, log = daemon
    client = fl.DaemonClient(prefix, root, node_name="pytest-plant")
    assert client.wait_for_daemon(20.0), "frictiond did not open its ports"
    est = fl.Estimator(model)
    seen = {0: set(), 1: set()}
    warming = 0
    beyond_ff = 0
    last_seq = None
    for k in range(150):
        s, sdot, theta, omega = sample(k)
        tau = [1.5 * np.sin(0.01 * k), 0.8 * np.cos(0.02 * k)]
        sdot1 = 0.5 * np.sin(0.05 * k)
        js = fl.JointStates(
            n_joints=2,
            s_rad=np.array([s, 0.0]),
            sdot_rad_s=np.array([sdot, sdot1]),
            theta_motor_rad=np.array([theta, 0.0]),
            omega_motor_rad_s=np.array([omega, R1 * sdot1]),
        )
        seq = client.publish_states(js)
        client.publish_request(fl.TorqueRequest(np.array(tau), enable_mask=0b11, state_seq=seq, seq=seq))
        c = client.command_for(seq, timeout_s=20.0)
        assert c is not None, f"no command for state {seq}: {proc.poll()}"
        assert c.state_seq == seq and c.n_joints == 2 and c.is_valid(0) and c.is_valid(1)
        if last_seq is not None:
            assert c.seq == last_seq + 1, "one command per state"
        last_seq = c.seq

        f0 = est.push(s, sdot, theta, omega)
        want0 = current_ref(tau[0], f0, KFC0, KT0, R0, MAX_I0)
        f1 = CV["kc"] * np.tanh(CV["ka"] * sdot1) + CV["kv"] * sdot1
        want1 = current_ref(tau[1], f1, KFC1, KT1, R1, MAX_I1)
        assert abs(c.i_ref_a[0] - want0) <= 1e-9, (k, c.i_ref_a[0], want0)
        assert abs(c.i_ref_a[1] - want1) <= 1e-9, (k, c.i_ref_a[1], want1)
        assert bool(c.flags[0] & fl.FLAG_WARMING_UP) == (not est.warm), k
        assert not c.flags[1] & fl.FLAG_WARMING_UP
        assert not (c.flags[0] | c.flags[1]) & fl.FLAG_STALE
        warming += int(not est.warm)
        beyond_ff += int(abs(c.i_ref_a[0] - tau[0] / (KT0 * R0)) > 1e-3)
        seen[0].add(float(c.i_ref_a[0]))
        seen[1].add(float(c.i_ref_a[1]))
    assert warming == H - 1
    assert beyond_ff > 100, "the network's estimate is in the command"

    st = client.status(timeout_s=5.0)
    assert st is not None
    assert st.n_joints == 2 and st.ticks >= 100 and st.generation == 0
    assert list(st.model_kind) == [fl.MODEL_KIND_PINN, fl.MODEL_KIND_CV]
    # The status is a snapshot of one of the ticks above.
    assert float(st.i_ref_a[0]) in seen[0] and float(st.i_ref_a[1]) in seen[1]
    assert st.period_ns == 1_000_000
    # The shared-memory backend's link counters: the states and requests it took, what it sent.
    assert st.bus["kind"] == "shm" and st.bus["links"] == 1, st.bus
    assert st.bus["rx_messages"] >= 100 and st.bus["tx_messages"] >= 100, st.bus
    assert st.bus["detail"] == {} and st.bus["io_errors"] == 0, st.bus

    proc.send_signal(signal.SIGTERM)
    code = proc.wait(timeout=20)
    log.seek(0)
    assert code == 0, log.read()


def control_client(prefix, root):
    """A client once the daemon answers control gets (its server opens after the RT thread)."""
    client = fl.DaemonClient(prefix, root, node_name="pytest-ctl")
    assert client.wait_for_daemon(20.0), "frictiond did not open its ports"
    deadline = time.monotonic() + 20.0
    while True:
        try:
            return client, client.control_get("ankle")
        except fl.IpcError:
            assert time.monotonic() < deadline, "no control answer"


def test_control_set_changes_the_next_tick_and_refusals_name_the_rule(daemon):
    proc, prefix, root, model, log = daemon
    client, got = control_client(prefix, root)
    assert got["kfc"] == KFC1 and got["compensation"] and got["set_since_ns"]["kfc"] is None
    set_ = client.control_set("ankle", "kfc", 0.4)
    assert set_["kfc"] == 0.4 and set_["set_since_ns"]["kfc"] > 0
    client.control_set("ankle", "compensation", False)
    assert not client.control_get("ankle")["compensation"]
    with pytest.raises(ValueError, match=r"must be in \[0, 2\]"):
        client.control_set("ankle", "kfc", 3)
    with pytest.raises(ValueError, match="no such joint"):
        client.control_get("hip")
    # The next tick: compensation off, so i = τ_des/(kt·r) on the ankle.
    for k in range(3):
        js = fl.JointStates(n_joints=2, sdot_rad_s=np.array([0.0, 0.3]))
        seq = client.publish_states(js)
        client.publish_request(fl.TorqueRequest(np.array([0.0, 0.5]), enable_mask=0b10,
                                                state_seq=seq, seq=seq))
        c = client.command_for(seq, timeout_s=20.0)
        assert c is not None
        assert abs(c.i_ref_a[1] - current_ref(0.5, 0.0, 0.4, KT1, R1, MAX_I1)) <= 1e-12, k
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=20) == 0


def test_control_reports_the_models_and_switches_them_by_name(daemon):
    proc, prefix, root, model, log = daemon
    client, got = control_client(prefix, root)
    # The ankle's own CV, its one alternate and `none`; the knee's PINN and `none`.
    assert (got["model"], got["model_kind"]) == ("default", "cv")
    assert got["models"] == ["default", "scv_b", "none"]
    assert got["model_since_tick"] == 0 and got["set_since_ns"]["model"] is None
    knee = client.control_get("knee")
    assert (knee["model"], knee["model_kind"], knee["models"]) == ("default", "pinn", ["default", "none"])

    for name, kind in [("scv_b", "scv"), ("none", "none"), ("default", "cv"), ("scv_b", "scv")]:
        set_ = client.control_set("ankle", "model", name)
        assert (set_["model"], set_["model_kind"]) == (name, kind)
        assert set_["set_since_ns"]["model"] > 0 and set_["models"] == ["default", "scv_b", "none"]
        got = client.control_get("ankle")
        assert (got["model"], got["model_kind"]) == (name, kind)
    with pytest.raises(ValueError, match=r"no such model of this joint \(available: default, scv_b, none\)"):
        client.control_set("ankle", "model", "lugre_x")
    with pytest.raises(ValueError, match=r"no such model of this joint \(available: default, none\)"):
        client.control_set("knee", "model", "scv_b")  # another joint's alternate
    # Refused names changed nothing.
    assert client.control_get("ankle")["model"] == "scv_b"
    assert client.control_get("knee")["model"] == "default"
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=20) == 0


def test_client_errors(tmp_path):
    with pytest.raises(ValueError, match="n_joints"):
        c = fl.DaemonClient(f"flpy_err_{os.getpid()}", tmp_path)
        c.publish_states(fl.JointStates(n_joints=fl.MAX_JOINTS + 1))
    c = fl.DaemonClient(f"flpy_err2_{os.getpid()}", tmp_path)
    with pytest.raises(ValueError, match="has 1 values, n_joints is 2"):
        c._c.publish_states(2, s_rad=[0.0])
    assert c.command() is None and c.status() is None
    assert not c.wait_for_daemon(0.05)
    with pytest.raises(fl.IpcError, match="service name"):
        fl.DaemonClient("x" * 300, tmp_path)  # longer than iceoryx2's service names allow
