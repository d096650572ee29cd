"""The Ray driver on a real local Ray cluster: a 2-joint x 4-trial search of the tiny robot
(`robot_tiny.toml`) equals the single-machine `frictl robot run` trial by trial, a worker killed
mid-task has its trial retried, a search begun on this machine is finished by a cluster started with
`ray start --head`, and the frictiond config passes `frictiond --check`.

Needs FRICTL and FRICTIOND (the binaries; `tests/ray/run.sh` builds them and sets both).
"""

import hashlib
import json
import os
import secrets
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
DRIVER = HERE.parent / "frictl_ray.py"
ROBOT = HERE / "robot_tiny.toml"
JOINTS = ["l_knee", "l_ankle_roll"]


def binary(name):
    path = os.environ.get(name.upper())
    if not path or not Path(path).is_file():
        pytest.fail(f"${name.upper()} must name the {name} binary (tests/ray/run.sh sets it)")
    return path


FRICTL = binary("frictl")
FRICTIOND = binary("frictiond")


def frictl(*args, cwd):
    proc = subprocess.run([FRICTL, *map(str, args)], cwd=cwd, capture_output=True, text=True)
    assert proc.returncode == 0, f"frictl {args} failed:\n{proc.stderr}"
    return proc


def driver(*args, cwd, env=None):
    proc = subprocess.run(
        [sys.executable, str(DRIVER), "--frictl", FRICTL, *map(str, args)],
        cwd=cwd, capture_output=True, text=True, env={**os.environ, **(env or {})},
    )
    assert proc.returncode == 0, f"driver {args} failed:\n{proc.stdout}\n{proc.stderr}"
    return proc


def lines(path):
    return [json.loads(l) for l in Path(path).read_text().splitlines() if l.strip()]


def ranked(out, joint):
    return json.loads((out / "joints" / joint / "search" / "results.json").read_text())


def check_config(out):
    proc = subprocess.run([FRICTIOND, "--config", str(out / "frictiond.toml"), "--check"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for joint in JOINTS:
        assert joint in proc.stdout and "pinn" in proc.stdout


def close(a, b, where):
    """Equal JSON, floats within 1e-9 relative (parallel reductions may differ in the last bit)."""
    if isinstance(a, float) or isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-9, abs=0), where
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            close(x, y, f"{where}[{i}]")
    else:
        assert a == b, where


def same_trials(a, b):
    """Trial by trial: identical hyper-parameters and seeds; validation RMSE equal to float
    reproducibility (each trial trains with 1 thread; see docs/cluster.md)."""
    assert len(a) == len(b) == 4
    for x, y in zip(sorted(a, key=lambda r: r["params"]["trial"]),
                    sorted(b, key=lambda r: r["params"]["trial"])):
        assert x["params"] == y["params"]
        assert x["status"] == y["status"] == "ok"
        assert x["val_rmse_nm"] == pytest.approx(y["val_rmse_nm"], rel=1e-9, abs=0)
        assert x["epochs_run"] == y["epochs_run"]


@pytest.fixture(scope="module")
def single_machine(tmp_path_factory):
    """The reference: `frictl robot run` on this machine, no Ray."""
    out = tmp_path_factory.mktemp("single") / "out"
    frictl("robot", "run", ROBOT, "--out", out, cwd=out.parent)
    return out


def test_ray_run_equals_single_machine_and_a_killed_worker_is_retried(single_machine, tmp_path):
    out = tmp_path / "out"
    markers = tmp_path / "markers"
    markers.mkdir()
    proc = driver("--address", "local", "--num-cpus", "2", "--max-retries", "2", ROBOT,
                  "--out", out, cwd=tmp_path,
                  env={"FRICTL_RAY_TEST_KILL_ONCE": f"{markers}:l_knee:1"})
    # The first attempt of the knee's trial 1 killed its worker (SIGKILL) after training...
    marker = markers / "l_knee_1"
    assert marker.is_file(), "the kill hook ran"
    # ... and Ray ran it again: every trial recorded once, none failed.
    assert "0 failed" in proc.stderr
    assert "done /" in proc.stderr and "running /" in proc.stderr
    for joint in JOINTS:
        recs = lines(out / "joints" / joint / "search" / "results.jsonl")
        assert sorted(r["params"]["trial"] for r in recs) == [0, 1, 2, 3], joint
        # the same data (content-addressed stages ran on workers)
        for f in ["train_ds.csv", "test_ds.csv"]:
            assert (out / "joints" / joint / f).read_bytes() == \
                (single_machine / "joints" / joint / f).read_bytes(), f"{joint} {f}"
        for f in ["cv.json", "scv.json"]:
            close(json.loads((out / "joints" / joint / f).read_text()),
                  json.loads((single_machine / "joints" / joint / f).read_text()), f"{joint} {f}")
        same_trials(ranked(out, joint), ranked(single_machine, joint))
        assert ranked(out, joint)[0]["params"] == ranked(single_machine, joint)[0]["params"]
    check_config(out)
    report = json.loads((out / "report.json").read_text())
    assert set(report["joints"]) == set(JOINTS)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_search_begun_locally_is_finished_by_a_ray_start_cluster(single_machine, tmp_path):
    """Also: files move through `[robot] shared_dir` (content-addressed) instead of the object store."""
    out = tmp_path / "out"
    shared = tmp_path / "shared"
    text = ROBOT.read_text()
    assert "\nseed = 3\n" in text
    robot = tmp_path / "robot.toml"
    robot.write_text(text.replace("\nseed = 3\n", f'\nseed = 3\nshared_dir = "{shared}"\n'))
    # On this machine: the data and fits of both joints, then trials 0 and 2 of the knee.
    frictl("robot", "run", robot, "--out", out, "--until", "fit", cwd=tmp_path)
    plan = json.loads(frictl("robot", "plan", robot, "--out", out, cwd=tmp_path).stdout)
    knee = plan["joints"][0]
    assert knee["name"] == "l_knee"
    frictl(*knee["search_args"], "--out", knee["search_dir"], "--only-trials", "0,2",
           "--threads", "1", cwd=out)
    local = {r["params"]["trial"]: r for r in
             lines(out / knee["search_dir"] / "results.jsonl")}
    assert sorted(local) == [0, 2]
    # A cluster started as on a real head node; the driver connects to its address.
    # Token authentication as on a real cluster: every node and the driver share the token.
    port = free_port()
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    ray_bin = Path(sys.executable).with_name("ray")
    head = subprocess.Popen(
        [str(ray_bin), "start", "--head", "--block", "--port", str(port), "--num-cpus", "2",
         "--include-dashboard=false", "--disable-usage-stats"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
    )
    try:
        deadline = time.monotonic() + 60
        proc = None
        while time.monotonic() < deadline:
            proc = subprocess.run(
                [sys.executable, str(DRIVER), "--frictl", FRICTL, "--address",
                 f"127.0.0.1:{port}", str(robot), "--out", str(out)],
                cwd=tmp_path, capture_output=True, text=True, env=env)
            if proc.returncode == 0 or "ConnectionError" not in proc.stderr:
                break
            time.sleep(2)  # the head is still starting
        assert proc is not None and proc.returncode == 0, proc.stdout + proc.stderr
    finally:
        head.terminate()
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()
    recs = lines(out / knee["search_dir"] / "results.jsonl")
    assert sorted(r["params"]["trial"] for r in recs) == [0, 1, 2, 3]
    # The trials' inputs went through the shared directory, each file under its SHA-256.
    stored = sorted(p.name for p in (shared / "sha256").iterdir())
    assert len(stored) >= 6, stored  # 2 joints x (dataset, sidecar, SCV fit)
    for p in (shared / "sha256").iterdir():
        assert hashlib.sha256(p.read_bytes()).hexdigest() == p.name
    for r in recs:
        if r["params"]["trial"] in local:
            assert r == local[r["params"]["trial"]], "trials run locally were kept, not re-run"
    for joint in JOINTS:
        same_trials(ranked(out, joint), ranked(single_machine, joint))
    check_config(out)
