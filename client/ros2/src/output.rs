//! Where the ROS messages go: [`Output`], implemented by [`crate::dds::DdsOutput`]
//! (RTPS, as `rmw_fastrtps_cpp` and `rmw_cyclonedds_cpp` speak it) and
//! [`crate::zenoh_out::ZenohOutput`] (rmw_zenoh's key expressions, payload and
//! attachment).
//!
//! Both are non-blocking on purpose: a ROS subscriber that never reads, or a Zenoh
//! router that is down, costs a refused send ([`OutputError::Send`], counted per
//! source), never a stalled bridge.

use thiserror::Error;

use crate::msg::{DiagnosticArray, Imu};

/// A failure of the ROS side.
#[derive(Debug, Error)]
pub enum OutputError {
    /// The middleware refused to make a node, topic or publisher.
    #[error("cannot create {what}: {reason}")]
    Create {
        /// What was being made (`topic /ghnet/x/heading`, ...).
        what: String,
        /// The middleware's message.
        reason: String,
    },
    /// A message was not sent (window full, session closed, ...).
    #[error("not sent on {topic}: {reason}")]
    Send {
        /// The topic.
        topic: String,
        /// The middleware's message.
        reason: String,
    },
}

/// Handle of a heading topic made by [`Output::add_heading_topic`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicId(pub usize);

/// A ROS 2 publisher of the bridge's two message types.
pub trait Output {
    /// Declares a `sensor_msgs/msg/Imu` publisher on `topic` (e.g.
    /// `/ghnet/gnss0/heading`).
    fn add_heading_topic(&mut self, topic: &str) -> Result<TopicId, OutputError>;
    /// Publishes one Imu on a topic made by [`add_heading_topic`](Self::add_heading_topic).
    fn publish_imu(&mut self, topic: TopicId, imu: Imu) -> Result<(), OutputError>;
    /// Publishes on `/diagnostics`.
    fn publish_diagnostics(&mut self, diagnostics: DiagnosticArray) -> Result<(), OutputError>;
}
