#!/usr/bin/env python3
"""Reference inverse- and forward-dynamics cases from Pinocchio for frictl's Rust RNEA and ABA
(tools/dynamics/tests/dynamics_pinocchio.rs).

Writes OUT/pinocchio_rnea.jsonl, one JSON object per line:

  {"model": "iCubGenova09" | "ergoCubSN001", "urdf": "/abs/path/model.urdf", "kind": "fixed" | "legs" | "floating",
   "keep": [joint names] | null,           # reduced model: only these joints movable ...
   "locked_q": {joint: rad},               # ... the others locked here (joints not listed: 0)
   "q": {joint: rad}, "qd": {joint: rad/s}, "qdd": {joint: rad/s^2},
   "base": {"pos": [x,y,z], "quat": [x,y,z,w], "vel": [vx,vy,vz,wx,wy,wz], "acc": [6]} | null,
   "wrenches": {frame: [fx,fy,fz,mx,my,mz]},
   "tau": {joint: Nm}, "base_wrench": [fx,fy,fz,mx,my,mz] | null}

Conventions (Pinocchio's): gravity [0, 0, -9.80665]; fixed base = root link welded to the world at identity;
floating base = free-flyer with body-fixed velocity (linear first) and q = [pos, quat xyzw]; base_wrench in the
root-link frame. Each external wrench acts ON the robot at the frame origin, expressed in the frame's axes.
Joints are named, never indexed: Pinocchio's order is depth-first and differs from ours.

Also writes OUT/pinocchio_aba.jsonl (fixed-base forward dynamics, Pinocchio's `aba`), one JSON object per line:

  {"model": ..., "urdf": ..., "kind": "fixed" | "left_leg", "keep": [joint names] | null, "locked_q": {joint: rad},
   "q": {joint: rad}, "qd": {joint: rad/s}, "tau": {joint: Nm}, "qdd": {joint: rad/s^2}}

for the ergoCub and iCub 3 left legs (the six joints movable, every other joint locked at a random position)
with random torques, and for the whole models with the torques of a random acceleration (random tau on a
finger would give accelerations of 1e7 rad/s^2).

Models: iCub 3 (`iCubGenova09` from icub-models==2.8.1) and the real ergoCub URDF
(`--ergocub PATH`, default tests/fixtures/ergocub/ergoCubSN001.urdf in the repository): fixed base,
legs-only and floating base with sole wrenches. Then every URDF of example-robot-data==6.0.0 (about 70
real descriptions: Panda, UR, Talos, TIAGo, G1, Go2, ANYmal, Baxter, PR2, Romeo, iCub, ...; model
label "erd:<path under robots/>") that Pinocchio loads: fixed base twice (the first at rest) and
floating base once. Continuous joints (Pinocchio nq = 2) are given by angle, like revolute ones.
"""

import argparse
import json
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pinocchio as pin

SEED = 20240917
GRAVITY = np.array([0.0, 0.0, -9.80665])  # Pinocchio's default is -9.81: set it explicitly
LEG_JOINTS = [f"{s}_{j}" for s in "lr" for j in ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch", "ankle_roll")]


def joint_limits(model, jid):
    """Finite sampling range for a 1-DoF joint: its URDF limits, or +-pi if unlimited."""
    iq = model.joints[jid].idx_q
    lo, hi = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi - lo > 100:
        lo, hi = -np.pi, np.pi
    return lo, hi


def revolute_joints(model):
    """(name, joint id) for every 1-DoF joint (revolute, prismatic, continuous), skipping the universe
    and a free-flyer."""
    out = []
    for jid in range(1, model.njoints):
        if model.joints[jid].nv == 1:
            out.append((model.names[jid], jid))
    return out


def is_continuous(model, jid):
    """A continuous joint: Pinocchio stores its angle as (cos, sin)."""
    return model.joints[jid].nq == 2


def random_state(model, rng):
    q, qd, qdd = {}, {}, {}
    for name, jid in revolute_joints(model):
        lo, hi = (-np.pi, np.pi) if is_continuous(model, jid) else joint_limits(model, jid)
        q[name] = float(rng.uniform(lo, hi))
        qd[name] = float(rng.uniform(-2.0, 2.0))
        qdd[name] = float(rng.uniform(-5.0, 5.0))
    return q, qd, qdd


def to_vectors(model, q, qd, qdd, base=None):
    qv, vv, av = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
    if base is not None:
        qv[0:3] = base["pos"]
        qv[3:7] = base["quat"]
        vv[0:6] = base["vel"]
        av[0:6] = base["acc"]
    for name, jid in revolute_joints(model):
        j = model.joints[jid]
        if is_continuous(model, jid):
            qv[j.idx_q], qv[j.idx_q + 1] = np.cos(q.get(name, 0.0)), np.sin(q.get(name, 0.0))
        else:
            qv[j.idx_q] = q.get(name, 0.0)
        vv[j.idx_v] = qd.get(name, 0.0)
        av[j.idx_v] = qdd.get(name, 0.0)
    return qv, vv, av


def run_rnea(model, q, qd, qdd, base=None, wrenches=None):
    model.gravity.linear = GRAVITY
    data = model.createData()
    qv, vv, av = to_vectors(model, q, qd, qdd, base)
    fext = pin.StdVec_Force()
    for _ in range(model.njoints):
        fext.append(pin.Force.Zero())
    for frame_name, w in (wrenches or {}).items():
        fid = model.getFrameId(frame_name)
        if fid >= len(model.frames):
            raise SystemExit(f"frame {frame_name} not in model")
        fr = model.frames[fid]
        # wrench [f; n] in the frame, about its origin -> parent joint frame
        fext[fr.parentJoint] += fr.placement.act(pin.Force(np.array(w[0:3]), np.array(w[3:6])))
    tau = pin.rnea(model, data, qv, vv, av, fext)
    out = {}
    for name, jid in revolute_joints(model):
        out[name] = float(tau[model.joints[jid].idx_v])
    base_wrench = [float(x) for x in tau[0:6]] if base is not None else None
    return out, base_wrench


def random_base(rng):
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    return {
        "pos": [float(x) for x in rng.uniform(-1.0, 1.0, 3)],
        "quat": [float(x) for x in quat],  # x, y, z, w
        "vel": [float(x) for x in rng.uniform(-1.0, 1.0, 6)],
        "acc": [float(x) for x in rng.uniform(-3.0, 3.0, 6)],
    }


def random_wrench(rng):
    return [float(x) for x in np.concatenate([rng.uniform(-300, 300, 3), rng.uniform(-20, 20, 3)])]


def cases_for(label, urdf, rng, n_fixed, n_legs, n_float):
    urdf = str(Path(urdf).resolve())
    fixed = pin.buildModelFromUrdf(urdf)
    floating = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
    cases = []

    def case(kind, q, qd, qdd, tau, keep=None, locked=None, base=None, wrenches=None, base_wrench=None):
        return {
            "model": label, "urdf": urdf, "kind": kind, "keep": keep, "locked_q": locked or {},
            "q": q, "qd": qd, "qdd": qdd, "base": base, "wrenches": wrenches or {},
            "tau": tau, "base_wrench": base_wrench,
        }

    # Fixed base, all joints; the first case is gravity only at a random posture.
    for i in range(n_fixed):
        q, qd, qdd = random_state(fixed, rng)
        if i == 0:
            qd = {k: 0.0 for k in qd}
            qdd = {k: 0.0 for k in qdd}
        tau, _ = run_rnea(fixed, q, qd, qdd)
        cases.append(case("fixed", q, qd, qdd, tau))

    # Legs only: reduced model, every other joint locked at a random position.
    ids_to_lock = [jid for name, jid in revolute_joints(fixed) if name not in LEG_JOINTS]
    for _ in range(n_legs):
        q_all, qd_all, qdd_all = random_state(fixed, rng)
        locked = {fixed.names[jid]: q_all[fixed.names[jid]] for jid in ids_to_lock}
        q_ref, _, _ = to_vectors(fixed, q_all, {}, {})
        reduced = pin.buildReducedModel(fixed, ids_to_lock, q_ref)
        q = {k: q_all[k] for k in LEG_JOINTS}
        qd = {k: qd_all[k] for k in LEG_JOINTS}
        qdd = {k: qdd_all[k] for k in LEG_JOINTS}
        tau, _ = run_rnea(reduced, q, qd, qdd)
        assert sorted(tau) == sorted(LEG_JOINTS), sorted(tau)
        cases.append(case("legs", q, qd, qdd, tau, keep=LEG_JOINTS, locked=locked))

    # Floating base with wrenches on the soles.
    for i in range(n_float):
        q, qd, qdd = random_state(floating, rng)
        base = random_base(rng)
        wrenches = {"l_sole": random_wrench(rng)}
        if i % 2 == 1:
            wrenches["r_sole"] = random_wrench(rng)
        tau, bw = run_rnea(floating, q, qd, qdd, base, wrenches)
        cases.append(case("floating", q, qd, qdd, tau, base=base, wrenches=wrenches, base_wrench=bw))
    return cases


def run_aba(model, q, qd, tau):
    model.gravity.linear = GRAVITY
    data = model.createData()
    qv, vv, _ = to_vectors(model, q, qd, {})
    tv = np.zeros(model.nv)
    for name, jid in revolute_joints(model):
        tv[model.joints[jid].idx_v] = tau[name]
    ddq = pin.aba(model, data, qv, vv, tv)
    return {name: float(ddq[model.joints[jid].idx_v]) for name, jid in revolute_joints(model)}


def aba_cases_for(label, urdf, rng, n_fixed, n_leg):
    urdf = str(Path(urdf).resolve())
    fixed = pin.buildModelFromUrdf(urdf)
    cases = []
    for _ in range(n_fixed):
        q, qd, qdd = random_state(fixed, rng)
        tau, _ = run_rnea(fixed, q, qd, qdd)
        cases.append({"model": label, "urdf": urdf, "kind": "fixed", "keep": None, "locked_q": {},
                      "q": q, "qd": qd, "tau": tau, "qdd": run_aba(fixed, q, qd, tau)})
    left = [j for j in LEG_JOINTS if j.startswith("l_")]
    ids_to_lock = [jid for name, jid in revolute_joints(fixed) if name not in left]
    for _ in range(n_leg):
        q_all, qd_all, _ = random_state(fixed, rng)
        locked = {fixed.names[jid]: q_all[fixed.names[jid]] for jid in ids_to_lock}
        q_ref, _, _ = to_vectors(fixed, q_all, {}, {})
        reduced = pin.buildReducedModel(fixed, ids_to_lock, q_ref)
        q = {k: q_all[k] for k in left}
        qd = {k: qd_all[k] for k in left}
        tau = {k: float(rng.uniform(-30.0, 30.0)) for k in left}
        qdd = run_aba(reduced, q, qd, tau)
        assert sorted(qdd) == sorted(left), sorted(qdd)
        cases.append({"model": label, "urdf": urdf, "kind": "left_leg", "keep": left, "locked_q": locked,
                      "q": q, "qd": qd, "tau": tau, "qdd": qdd})
    return cases


def erd_cases(rng):
    """Fixed (twice, the first at rest) and floating-base cases for every example-robot-data URDF
    Pinocchio loads; prints the ones it refuses."""
    root = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
    urdfs = sorted(root.glob("**/*.urdf"))
    if not urdfs:
        sys.exit(f"gen_pinocchio_refs: no URDF under {root} (needs example-robot-data==6.0.0)")
    cases = []
    for urdf in urdfs:
        label = "erd:" + str(urdf.relative_to(root))
        try:
            fixed = pin.buildModelFromUrdf(str(urdf))
            floating = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
        except Exception as e:  # noqa: BLE001 - Pinocchio raises plain exceptions
            print(f"gen_pinocchio_refs: skipped {label}: Pinocchio refuses it ({str(e).splitlines()[0]})")
            continue
        for i in range(2):
            q, qd, qdd = random_state(fixed, rng)
            if i == 0:
                qd = {k: 0.0 for k in qd}
                qdd = {k: 0.0 for k in qdd}
            tau, _ = run_rnea(fixed, q, qd, qdd)
            cases.append({
                "model": label, "urdf": str(urdf), "kind": "fixed", "keep": None, "locked_q": {},
                "q": q, "qd": qd, "qdd": qdd, "base": None, "wrenches": {}, "tau": tau, "base_wrench": None,
            })
        q, qd, qdd = random_state(floating, rng)
        base = random_base(rng)
        tau, bw = run_rnea(floating, q, qd, qdd, base)
        cases.append({
            "model": label, "urdf": str(urdf), "kind": "floating", "keep": None, "locked_q": {},
            "q": q, "qd": qd, "qdd": qdd, "base": base, "wrenches": {}, "tau": tau, "base_wrench": bw,
        })
    return cases


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--ergocub", help="ergoCub URDF (default: tests/fixtures/ergocub/ergoCubSN001.urdf)")
    args = ap.parse_args()

    import icub_models

    repo = Path(__file__).resolve().parents[2]
    ergocub = Path(args.ergocub) if args.ergocub else repo / "tests" / "fixtures" / "ergocub" / "ergoCubSN001.urdf"
    if not ergocub.is_file():
        sys.exit(f"gen_pinocchio_refs: ergoCub URDF not found at {ergocub} (pass --ergocub PATH)")
    icub3 = Path(str(icub_models.get_model_file("iCubGenova09")))
    if not icub3.is_file():
        sys.exit(f"gen_pinocchio_refs: iCubGenova09 URDF not found at {icub3} (needs icub-models==2.8.1)")

    rng = np.random.default_rng(SEED)
    cases = cases_for("iCubGenova09", icub3, rng, n_fixed=12, n_legs=6, n_float=8)
    cases += cases_for("ergoCubSN001", ergocub, rng, n_fixed=8, n_legs=4, n_float=6)
    cases += erd_cases(rng)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "pinocchio_rnea.jsonl"
    with open(path, "w") as f:
        for c in cases:
            f.write(json.dumps(c) + "\n")
    print(f"gen_pinocchio_refs: wrote {len(cases)} cases (pinocchio {pin.__version__}) to {path}")

    # Forward dynamics: its own generator stream, so the RNEA cases above stay what they were.
    rng = np.random.default_rng(SEED + 1)
    aba = aba_cases_for("ergoCubSN001", ergocub, rng, n_fixed=4, n_leg=40)
    aba += aba_cases_for("iCubGenova09", icub3, rng, n_fixed=4, n_leg=10)
    path = out / "pinocchio_aba.jsonl"
    with open(path, "w") as f:
        for c in aba:
            f.write(json.dumps(c) + "\n")
    print(f"gen_pinocchio_refs: wrote {len(aba)} forward-dynamics cases to {path}")


if __name__ == "__main__":
    main()
