//! [`DdsOutput`]: the bridge as a ROS 2 node on DDS, through `ros2-client` (RustDDS
//! underneath: pure Rust, no ROS installation). Interoperates with `rmw_fastrtps_cpp`
//! and `rmw_cyclonedds_cpp` nodes of the same domain.
//!
//! QoS of both topics: reliable, volatile, keep last 10 (ROS 2's default profile for
//! sensor topics that must not lose messages to a healthy subscriber). A reliable
//! writer whose window of 10 unacknowledged messages is full refuses the write at once
//! (`WhenFull::Fail`) instead of waiting: the message is counted as a send failure.

use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    QosProfile,
};
use serde::Serialize;

use crate::msg::{DiagnosticArray, Imu, RosMessage};
use crate::names::NODE_NAME;
use crate::output::{Output, OutputError, TopicId};

/// How many messages each topic keeps for late repair (keep-last depth).
pub const HISTORY_DEPTH: usize = 10;

/// The bridge's DDS participant, node and publishers.
pub struct DdsOutput {
    // Publishers before the node and context: drop order.
    headings: Vec<(String, Publisher<Imu>)>,
    diagnostics: Publisher<DiagnosticArray>,
    node: Node,
    _context: Context,
}

/// The QoS of every topic of the bridge.
pub fn qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Fail)
        .durability(Durability::Volatile)
        .history(History::KeepLast {
            depth: HISTORY_DEPTH,
        })
}

fn create_err(what: &str) -> impl FnOnce(String) -> OutputError + '_ {
    move |reason| OutputError::Create {
        what: what.to_owned(),
        reason,
    }
}

impl DdsOutput {
    /// Joins `domain_id` as node `/ghnet` with a `/diagnostics` publisher.
    pub fn new(domain_id: u16) -> Result<Self, OutputError> {
        let context = Context::with_options(ContextOptions::new().domain_id(domain_id))
            .map_err(|e| create_err("a DDS participant")(format!("{e:?}")))?;
        let name = NodeName::new("/", NODE_NAME).map_err(|e| create_err("node")(e.to_string()))?;
        let mut node = context
            .new_node(name, NodeOptions::new().enable_rosout(false))
            .map_err(|e| create_err("node /ghnet")(format!("{e:?}")))?;
        let diagnostics = publisher::<DiagnosticArray>(&mut node, "/diagnostics")?;
        Ok(DdsOutput {
            headings: Vec::new(),
            diagnostics,
            node,
            _context: context,
        })
    }
}

/// A publisher of `M` on the absolute ROS topic `topic`.
fn publisher<M: RosMessage>(node: &mut Node, topic: &str) -> Result<Publisher<M>, OutputError> {
    let what = format!("topic {topic}");
    let (namespace, base) = topic.rsplit_once('/').unwrap_or(("", topic));
    let namespace = if namespace.is_empty() { "/" } else { namespace };
    let name = Name::new(namespace, base).map_err(|e| create_err(&what)(e.to_string()))?;
    let type_name = MessageTypeName::new(M::PACKAGE, M::NAME);
    let t = node
        .create_topic(&name, type_name, &qos())
        .map_err(|e| create_err(&what)(format!("{e:?}")))?;
    node.create_publisher::<M>(&t, None)
        .map_err(|e| create_err(&what)(format!("{e:?}")))
}

fn send<M: Serialize>(p: &Publisher<M>, topic: &str, m: M) -> Result<(), OutputError> {
    p.publish(m).map_err(|e| OutputError::Send {
        topic: topic.to_owned(),
        reason: e.to_string(),
    })
}

impl Output for DdsOutput {
    fn add_heading_topic(&mut self, topic: &str) -> Result<TopicId, OutputError> {
        let p = publisher::<Imu>(&mut self.node, topic)?;
        self.headings.push((topic.to_owned(), p));
        Ok(TopicId(self.headings.len() - 1))
    }

    fn publish_imu(&mut self, topic: TopicId, imu: Imu) -> Result<(), OutputError> {
        let (name, p) = &self.headings[topic.0];
        send(p, name, imu)
    }

    fn publish_diagnostics(&mut self, diagnostics: DiagnosticArray) -> Result<(), OutputError> {
        send(&self.diagnostics, "/diagnostics", diagnostics)
    }
}
