//! Whole-body τ_ID for the `current` label: τ_ID = RNEA(q, q̇, q̈) on the whole URDF at every grid
//! sample, with q of every joint the log has ([`JointStates`]), the joints it lacks held at given
//! positions (0 when not given), a fixed base at the identity pose or one oriented by a logged
//! quaternion (a robot on a tilted pole).
//!
//! Each logged joint goes through the same resampler and Kalman smoother as the labelled joint (its
//! q̇, q̈ as given when the log has them), so the label of every joint sees the same estimates.
//! One RNEA per sample gives τ_ID of every labelled joint ([`super::preprocess::preprocess_joints`]).
//!
//! Measured wrenches applied to the robot at named frames (a foot's force-torque sensor) enter the
//! RNEA as external wrenches ([`FrameWrench`]: τ = M·q̈ + h − Jᵀ·f_ext).
//!
//! What it is **not**: a contact or floating-base estimator (no base velocity or acceleration), or
//! a reader of logs (`frictionless-logs` fills [`JointStates`]).

use std::collections::BTreeMap;

use frictionless_dynamics::{BaseState, ExternalWrench, Force, FrameId, Motion, Robot, Workspace};
use nalgebra::{Rotation3, UnitQuaternion};
use serde::Serialize;

use super::kalman::{self, KalmanConfig};
use super::preprocess::{JointLabel, PreprocessError, RunSignals, interp};

/// Positions (and, when logged, velocities and accelerations) of every robot joint a log has, on one
/// run's clock (one value per sample of the run's `time_s`), SI units.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointStates {
    /// Joint names as the log spells them (matched to the URDF by name).
    pub names: Vec<String>,
    /// Position per joint [rad or m].
    pub q: Vec<Vec<f64>>,
    /// Velocity per joint when logged [rad/s or m/s] (absent: from q through the Kalman smoother).
    pub qdot: Vec<Option<Vec<f64>>>,
    /// Acceleration per joint when logged [rad/s² or m/s²] (absent: from the smoother).
    pub qddot: Vec<Option<Vec<f64>>>,
    /// Orientation in the world of the root link, or of [`Self::base_frame`], unit quaternion
    /// `[x, y, z, w]` per sample (absent: the root link is welded to the world at the identity
    /// pose).
    pub base_quat_xyzw: Option<[Vec<f64>; 4]>,
    /// The frame whose orientation `base_quat_xyzw` is, as the log names it (an IMU's; `None`:
    /// the root link's). The label places it on the root link through the URDF at each sample's q
    /// ([`WholeBody::with_base_frame`] overrides it).
    pub base_frame: Option<String>,
    /// Measured wrenches applied to the robot at named frames, per sample.
    pub wrenches: Vec<FrameWrench>,
}

/// A measured wrench applied **to** the robot at a named frame (link or joint frame of the URDF),
/// in that frame's coordinates, about its origin, one value per sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameWrench {
    /// Frame name (the URDF's).
    pub frame: String,
    /// `[fx, fy, fz]` [N] then `[mx, my, mz]` [N·m].
    pub series: [Vec<f64>; 6],
}

impl JointStates {
    /// An empty state for `names`, every series with room for `capacity` samples.
    pub fn with_names(names: Vec<String>, qdot: &[bool], qddot: &[bool], capacity: usize) -> Self {
        let n = names.len();
        let v = |has: bool| has.then(|| Vec::with_capacity(capacity));
        Self {
            q: (0..n).map(|_| Vec::with_capacity(capacity)).collect(),
            qdot: (0..n)
                .map(|k| v(qdot.get(k).copied().unwrap_or(false)))
                .collect(),
            qddot: (0..n)
                .map(|k| v(qddot.get(k).copied().unwrap_or(false)))
                .collect(),
            names,
            base_quat_xyzw: None,
            base_frame: None,
            wrenches: Vec::new(),
        }
    }

    /// Checks that every series has `n` samples; the message names the joint.
    pub fn check(&self, n: usize) -> Result<(), String> {
        if self.q.len() != self.names.len()
            || self.qdot.len() != self.names.len()
            || self.qddot.len() != self.names.len()
        {
            return Err("the joint state has a different number of names and series".into());
        }
        for (k, name) in self.names.iter().enumerate() {
            let lens = [
                Some(self.q[k].len()),
                self.qdot[k].as_ref().map(Vec::len),
                self.qddot[k].as_ref().map(Vec::len),
            ];
            if let Some(m) = lens.into_iter().flatten().find(|&m| m != n) {
                return Err(format!(
                    "joint `{name}` has {m} samples, the run has {n}: mismatched time bases"
                ));
            }
        }
        if let Some(b) = &self.base_quat_xyzw
            && let Some(m) = b.iter().map(Vec::len).find(|&m| m != n)
        {
            return Err(format!(
                "the base quaternion has {m} samples, the run has {n}: mismatched time bases"
            ));
        }
        for w in &self.wrenches {
            if let Some(m) = w.series.iter().map(Vec::len).find(|&m| m != n) {
                return Err(format!(
                    "the wrench at `{}` has {m} samples, the run has {n}: mismatched time bases",
                    w.frame
                ));
            }
        }
        Ok(())
    }
}

/// Where each URDF joint's position comes from, for the dataset sidecar.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StatePlan {
    /// URDF joints whose q comes from the log.
    pub from_log: Vec<String>,
    /// URDF joints held at a given position (`--fixed-joint`; wins over the log) [rad or m].
    pub held: BTreeMap<String, f64>,
    /// URDF joints neither in the log nor given: held at 0.
    pub held_at_zero: Vec<String>,
    /// Those of [`Self::held_at_zero`] whose position changes the label of a labelled joint
    /// ([`WholeBody::label_joints`]); the others are held silently.
    pub held_at_zero_relevant: Vec<String>,
    /// Names in the log that are not movable joints of the URDF (not used).
    pub not_in_urdf: Vec<String>,
    /// The base: fixed at the identity pose, or its orientation from the log (the root link's, or
    /// a named frame's placed on it through the URDF).
    pub base: String,
    /// Frames with a measured external wrench from the log.
    pub wrenches: Vec<String>,
}

impl StatePlan {
    /// The warnings of the plan, one line each: the URDF joints held at 0 that change a label
    /// (named; how many others are held at 0 without changing one), and the log's joints the URDF
    /// lacks.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !self.held_at_zero_relevant.is_empty() {
            let silent = self.held_at_zero.len() - self.held_at_zero_relevant.len();
            out.push(format!(
                "URDF joints neither in the log nor given with --fixed-joint, held at 0 rad, that \
                 change the label (on the path from the root to a labelled joint or below it): {}; \
                 {silent} other joints held at 0 rad do not change it (settings whole_body.held_at_zero)",
                self.held_at_zero_relevant.join(", ")
            ));
        }
        if !self.not_in_urdf.is_empty() {
            out.push(format!(
                "log joints the URDF lacks (not used): {}",
                self.not_in_urdf.join(", ")
            ));
        }
        out
    }
}

/// How a sidecar's `dynamics` line names the gravity of τ_ID: `g = 9.80665 m/s²`.
pub fn gravity_text(gravity_m_s2: f64) -> String {
    format!("g = {gravity_m_s2} m/s²")
}

/// The robot and the held joint positions of the whole-body τ_ID.
#[derive(Clone, Debug)]
pub struct WholeBody {
    robot: Robot,
    held: BTreeMap<String, f64>,
    q_held: Vec<f64>,
    /// The frame whose orientation a logged base orientation is, whatever the log says.
    base_frame: Option<String>,
}

/// One joint whose q comes from the log (or from a labelled joint's own signals).
pub(crate) struct Track<'a> {
    index: usize,
    q: &'a [f64],
    qd: Option<&'a [f64]>,
    qdd: Option<&'a [f64]>,
}

/// A labelled joint's own series (used when the state lacks it).
pub(crate) struct Labelled<'a> {
    pub(crate) joint: String,
    pub(crate) q: Option<&'a [f64]>,
    pub(crate) qd: Option<&'a [f64]>,
    pub(crate) qdd: Option<&'a [f64]>,
}

/// The logged joints of one run, by robot index.
pub(crate) struct Tracks<'a> {
    joints: Vec<Track<'a>>,
    base: Option<&'a [Vec<f64>; 4]>,
    /// The frame whose orientation `base` is (`None`: the root link).
    base_frame: Option<FrameId>,
    wrenches: Vec<(FrameId, &'a [Vec<f64>; 6])>,
}

fn bad(msg: String) -> PreprocessError {
    PreprocessError::Sidecar {
        path: "imported signals".into(),
        msg,
    }
}

/// One logged joint on the label grid: (URDF index, q [rad], q̇ [rad/s], q̈ [rad/s²]).
type GridTrack = (usize, Vec<f64>, Vec<f64>, Vec<f64>);

impl WholeBody {
    /// `held`: positions of joints held fixed [rad or m] (each must be a movable joint of `robot`,
    /// finite).
    pub fn new(robot: Robot, held: BTreeMap<String, f64>) -> Result<Self, PreprocessError> {
        let mut q_held = vec![0.0; robot.dof()];
        for (name, &v) in &held {
            let k = robot.joint_index(name).map_err(|e| bad(e.to_string()))?;
            if !v.is_finite() {
                return Err(bad(format!("held joint `{name}` = {v}: must be finite")));
            }
            q_held[k] = v;
        }
        Ok(Self {
            robot,
            held,
            q_held,
            base_frame: None,
        })
    }

    /// The frame (a URDF link or joint, e.g. an IMU's) whose orientation in the world a logged base
    /// orientation is, instead of the one the log names (`None`: the log's; the root link when it
    /// names none). Fails when the URDF has no such frame.
    pub fn with_base_frame(mut self, frame: Option<String>) -> Result<Self, PreprocessError> {
        if let Some(f) = &frame {
            self.robot
                .frame_id(f)
                .map_err(|e| bad(format!("--base-frame {f}: {e}")))?;
        }
        self.base_frame = frame;
        Ok(self)
    }

    /// The frame whose orientation a logged base orientation is: the override, else the log's
    /// name for it (`log_frame`); `None` for the root link. A name the URDF lacks is an error
    /// saying how to name it.
    fn resolve_base_frame(&self, log_frame: Option<&str>) -> Result<Option<FrameId>, String> {
        let Some(name) = self.base_frame.as_deref().or(log_frame) else {
            return Ok(None);
        };
        // A ROS 1 style frame id (`/imu_link`) names the URDF's `imu_link`.
        let name = match self.robot.frame_id(name) {
            Err(_) if name.starts_with('/') => name.trim_start_matches('/'),
            _ => name,
        };
        if name == self.robot.root_link {
            return Ok(None);
        }
        self.robot.frame_id(name).map(Some).map_err(|_| {
            format!(
                "the log gives the orientation of frame `{name}`, which the URDF {} lacks: pass \
                 --base-frame with the URDF frame it is (the sensor's frame, or the root link `{}`)",
                self.robot.source, self.robot.root_link
            )
        })
    }

    /// The robot.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The sidecar's `dynamics` line of the whole-body τ_ID with `plan`, pointing at the plan's
    /// place in the sidecar (`plan_key`, e.g. `settings.whole_body`).
    pub fn describe(&self, plan: &StatePlan, plan_key: &str) -> String {
        format!(
            "whole-body RNEA on URDF {} ({} joints): {} from the log, {} held at given values, {} \
             held at 0; base {}; {} ({plan_key})",
            self.robot.source,
            self.robot.dof(),
            plan.from_log.len(),
            plan.held.len(),
            plan.held_at_zero.len(),
            plan.base,
            gravity_text(self.robot.gravity_m_s2())
        )
    }

    /// Which joints' positions change τ_ID of the joints `labelled` (URDF indices), by joint index:
    /// for each labelled joint, the joints on the path from the root to it (their positions turn
    /// gravity and the motion it is carried by) and the joints below it (their bodies' masses and
    /// motions load it); with the orientation of a frame `base_frame` giving the base's, the joints
    /// between the root and that frame. A joint of another branch moves no body whose force reaches
    /// the labelled joint, the base being fixed or its motion given
    /// (`tests::a_joint_of_another_branch_leaves_the_torque_unchanged`).
    pub fn label_joints(&self, labelled: &[usize], base_frame: Option<FrameId>) -> Vec<bool> {
        let joints = &self.robot.joints;
        let mut out = vec![false; joints.len()];
        // Marks the joints from body `b` up to the root.
        let up = |mut b: usize, out: &mut [bool]| {
            while b > 0 {
                out[b - 1] = true;
                b = joints[b - 1].parent_body;
            }
        };
        for &j in labelled {
            up(j + 1, &mut out);
        }
        if let Some(f) = base_frame {
            up(self.robot.frames[f.0].body, &mut out);
        }
        for (k, o) in out.iter_mut().enumerate() {
            let mut b = k + 1;
            while b > 0 && !labelled.contains(&(b - 1)) {
                b = joints[b - 1].parent_body;
            }
            *o |= b > 0;
        }
        out
    }

    /// Which URDF joints come from a log holding `log_names` (plus the `labelled` joints, whose own
    /// positions count as logged).
    /// `base`: whether the log gives a base orientation, and the frame it names for it.
    pub fn plan(
        &self,
        log_names: &[String],
        labelled: &[String],
        base: Option<Option<&str>>,
    ) -> StatePlan {
        let frame = base.map(|f| self.resolve_base_frame(f));
        let labelled_index: Vec<usize> = labelled
            .iter()
            .filter_map(|n| self.robot.joint_index(n).ok())
            .collect();
        let relevant = if labelled_index.is_empty() {
            // No labelled joint of the URDF: every joint counts.
            vec![true; self.robot.dof()]
        } else {
            let base_frame = match &frame {
                Some(Ok(f)) => *f,
                _ => None,
            };
            self.label_joints(&labelled_index, base_frame)
        };
        let mut p = StatePlan {
            base: match frame {
                None => "fixed at the identity pose".into(),
                Some(Ok(None)) => "root-link orientation from the log (at rest)".into(),
                Some(Ok(Some(id))) => format!(
                    "orientation of frame `{}` from the log, placed on the root link through the \
                     URDF at each sample's q (at rest)",
                    self.robot.frames[id.0].name
                ),
                Some(Err(e)) => e,
            },
            ..StatePlan::default()
        };
        for (k, name) in self.robot.joint_names().enumerate() {
            if let Some(&v) = self.held.get(name) {
                p.held.insert(name.to_string(), v);
            } else if log_names.iter().chain(labelled).any(|n| n == name) {
                p.from_log.push(name.to_string());
            } else {
                p.held_at_zero.push(name.to_string());
                if relevant[k] {
                    p.held_at_zero_relevant.push(name.to_string());
                }
            }
        }
        for n in log_names {
            if self.robot.joint_index(n).is_err() && !p.not_in_urdf.contains(n) {
                p.not_in_urdf.push(n.clone());
            }
        }
        p
    }

    /// The logged joints of one run: every state joint the URDF has (not held), then every labelled
    /// joint the state lacks, from its own signals.
    pub(crate) fn tracks<'a>(
        &self,
        st: &'a JointStates,
        joints: &[JointLabel],
        signals: &[&'a RunSignals],
    ) -> Result<Tracks<'a>, PreprocessError> {
        let labelled: Vec<Labelled<'a>> = joints
            .iter()
            .zip(signals)
            .map(|(jl, sig)| Labelled {
                joint: jl.joint.clone(),
                q: sig.s_rad.as_deref(),
                qd: sig.sdot_rad_s.as_deref(),
                qdd: sig.sddot_rad_s2.as_deref(),
            })
            .collect();
        self.tracks_of(st, &labelled)
    }

    /// [`Self::tracks`] with the labelled joints' own series given directly.
    pub(crate) fn tracks_of<'a>(
        &self,
        st: &'a JointStates,
        labelled: &[Labelled<'a>],
    ) -> Result<Tracks<'a>, PreprocessError> {
        let mut out: Vec<Track<'a>> = Vec::new();
        for (k, name) in st.names.iter().enumerate() {
            let Ok(index) = self.robot.joint_index(name) else {
                continue;
            };
            if self.held.contains_key(name) || out.iter().any(|t| t.index == index) {
                continue;
            }
            out.push(Track {
                index,
                q: &st.q[k],
                qd: st.qdot[k].as_deref(),
                qdd: st.qddot[k].as_deref(),
            });
        }
        for l in labelled {
            let Ok(index) = self.robot.joint_index(&l.joint) else {
                continue;
            };
            if self.held.contains_key(&l.joint) || out.iter().any(|t| t.index == index) {
                continue;
            }
            let Some(q) = l.q else {
                return Err(bad(format!(
                    "joint `{}`: the whole-body label needs its position",
                    l.joint
                )));
            };
            out.push(Track {
                index,
                q,
                qd: l.qd,
                qdd: l.qdd,
            });
        }
        let wrenches = st
            .wrenches
            .iter()
            .map(|w| {
                self.robot
                    .frame_id(&w.frame)
                    .map(|id| (id, &w.series))
                    .map_err(|e| bad(format!("--wrench {}: {e}", w.frame)))
            })
            .collect::<Result<_, _>>()?;
        let base_frame = match st.base_quat_xyzw {
            Some(_) => self
                .resolve_base_frame(st.base_frame.as_deref())
                .map_err(bad)?,
            None => None,
        };
        Ok(Tracks {
            joints: out,
            base: st.base_quat_xyzw.as_ref(),
            base_frame,
            wrenches,
        })
    }

    /// τ_ID of the robot joints `wanted` (indices) on the grid `tq` of samples `a..b` of a run with
    /// time `time_s`: one column per wanted joint.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn chunk_tau(
        &self,
        ws: &mut Workspace,
        tracks: &Tracks<'_>,
        time_s: &[f64],
        a: usize,
        b: usize,
        tq: &[f64],
        kalman_cfg: &KalmanConfig,
        dt_s: f64,
        wanted: &[usize],
    ) -> Result<Vec<Vec<f64>>, PreprocessError> {
        let t = &time_s[a..b];
        let n = tq.len();
        let li = |y: &[f64]| interp(t, &y[a..b], tq);
        // q, q̇, q̈ of every logged joint on the grid (the labelled joint's own derivation rules).
        let mut grid: Vec<GridTrack> = Vec::with_capacity(tracks.joints.len());
        for tr in &tracks.joints {
            let q = li(tr.q);
            let (qd, qdd) = match (tr.qd, tr.qdd) {
                (Some(v), Some(acc)) => (li(v), li(acc)),
                (Some(v), None) => {
                    let v = li(v);
                    let acc = kalman::smooth(kalman_cfg, dt_s, &v)?.vel_rad_s;
                    (v, acc)
                }
                (None, acc) => {
                    let e = kalman::smooth(kalman_cfg, dt_s, &q)?;
                    (e.vel_rad_s, acc.map_or(e.acc_rad_s2, li))
                }
            };
            grid.push((tr.index, q, qd, qdd));
        }
        let base = tracks
            .base
            .map(|b| [li(&b[0]), li(&b[1]), li(&b[2]), li(&b[3])]);
        let wrenches: Vec<(FrameId, [Vec<f64>; 6])> = tracks
            .wrenches
            .iter()
            .map(|(id, s)| (*id, std::array::from_fn(|c| li(&s[c]))))
            .collect();
        let mut ext: Vec<ExternalWrench> = wrenches
            .iter()
            .map(|(id, _)| ExternalWrench {
                frame: *id,
                wrench: Force::ZERO,
            })
            .collect();
        let dof = self.robot.dof();
        let mut q = self.q_held.clone();
        let (mut qd, mut qdd, mut tau) = (vec![0.0; dof], vec![0.0; dof], vec![0.0; dof]);
        let mut out: Vec<Vec<f64>> = wanted.iter().map(|_| Vec::with_capacity(n)).collect();
        let err = |e: frictionless_dynamics::DynamicsError| bad(e.to_string());
        for k in 0..n {
            for (i, gq, gqd, gqdd) in &grid {
                q[*i] = gq[k];
                qd[*i] = gqd[k];
                qdd[*i] = gqdd[k];
            }
            for (e, (_, s)) in ext.iter_mut().zip(&wrenches) {
                e.wrench.lin = [s[0][k], s[1][k], s[2][k]].into();
                e.wrench.ang = [s[3][k], s[4][k], s[5][k]].into();
            }
            match &base {
                None if ext.is_empty() => {
                    self.robot.rnea(ws, &q, &qd, &qdd, &mut tau).map_err(err)?
                }
                None => self
                    .robot
                    .rnea_with_wrenches(ws, &q, &qd, &qdd, &ext, &mut tau)
                    .map_err(err)?,
                Some(bq) => {
                    let quat = [bq[0][k], bq[1][k], bq[2][k], bq[3][k]];
                    match BaseState::from_arrays([0.0; 3], quat, [0.0; 6], [0.0; 6]) {
                        Ok(mut bs) => {
                            bs.vel = Motion::ZERO;
                            if let Some(f) = tracks.base_frame {
                                // R_world_root = R_world_frame · R_root_frame(q)ᵀ.
                                let x = self.robot.frame_placement(f, &q).map_err(err)?;
                                let r = Rotation3::from_matrix_unchecked(x.rot);
                                bs.orientation *=
                                    UnitQuaternion::from_rotation_matrix(&r).inverse();
                            }
                            self.robot
                                .rnea_floating(ws, &bs, &q, &qd, &qdd, &ext, &mut tau)
                                .map_err(err)?;
                        }
                        // A zero or non-finite quaternion: no τ_ID for this sample (invalid).
                        Err(_) => tau.iter_mut().for_each(|x| *x = f64::NAN),
                    }
                }
            }
            for (o, &w) in out.iter_mut().zip(wanted) {
                o.push(tau[w]);
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ergocub() -> WholeBody {
        let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/fixtures/ergocub/ergoCubSN001.urdf");
        WholeBody::new(Robot::from_urdf_file(urdf).unwrap(), BTreeMap::new()).unwrap()
    }

    /// The left leg of ergoCub, root to foot.
    const LEFT_LEG: [&str; 6] = [
        "l_hip_pitch",
        "l_hip_roll",
        "l_hip_yaw",
        "l_knee",
        "l_ankle_pitch",
        "l_ankle_roll",
    ];

    #[test]
    fn a_joint_of_another_branch_leaves_the_torque_unchanged() {
        let b = ergocub();
        let r = b.robot();
        let knee = r.joint_index("l_knee").unwrap();
        let rel = b.label_joints(&[knee], None);
        let mut set: Vec<&str> = (0..r.dof())
            .filter(|&k| rel[k])
            .map(|k| r.joints[k].name.as_str())
            .collect();
        set.sort_unstable();
        let mut leg = LEFT_LEG.to_vec();
        leg.sort_unstable();
        assert_eq!(set, leg);
        // A state with every joint moving, and a base moving in the world.
        let dof = r.dof();
        let wave = |f: f64| -> Vec<f64> {
            (0..dof)
                .map(|k| 0.5 * ((k as f64 + 1.0) * f).sin())
                .collect()
        };
        let (q, qd, qdd) = (wave(1.3), wave(2.1), wave(0.7));
        let base = BaseState::from_arrays(
            [0.1, -0.2, 0.8],
            [0.1, 0.2, -0.1, 0.9],
            [0.3, -0.1, 0.2, 0.4, -0.6, 0.2],
            [1.0, 2.0, -0.5, 0.7, 0.3, -1.1],
        )
        .unwrap();
        let mut ws = Workspace::new(r);
        let mut tau = vec![0.0; dof];
        let mut knee_tau = |q: &[f64], qd: &[f64], qdd: &[f64], floating: bool| {
            if floating {
                r.rnea_floating(&mut ws, &base, q, qd, qdd, &[], &mut tau)
                    .unwrap();
            } else {
                r.rnea(&mut ws, q, qd, qdd, &mut tau).unwrap();
            }
            tau[knee]
        };
        for floating in [false, true] {
            let tau0 = knee_tau(&q, &qd, &qdd, floating);
            for k in 0..dof {
                let (mut q1, mut qd1, mut qdd1) = (q.clone(), qd.clone(), qdd.clone());
                q1[k] += 0.3;
                qd1[k] += 0.5;
                qdd1[k] += 2.0;
                let d = (knee_tau(&q1, &qd1, &qdd1, floating) - tau0).abs();
                let name = &r.joints[k].name;
                if rel[k] {
                    assert!(
                        d > 1e-6,
                        "{name} (floating {floating}) changes the knee: {d}"
                    );
                } else {
                    assert!(
                        d < 1e-9,
                        "{name} (floating {floating}) leaves the knee: {d}"
                    );
                }
            }
        }
        // A base orientation given as the waist IMU's puts the torso between it and the root.
        let imu = r.frame_id("waist_imu_0").unwrap();
        let rel = b.label_joints(&[knee], Some(imu));
        assert!(rel[r.joint_index("torso_roll").unwrap()]);
        assert!(!rel[r.joint_index("r_knee").unwrap()]);
    }

    #[test]
    fn only_joints_that_change_a_label_are_warned_about() {
        let b = ergocub();
        let knee = ["l_knee".to_string()];
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        // The whole leg logged: nothing held at 0 changes the knee's label.
        let p = b.plan(&names(&LEFT_LEG), &knee, None);
        assert!(p.held_at_zero.contains(&"r_knee".to_string()));
        assert!(p.held_at_zero_relevant.is_empty());
        assert!(p.warnings().is_empty(), "{:?}", p.warnings());
        // Without the hip roll: it is named, the others are counted.
        let no_roll: Vec<&str> = LEFT_LEG
            .into_iter()
            .filter(|j| *j != "l_hip_roll")
            .collect();
        let p = b.plan(&names(&no_roll), &knee, None);
        assert_eq!(p.held_at_zero_relevant, ["l_hip_roll"]);
        let w = p.warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        let silent = p.held_at_zero.len() - 1;
        assert!(
            w[0].contains(": l_hip_roll; ")
                && w[0].contains(&format!("{silent} other joints held at 0 rad"))
                && !w[0].contains("r_knee"),
            "{}",
            w[0]
        );
        // The torso carries the waist IMU that gives the base's orientation.
        let p = b.plan(&names(&LEFT_LEG), &knee, Some(Some("waist_imu_0")));
        assert_eq!(p.held_at_zero_relevant, ["torso_roll"]);
    }

    #[test]
    fn the_logged_orientation_frame_is_found_in_the_urdf_or_refused() {
        let b = ergocub();
        let base = |frame: Option<&str>| b.plan(&[], &[], Some(frame)).base;
        assert!(base(Some("waist_imu_0")).contains("frame `waist_imu_0`"));
        // A ROS 1 style frame id, and the root link by name.
        assert!(base(Some("/waist_imu_0")).contains("frame `waist_imu_0`"));
        assert!(base(Some("root_link")).starts_with("root-link orientation"));
        assert!(base(None).starts_with("root-link orientation"));
        let e = base(Some("imu_link"));
        assert!(
            e.contains("`imu_link`") && e.contains("--base-frame"),
            "{e}"
        );
        assert!(b.plan(&[], &[], None).base.starts_with("fixed"));
        // The override wins over the log's name; a frame the URDF lacks is refused at once.
        let forced = ergocub().with_base_frame(Some("root_link".into())).unwrap();
        assert!(
            forced
                .plan(&[], &[], Some(Some("waist_imu_0")))
                .base
                .starts_with("root-link orientation")
        );
        assert!(ergocub().with_base_frame(Some("nowhere".into())).is_err());
    }
}
