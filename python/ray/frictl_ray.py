#!/usr/bin/env python3
"""Run `frictl robot run ROBOT.toml` on a Ray cluster: one Ray task per joint's data + fit stages and
one per search trial, each running the `frictl` binary on a worker.

    python frictl_ray.py --address auto ROBOT.toml --out DIR          # an existing cluster
    python frictl_ray.py --address local --num-cpus 2 ROBOT.toml      # a cluster of this machine

What it is: a thin driver around three `frictl` entry points --
`frictl robot plan` (what to run), `frictl robot run --joint J --until fit` (a joint's data and fits)
and `frictl search --only-trials K` (one trial). Every file a task reads travels by its SHA-256:
through Ray's object store (`ray.put` of the bytes, once per content) or, when the robot file names
`[robot] shared_dir`, through `shared_dir/sha256/<hex>` on storage every node mounts. Workers write into
a private scratch directory and return their outputs as bytes; only this driver writes `DIR`, in the
layout `frictl robot run` and `frictl search` write themselves (results appended to
`DIR/joints/J/search/results.jsonl`), so a search begun on one machine continues on the cluster and
the other way round. Failed tasks (a dead worker, a failing `frictl`) are retried `--max-retries`
times. At the end, `frictl robot run` on this machine publishes each search (`results.json/csv`,
`best.fwt`), evaluates, exports and writes `DIR/frictiond.toml` and the report; the stages Ray ran
are recognised by their stamps and skipped.

What it is not: a scheduler (Ray is), a package, or a second implementation of any stage.

Testing hook: `FRICTL_RAY_TEST_KILL_ONCE=MARKER_DIR:JOINT:TRIAL` makes the first attempt of that trial's
task kill its own worker process (SIGKILL) after the trial ran (retry must re-run it).
"""

import argparse
import hashlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import ray


def sha256_file(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class Store:
    """Moves file contents by SHA-256: the object store, or a shared directory."""

    def __init__(self, shared_dir):
        self.shared_dir = Path(shared_dir) if shared_dir else None
        self.refs = {}

    def put(self, path):
        """(sha, handle) of a file's content; each content is uploaded once."""
        sha = sha256_file(path)
        if sha not in self.refs:
            if self.shared_dir is not None:
                dst = self.shared_dir / "sha256" / sha
                if not dst.exists():
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    tmp = dst.with_name(f".{sha}.{os.getpid()}")
                    shutil.copyfile(path, tmp)
                    os.replace(tmp, dst)
                self.refs[sha] = None
            else:
                self.refs[sha] = ray.put(Path(path).read_bytes())
        return sha, self.refs[sha]


def materialize(files, scratch, shared_dir):
    """Writes each (path, sha, ref) below `scratch`: a relative path at `scratch/work/path`, an absolute
    one mirrored at `scratch/root/path` (relative layouts survive). Contents are cached per node in
    `$TMPDIR/frictl-ray-cache/<sha>` and checked against their hash. Returns {path: local path}."""
    cache = Path(tempfile.gettempdir()) / "frictl-ray-cache"
    cache.mkdir(parents=True, exist_ok=True)
    where = {}
    for path, sha, ref in files:
        cached = cache / sha
        if not cached.exists():
            if shared_dir:
                data = (Path(shared_dir) / "sha256" / sha).read_bytes()
            else:
                data = ray.get(ref)
            if hashlib.sha256(data).hexdigest() != sha:
                raise RuntimeError(f"{path}: content does not match its SHA-256 {sha}")
            tmp = cache / f".{sha}.{os.getpid()}"
            tmp.write_bytes(data)
            os.replace(tmp, cached)
        p = Path(path)
        local = scratch / "root" / p.relative_to("/") if p.is_absolute() else scratch / "work" / p
        local.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(cached, local)
        where[path] = str(local)
    return where


def find_frictl(hint):
    if hint and Path(hint).is_file():
        return hint
    found = shutil.which("frictl")
    if found:
        return found
    raise RuntimeError(f"frictl not found on this node ({hint!r} missing, none on PATH)")


def run_frictl(frictl, args, cwd):
    proc = subprocess.run([frictl, *args], cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(
            f"frictl {' '.join(args)} failed ({proc.returncode}):\n{proc.stderr[-4000:]}"
        )
    return proc


def prepare_task(frictl, robot_path, joint, files, shared_dir):
    """A joint's data and fit stages; returns the joint directory as tar bytes."""
    with tempfile.TemporaryDirectory(prefix="frictl-ray-") as tmp:
        scratch = Path(tmp)
        where = materialize(files, scratch, shared_dir)
        work = scratch / "work"
        work.mkdir(exist_ok=True)
        run_frictl(
            find_frictl(frictl),
            ["robot", "run", where[robot_path], "--out", str(work), "--joint", joint,
             "--until", "fit"],
            cwd=work,
        )
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w") as tar:
            tar.add(work / "joints" / joint, arcname=joint)
        return buf.getvalue()


def trial_task(frictl, joint, search_args, search_dir, trial, files, settings, shared_dir,
               threads):
    """One search trial in a scratch copy of the search directory; returns its outputs as bytes."""
    with tempfile.TemporaryDirectory(prefix="frictl-ray-") as tmp:
        scratch = Path(tmp)
        where = materialize(files, scratch, shared_dir)
        work = scratch / "work"
        sd = work / search_dir
        sd.mkdir(parents=True, exist_ok=True)
        if settings is not None:
            (sd / "search.json").write_bytes(settings)  # frictl refuses other settings
        args = [where.get(a, a) if Path(a).is_absolute() else a for a in search_args]
        args += ["--out", search_dir, "--only-trials", str(trial), "--threads", str(threads),
                 "--parallel", "1", "--quiet"]
        run_frictl(find_frictl(frictl), args, cwd=work)
        lines = [l for l in (sd / "results.jsonl").read_text().splitlines() if l.strip()]
        if len(lines) != 1:
            raise RuntimeError(f"{joint} trial {trial}: {len(lines)} result lines")
        out = {"line": lines[0], "search_json": (sd / "search.json").read_bytes(), "files": {}}
        result = json.loads(lines[0])
        if result.get("model"):
            model = sd / result["model"]
            report = model.with_suffix(".train.json")
            for p in (model, report):
                out["files"][str(p.relative_to(sd))] = p.read_bytes()
        kill = os.environ.get("FRICTL_RAY_TEST_KILL_ONCE", "")
        if kill:
            marker_dir, kjoint, ktrial = kill.rsplit(":", 2)
            marker = Path(marker_dir) / f"{kjoint}_{ktrial}"
            if kjoint == joint and int(ktrial) == trial and not marker.exists():
                marker.write_text(str(os.getpid()))
                os.kill(os.getpid(), signal.SIGKILL)  # this worker dies mid-task
        return out


def stage_done(out, joint_plan, phases):
    """A joint's stages of `phases` have stamps and outputs in `out` (`frictl robot run` re-checks the
    stamps' content hashes itself)."""
    for st in joint_plan["stages"]:
        if st["phase"] in phases:
            stamp = out / joint_plan["dir"] / "stamps" / f"{st['id']}.sha256"
            if not stamp.is_file() or not all((out / o).is_file() for o in st["outputs"]):
                return False
    return True


def recorded_trials(results_jsonl):
    done = set()
    if results_jsonl.is_file():
        for line in results_jsonl.read_text().splitlines():
            try:
                done.add(json.loads(line)["params"]["trial"])
            except (ValueError, KeyError):
                pass  # a torn last line
    return done


def append_line(path, line):
    """One write(2) of one line with O_APPEND (the format `frictl search` appends with)."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        data = (line.rstrip("\n") + "\n").encode()
        if os.write(fd, data) != len(data):
            raise OSError(f"{path}: short append")
    finally:
        os.close(fd)


class Progress:
    def __init__(self):
        self.done = self.failed = self.running = 0
        self.last = 0.0

    def show(self, force=False):
        now = time.monotonic()
        if force or now - self.last > 2.0:
            print(f"tasks: {self.done} done / {self.running} running / {self.failed} failed",
                  file=sys.stderr, flush=True)
            self.last = now


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("robot", help="the robot TOML file")
    ap.add_argument("--out", default="robot-out", help="output directory (on this machine)")
    ap.add_argument("--address", default="auto",
                    help="Ray address: auto, ray://HOST:10001, HOST:6379, or local (start Ray here)")
    ap.add_argument("--num-cpus", type=int, default=None, help="with --address local: CPUs")
    ap.add_argument("--frictl", default=os.environ.get("FRICTL") or shutil.which("frictl"),
                    help="the frictl binary (same path on every node, else found on PATH)")
    ap.add_argument("--max-retries", type=int, default=3, help="retries of a failed task")
    ap.add_argument("--no-finish", action="store_true",
                    help="only run the Ray tasks (no local `frictl robot run` at the end)")
    args = ap.parse_args(argv)
    if not args.frictl:
        ap.error("no frictl: pass --frictl or put it on PATH")
    frictl = str(Path(args.frictl).resolve())
    robot = Path(args.robot).resolve()
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    plan = json.loads(run_frictl(frictl, ["robot", "plan", str(robot), "--out", str(out)],
                                 cwd=out).stdout)
    shared_dir = plan["shared_dir"]
    threads = plan["threads_per_trial"]

    if args.address == "local":
        ray.init(address="local", num_cpus=args.num_cpus, include_dashboard=False,
                 log_to_driver=False,
                 object_store_memory=200 * 1024 * 1024)
    else:
        ray.init(address=args.address, log_to_driver=False)
    opts = dict(num_cpus=threads, max_retries=args.max_retries, retry_exceptions=True)
    prepare = ray.remote(**opts)(prepare_task)
    run_trial = ray.remote(**opts)(trial_task)
    store = Store(shared_dir)
    progress = Progress()
    started = time.monotonic()

    pending = {}  # ObjectRef -> (kind, joint plan, trial)
    joints = {j["name"]: j for j in plan["joints"]}

    def submit_trials(j):
        if not j["search_dir"]:
            return
        sd = out / j["search_dir"]
        done = recorded_trials(sd / "results.jsonl")
        inputs = [*j["train"], *[str(Path(p).with_suffix(".json")) for p in j["train"]], j["scv"]]
        files = []
        for p in inputs:
            sha, ref = store.put(p if Path(p).is_absolute() else out / p)
            files.append((p, sha, ref))
        settings = (sd / "search.json").read_bytes() if (sd / "search.json").is_file() else None
        for k in range(j["trials"]):
            if k in done:
                continue
            ref = run_trial.remote(frictl, j["name"], j["search_args"], j["search_dir"], k, files,
                                   settings, shared_dir, threads)
            pending[ref] = ("trial", j, k)
            progress.running += 1

    for j in plan["joints"]:
        if stage_done(out, j, ("data", "fit")):
            submit_trials(j)
            continue
        files = []
        for p in [str(robot), *j["external_inputs"]]:
            sha, ref = store.put(p)
            files.append((p, sha, ref))
        ref = prepare.remote(frictl, str(robot), j["name"], files, shared_dir)
        pending[ref] = ("prepare", j, None)
        progress.running += 1
    progress.show(force=True)

    errors = []
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1, timeout=2.0)
        progress.show()
        for ref in ready:
            kind, j, k = pending.pop(ref)
            progress.running -= 1
            try:
                value = ray.get(ref)
            except Exception as e:  # retries exhausted
                progress.failed += 1
                errors.append(f"{j['name']} {kind} {'' if k is None else k}: {e}")
                continue
            progress.done += 1
            if kind == "prepare":
                dst = out / j["dir"]
                dst.parent.mkdir(parents=True, exist_ok=True)
                with tarfile.open(fileobj=io.BytesIO(value)) as tar:
                    tar.extractall(dst.parent, filter="data")
                submit_trials(joints[j["name"]])
            else:
                sd = out / j["search_dir"]
                (sd / "trials").mkdir(parents=True, exist_ok=True)
                if not (sd / "search.json").exists():
                    (sd / "search.json").write_bytes(value["search_json"])
                for rel, data in value["files"].items():
                    (sd / rel).write_bytes(data)
                append_line(sd / "results.jsonl", value["line"])
    progress.show(force=True)
    ray_seconds = time.monotonic() - started
    print(f"ray: {progress.done} task(s) done, {progress.failed} failed in {ray_seconds:.1f} s",
          file=sys.stderr)
    ray.shutdown()
    if errors:
        for e in errors:
            print(f"failed: {e}", file=sys.stderr)
        return 1
    if not args.no_finish:
        proc = subprocess.run([frictl, "robot", "run", str(robot), "--out", str(out)])
        return proc.returncode
    return 0


if __name__ == "__main__":
    sys.exit(main())
