//! The whole-body state's topics of an MCAP bag beyond the `JointState` one ([`McapState`]): the
//! root link's orientation (`sensor_msgs/msg/Imu`) and measured wrenches
//! (`geometry_msgs/msg/WrenchStamped`), each held from its last message onto the `JointState`
//! rows (sample and hold in the bag's order).

use std::collections::BTreeMap;

use crate::mcap_cdr::decode_imu;
use crate::mcap_cdr::decode_wrench;
use crate::{RunReport, StateLayout};

const IMU_SCHEMA: &str = "sensor_msgs/msg/Imu";
const WRENCH_SCHEMA: &str = "geometry_msgs/msg/WrenchStamped";

/// What an MCAP bag adds to the whole-body state beyond the joint positions (read only with
/// [`McapSpec::state_joints`](crate::mcap_log::McapSpec::state_joints); [`read_state`](crate::mcap_log::read_state)). Each `JointState` row takes the last message of
/// each topic read before it in the bag's order (sample and hold).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct McapState {
    /// Topic of `sensor_msgs/msg/Imu` messages whose `orientation` is the root link's in the
    /// world (see [`read_with_base`](crate::mcap_log::read_with_base)).
    pub base_orientation: Option<String>,
    /// Measured wrenches applied to the robot: `(URDF frame, topic)`, the topic's
    /// `geometry_msgs/msg/WrenchStamped` messages' `wrench.force` [N] and `wrench.torque` [N·m] in
    /// the coordinates of the URDF frame, about its origin (the message's frame must be that
    /// frame; a `header.frame_id` that is not its name is warned about). A `JointState` row before
    /// the topic's first message is an error.
    pub wrenches: Vec<(String, String)>,
}

/// Per wrench topic: its channels, the last wrench read, the messages read and the first
/// `header.frame_id` that is not the URDF frame.
#[derive(Default)]
struct WrenchTopic {
    ids: Vec<u16>,
    last: Option<[f64; 6]>,
    msgs: u64,
    other_frame: Option<String>,
}

/// The [`McapState`] topics met while reading a bag: their channels and last values.
pub(crate) struct StateTopics<'a> {
    extra: &'a McapState,
    imu_ids: Vec<u16>,
    last_base: Option<[f64; 4]>,
    imu_msgs: u64,
    imu_without: u64,
    /// The first `Imu` message's non-empty `header.frame_id`.
    imu_frame: Option<String>,
    /// `Imu` messages whose `header.frame_id` is another: (count, the first such).
    imu_other_frame: (u64, Option<String>),
    wrenches: Vec<WrenchTopic>,
}

impl<'a> StateTopics<'a> {
    pub(crate) fn new(extra: &'a McapState) -> Self {
        Self {
            extra,
            imu_ids: Vec::new(),
            last_base: None,
            imu_msgs: 0,
            imu_without: 0,
            imu_frame: None,
            imu_other_frame: (0, None),
            wrenches: extra
                .wrenches
                .iter()
                .map(|_| WrenchTopic::default())
                .collect(),
        }
    }

    /// Whether anything beyond the joint positions is read.
    pub(crate) fn any(&self) -> bool {
        self.extra.base_orientation.is_some() || !self.extra.wrenches.is_empty()
    }

    /// The frame whose orientation the base topic gives: its first message's `header.frame_id`
    /// (`None` when empty: the root link's).
    pub(crate) fn base_frame(&self) -> Option<&str> {
        self.imu_frame.as_deref()
    }

    /// Adds the orientation and the wrenches to the state's layout.
    pub(crate) fn layout(&self, l: &mut StateLayout) {
        l.base_quat = self.extra.base_orientation.is_some();
        l.wrenches = self.extra.wrenches.iter().map(|w| w.0.clone()).collect();
    }

    /// A channel record: one of the state's topics carrying another schema or encoding is an
    /// error.
    pub(crate) fn channel(
        &mut self,
        topic: &str,
        schema: &str,
        encoding: &str,
        id: u16,
    ) -> Result<(), String> {
        if Some(topic) == self.extra.base_orientation.as_deref() {
            if schema != IMU_SCHEMA || encoding != "cdr" {
                return Err(format!(
                    "base orientation topic {topic} carries `{schema}` ({encoding}), not \
                     {IMU_SCHEMA} (cdr)"
                ));
            }
            self.imu_ids.push(id);
        }
        for ((frame, t), w) in self.extra.wrenches.iter().zip(&mut self.wrenches) {
            if t == topic {
                if schema != WRENCH_SCHEMA || encoding != "cdr" {
                    return Err(format!(
                        "wrench topic {topic} (--wrench {frame}={topic}) carries `{schema}` \
                         ({encoding}), not {WRENCH_SCHEMA} (cdr)"
                    ));
                }
                w.ids.push(id);
            }
        }
        Ok(())
    }

    /// A message record: whether it was on one of the state's topics (then decoded and held).
    pub(crate) fn message(&mut self, id: u16, data: &[u8]) -> Result<bool, String> {
        let mut mine = false;
        if self.imu_ids.contains(&id) {
            mine = true;
            self.imu_msgs += 1;
            let topic = self.extra.base_orientation.as_deref().unwrap_or_default();
            let (frame, q) = decode_imu(data)
                .map_err(|e| format!("message {} on {topic}: {e}", self.imu_msgs))?;
            match &self.imu_frame {
                None if self.imu_msgs == 1 => {
                    self.imu_frame = Some(frame).filter(|f| !f.is_empty());
                }
                known if known.as_deref().unwrap_or_default() != frame => {
                    self.imu_other_frame.0 += 1;
                    self.imu_other_frame.1.get_or_insert(frame);
                }
                _ => {}
            }
            match q {
                Some(q) => {
                    self.last_base = Some(crate::run::continue_sign(&mut self.last_base, q));
                }
                None => {
                    self.imu_without += 1;
                    self.last_base = Some([f64::NAN; 4]);
                }
            }
        }
        for ((frame, topic), w) in self.extra.wrenches.iter().zip(&mut self.wrenches) {
            if !w.ids.contains(&id) {
                continue;
            }
            mine = true;
            w.msgs += 1;
            let (frame_id, v) =
                decode_wrench(data).map_err(|e| format!("message {} on {topic}: {e}", w.msgs))?;
            if !frame_id.is_empty() && frame_id != *frame && w.other_frame.is_none() {
                w.other_frame = Some(frame_id);
            }
            w.last = Some(v);
        }
        Ok(mine)
    }

    /// Appends the held orientation and wrenches to a `JointState` row (`joint_topic`'s message
    /// `msg_no`); a wrench topic with no message yet is an error (`topics`: the bag's so far).
    pub(crate) fn extend_row(
        &self,
        vals: &mut Vec<f64>,
        joint_topic: &str,
        msg_no: u64,
        topics: &BTreeMap<String, String>,
    ) -> Result<(), String> {
        if self.extra.base_orientation.is_some() {
            vals.extend(self.last_base.unwrap_or([f64::NAN; 4]));
        }
        for ((frame, topic), w) in self.extra.wrenches.iter().zip(&self.wrenches) {
            let Some(v) = w.last else {
                return Err(if w.ids.is_empty() {
                    format!(
                        "no wrench topic {topic} (--wrench {frame}={topic}) before message \
                         {msg_no} on {joint_topic}; the bag has, up to there: {}",
                        topic_list(topics)
                    )
                } else {
                    format!(
                        "no message on wrench topic {topic} (--wrench {frame}={topic}) before \
                         message {msg_no} on {joint_topic}: that joint state has no wrench"
                    )
                });
            };
            vals.extend(v);
        }
        Ok(())
    }

    /// After the read: a topic the bag lacks is an error naming it and the bag's topics.
    pub(crate) fn check_present(&self, topics: &BTreeMap<String, String>) -> Result<(), String> {
        if let Some(bt) = &self.extra.base_orientation
            && self.imu_ids.is_empty()
        {
            return Err(format!(
                "no base orientation topic {bt}; the bag has: {}",
                topic_list(topics)
            ));
        }
        for ((frame, topic), w) in self.extra.wrenches.iter().zip(&self.wrenches) {
            if w.ids.is_empty() {
                return Err(format!(
                    "no wrench topic {topic} (--wrench {frame}={topic}); the bag has: {}",
                    topic_list(topics)
                ));
            }
        }
        Ok(())
    }

    /// The report's notes and warnings of the state's topics.
    pub(crate) fn report(&self, rep: &mut RunReport) {
        if let Some(bt) = &self.extra.base_orientation {
            rep.notes.push(format!(
                "base orientation: the last sensor_msgs/msg/Imu orientation on {bt} before each \
                 message ({} messages, {} without an orientation), of frame {}",
                self.imu_msgs,
                self.imu_without,
                self.imu_frame
                    .as_deref()
                    .map_or("(none named: the root link)".to_string(), |f| format!(
                        "`{f}`"
                    ))
            ));
            if let (n @ 1.., Some(other)) = &self.imu_other_frame {
                rep.warnings.push(format!(
                    "base orientation topic {bt}: {n} messages name frame `{other}`, not the first \
                     message's `{}`; every orientation was taken as that frame's",
                    self.imu_frame.as_deref().unwrap_or_default()
                ));
            }
        }
        for ((frame, topic), w) in self.extra.wrenches.iter().zip(&self.wrenches) {
            rep.sources.insert(
                format!("wrench:{frame}"),
                format!("{topic} (wrench.force, wrench.torque)"),
            );
            rep.notes.push(format!(
                "external wrench at frame `{frame}`: the last {WRENCH_SCHEMA} on {topic} before \
                 each message ({} messages; N, N·m, frame coordinates)",
                w.msgs
            ));
            if let Some(other) = &w.other_frame {
                rep.warnings.push(format!(
                    "wrench topic {topic}: header.frame_id `{other}` is not the URDF frame \
                     `{frame}`; its force and torque were taken in `{frame}`'s coordinates"
                ));
            }
        }
    }
}

/// `topic (schema), …` or `no channels`.
fn topic_list(topics: &BTreeMap<String, String>) -> String {
    if topics.is_empty() {
        return "no channels".into();
    }
    let list: Vec<String> = topics.iter().map(|(t, s)| format!("{t} ({s})")).collect();
    list.join(", ")
}
