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
    /// Names in the log that are not movable joints of the URDF (not used).
    pub not_in_urdf: Vec<String>,
    /// The base: fixed at the identity pose, or its orientation from the log (the root link's, or
    /// a named frame's placed on it through the URDF).
    pub base: String,
    /// Frames with a measured external wrench from the log.
    pub wrenches: Vec<String>,
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
        for name in self.robot.joint_names() {
            if let Some(&v) = self.held.get(name) {
                p.held.insert(name.to_string(), v);
            } else if log_names.iter().chain(labelled).any(|n| n == name) {
                p.from_log.push(name.to_string());
            } else {
                p.held_at_zero.push(name.to_string());
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
