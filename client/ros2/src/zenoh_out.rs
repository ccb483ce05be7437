//! [`ZenohOutput`]: the bridge as an `rmw_zenoh_cpp` node would appear on Zenoh, so
//! ROS 2 nodes running `RMW_IMPLEMENTATION=rmw_zenoh_cpp` (which all meet at a Zenoh
//! router, `tcp/localhost:7447` by default) see node `/ghnet` and its topics.
//!
//! rmw_zenoh's wire, as this module writes it:
//!
//! - data key: `<domain>/<topic without its leading '/'>/<DDS type name>/<type
//!   hash>`, e.g. `0/ghnet/gnss0/heading/sensor_msgs::msg::dds_::Imu_/RIHS01_7d9a…`;
//! - payload: the CDR encapsulation header `00 01 00 00` (little-endian plain CDR),
//!   then the CDR body ([`cdr_payload`]);
//! - attachment, 33 bytes ([`attachment`]): sequence number (`i64` LE, from 1 per
//!   publisher), publish time (`i64` LE, ns since the Unix epoch, the system clock as
//!   rmw_zenoh_cpp reads it), the length of the publisher id as one byte (16) and
//!   the 16-byte publisher id — zenoh-ext's serialisation of `(i64, i64, [u8; 16])`,
//!   written here directly (33 fixed bytes do not warrant zenoh-ext and its
//!   dependencies);
//! - liveliness tokens under `@ros2_lv/<domain>/<session id>/…`: one for the node
//!   (`…/0/0/NN/%/%/ghnet`) and one per publisher (`…/0/<id>/MP/%/%/ghnet/<topic with
//!   '/' as '%'>/<type>/<hash>/<QoS>`), which is how ROS 2 tools discover them.
//!
//! Type hashes are pinned ([`IMU_TYPE_HASH`], [`DIAGNOSTIC_ARRAY_TYPE_HASH`]) and
//! tested against an independent computation (the `rosbags` Python package).
//!
//! The session is a Zenoh client of the router (listens nowhere, no scouting): a
//! router that is down is retried every second on a thread of its own, a router that
//! restarts is reconnected by Zenoh. Publishers drop rather than block under
//! congestion. While no router is connected, messages are send failures (nobody can
//! get them).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use byteorder::LittleEndian;
use ghnet_client::zenoh::liveliness::LivelinessToken;
use ghnet_client::zenoh::pubsub::Publisher;
use ghnet_client::zenoh::qos::CongestionControl;
use ghnet_client::zenoh::{self, Session, Wait};
use serde::Serialize;

use crate::msg::{DiagnosticArray, Imu, RosMessage};
use crate::names::NODE_NAME;
use crate::output::{Output, OutputError, TopicId};

/// RIHS01 type hash of `sensor_msgs/msg/Imu` (Jazzy and later).
pub const IMU_TYPE_HASH: &str =
    "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b";

/// RIHS01 type hash of `diagnostic_msgs/msg/DiagnosticArray`.
pub const DIAGNOSTIC_ARRAY_TYPE_HASH: &str =
    "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e";

/// The CDR encapsulation header of little-endian plain CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// rmw_zenoh's QoS string of reliable, volatile, keep-last 10 (every field equal to
/// ROS's default profile is left empty; the depth is always written).
pub const QOS: &str = "::,10:,:,:,,";

/// The type hash of a message type the bridge sends.
pub trait TypeHash: RosMessage {
    /// `RIHS01_<sha256 hex>`.
    const TYPE_HASH: &'static str;
}

impl TypeHash for Imu {
    const TYPE_HASH: &'static str = IMU_TYPE_HASH;
}

impl TypeHash for DiagnosticArray {
    const TYPE_HASH: &'static str = DIAGNOSTIC_ARRAY_TYPE_HASH;
}

/// The DDS-style type name rmw_zenoh puts in keys: `sensor_msgs::msg::dds_::Imu_`.
pub fn dds_type_name<M: RosMessage>() -> String {
    format!("{}::msg::dds_::{}_", M::PACKAGE, M::NAME)
}

/// The data key of `topic` (absolute ROS name) in `domain`.
pub fn data_key<M: TypeHash>(domain: u16, topic: &str) -> String {
    let name = topic.trim_start_matches('/');
    format!("{domain}/{name}/{}/{}", dds_type_name::<M>(), M::TYPE_HASH)
}

/// The liveliness token of the bridge's node.
pub fn node_token_key(domain: u16, session: &str) -> String {
    format!("@ros2_lv/{domain}/{session}/0/0/NN/%/%/{NODE_NAME}")
}

/// The liveliness token of publisher `entity` on `topic`.
pub fn publisher_token_key<M: TypeHash>(
    domain: u16,
    session: &str,
    entity: u64,
    topic: &str,
) -> String {
    let mangled = topic.replace('/', "%");
    let ty = dds_type_name::<M>();
    let hash = M::TYPE_HASH;
    format!("@ros2_lv/{domain}/{session}/0/{entity}/MP/%/%/{NODE_NAME}/{mangled}/{ty}/{hash}/{QOS}")
}

/// The payload of `m`: encapsulation header and little-endian CDR.
pub fn cdr_payload<M: Serialize>(m: &M) -> Result<Vec<u8>, cdr_encoding::Error> {
    let body = cdr_encoding::to_vec::<M, LittleEndian>(m)?;
    let mut out = Vec::with_capacity(CDR_LE_HEADER.len() + body.len());
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    Ok(out)
}

/// The 33-byte attachment of a message: `seq`, publish time in ns, publisher id.
pub fn attachment(seq: i64, time_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut a = [0u8; 33];
    a[..8].copy_from_slice(&seq.to_le_bytes());
    a[8..16].copy_from_slice(&time_ns.to_le_bytes());
    a[16] = 16;
    a[17..].copy_from_slice(gid);
    a
}

/// How long the opener waits between attempts to reach the router.
const RETRY: Duration = Duration::from_secs(1);

/// One publisher: its key, token, id and sequence number.
struct Pub {
    topic: String,
    publisher: Publisher<'static>,
    _token: LivelinessToken,
    gid: [u8; 16],
    seq: i64,
}

/// A session and everything declared on it.
struct Live {
    // Publishers and tokens before the session: drop order.
    headings: Vec<Pub>,
    diagnostics: Pub,
    _node: LivelinessToken,
    session_id: String,
    zid: [u8; 16],
    session: Session,
    /// Whether a router was connected at the last look (each `/diagnostics`).
    connected: bool,
}

/// The bridge on Zenoh: a session to the router once one is reached (opened on a
/// thread of its own, so a router that is down never stalls the bridge), its
/// liveliness tokens and publishers.
pub struct ZenohOutput {
    domain: u16,
    /// Heading topics asked for, in [`TopicId`] order (declared when live).
    topics: Vec<String>,
    live: Option<Live>,
    opened: mpsc::Receiver<Session>,
    stop_opening: Arc<AtomicBool>,
}

fn create_err(what: &str) -> impl FnOnce(zenoh::Error) -> OutputError + '_ {
    move |e| OutputError::Create {
        what: what.to_owned(),
        reason: e.to_string(),
    }
}

/// The session's config: a Zenoh client of `router` (a router routes to its clients;
/// a peer with gossip off, attached only to a router, is not routed to), no
/// scouting, listening nowhere, reconnecting quickly when the router restarts.
fn client_config(router: &str) -> Result<zenoh::Config, OutputError> {
    let mut c = ghnet_client::peer_config(&[], &[router.to_owned()])
        .map_err(create_err("a Zenoh config"))?;
    c.insert_json5("mode", "\"client\"")
        .and_then(|_| {
            c.insert_json5(
                "connect/retry",
                "{period_init_ms: 100, period_max_ms: 1000}",
            )
        })
        .map_err(create_err("a Zenoh config"))?;
    Ok(c)
}

/// Tries to open a session every [`RETRY`] until one opens or `stop`; sends it.
fn open_until_reached(
    cfg: zenoh::Config,
    router: String,
    tx: mpsc::Sender<Session>,
    stop: Arc<AtomicBool>,
) {
    let mut logged = false;
    while !stop.load(Ordering::Relaxed) {
        match zenoh::open(cfg.clone()).wait() {
            Ok(s) => {
                let _ = tx.send(s);
                return;
            }
            Err(e) if !logged => {
                tracing::warn!(%router, "no Zenoh router connected yet ({e}); retrying every second");
                logged = true;
            }
            Err(_) => {}
        }
        std::thread::sleep(RETRY);
    }
}

impl ZenohOutput {
    /// Starts reaching `router` in the background and returns at once.
    pub fn new(domain: u16, router: &str) -> Result<Self, OutputError> {
        let cfg = client_config(router)?;
        let (tx, opened) = mpsc::channel();
        let stop_opening = Arc::new(AtomicBool::new(false));
        let (stop, router) = (stop_opening.clone(), router.to_owned());
        std::thread::Builder::new()
            .name("zenoh-open".into())
            .spawn(move || open_until_reached(cfg, router, tx, stop))
            .map_err(|e| OutputError::Create {
                what: "the Zenoh opener thread".into(),
                reason: e.to_string(),
            })?;
        Ok(ZenohOutput {
            domain,
            topics: Vec::new(),
            live: None,
            opened,
            stop_opening,
        })
    }

    /// Declares the node, `/diagnostics` and every heading topic on a new session.
    fn go_live(&mut self, session: Session) -> Result<(), OutputError> {
        let session_id = session.zid().to_string();
        let zid = session.zid().to_le_bytes();
        let node = session
            .liveliness()
            .declare_token(node_token_key(self.domain, &session_id))
            .wait()
            .map_err(create_err("the node's liveliness token"))?;
        let mut live = Live {
            headings: Vec::with_capacity(self.topics.len()),
            diagnostics: declare::<DiagnosticArray>(
                &session,
                self.domain,
                &session_id,
                zid,
                "/diagnostics",
                1,
            )?,
            _node: node,
            session_id,
            zid,
            session,
            connected: true,
        };
        for topic in &self.topics {
            live.add::<Imu>(self.domain, topic)?;
        }
        tracing::info!(session = %live.session_id, "Zenoh router reached");
        self.live = Some(live);
        Ok(())
    }
}

impl Drop for ZenohOutput {
    fn drop(&mut self) {
        self.stop_opening.store(true, Ordering::Relaxed);
    }
}

/// Declares a publisher of `M` on `topic` with its liveliness token.
fn declare<M: TypeHash>(
    session: &Session,
    domain: u16,
    session_id: &str,
    zid: [u8; 16],
    topic: &str,
    entity: u64,
) -> Result<Pub, OutputError> {
    let what = format!("publisher {topic}");
    let publisher = session
        .declare_publisher(data_key::<M>(domain, topic))
        .congestion_control(CongestionControl::Drop)
        .wait()
        .map_err(create_err(&what))?;
    let token_key = publisher_token_key::<M>(domain, session_id, entity, topic);
    let token = session
        .liveliness()
        .declare_token(token_key)
        .wait()
        .map_err(create_err(&what))?;
    // Unique per publisher of this session: the session id with the entity id in
    // its last eight bytes.
    let mut gid = zid;
    gid[8..].copy_from_slice(&entity.to_le_bytes());
    Ok(Pub {
        topic: topic.to_owned(),
        publisher,
        _token: token,
        gid,
        seq: 0,
    })
}

impl Live {
    /// Declares the next heading publisher (entity ids: 1 is `/diagnostics`,
    /// headings from 2, in topic order).
    fn add<M: TypeHash>(&mut self, domain: u16, topic: &str) -> Result<(), OutputError> {
        let entity = self.headings.len() as u64 + 2;
        let p = declare::<M>(
            &self.session,
            domain,
            &self.session_id,
            self.zid,
            topic,
            entity,
        )?;
        self.headings.push(p);
        Ok(())
    }

    /// Looks whether a router is connected; logs changes.
    fn check_router(&mut self) {
        let up = self.session.info().routers_zid().wait().next().is_some();
        if up != self.connected {
            if up {
                tracing::info!("Zenoh router reached again");
            } else {
                tracing::warn!("Zenoh router lost: messages are lost until it is back");
            }
            self.connected = up;
        }
    }
}

impl Pub {
    /// Puts `m`; a send failure if Zenoh refuses it or no router is `connected`
    /// (then nobody gets it).
    fn put<M: Serialize>(&mut self, m: &M, connected: bool) -> Result<(), OutputError> {
        let err = |reason: String| OutputError::Send {
            topic: self.topic.clone(),
            reason,
        };
        let payload = cdr_payload(m).map_err(|e| err(e.to_string()))?;
        self.seq += 1;
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i64);
        let att = attachment(self.seq, now, &self.gid);
        self.publisher
            .put(payload)
            .attachment(att.to_vec())
            .wait()
            .map_err(|e| err(e.to_string()))?;
        if !connected {
            return Err(err("no Zenoh router connected".to_owned()));
        }
        Ok(())
    }
}

fn not_live(topic: &str) -> OutputError {
    OutputError::Send {
        topic: topic.to_owned(),
        reason: "no Zenoh router reached yet".to_owned(),
    }
}

impl Output for ZenohOutput {
    fn add_heading_topic(&mut self, topic: &str) -> Result<TopicId, OutputError> {
        if let Some(live) = &mut self.live {
            live.add::<Imu>(self.domain, topic)?;
        }
        self.topics.push(topic.to_owned());
        Ok(TopicId(self.topics.len() - 1))
    }

    fn publish_imu(&mut self, topic: TopicId, imu: Imu) -> Result<(), OutputError> {
        match &mut self.live {
            Some(live) => live.headings[topic.0].put(&imu, live.connected),
            None => Err(not_live(&self.topics[topic.0])),
        }
    }

    /// Also the once-a-second housekeeping: takes a session the opener made, looks
    /// at the router.
    fn publish_diagnostics(&mut self, diagnostics: DiagnosticArray) -> Result<(), OutputError> {
        if self.live.is_none() {
            if let Ok(session) = self.opened.try_recv() {
                if let Err(e) = self.go_live(session) {
                    tracing::error!("Zenoh output not started: {e}");
                    return Err(e);
                }
            }
        }
        match &mut self.live {
            Some(live) => {
                live.check_router();
                live.diagnostics.put(&diagnostics, live.connected)
            }
            None => Err(not_live("/diagnostics")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_follow_rmw_zenoh() {
        assert_eq!(
            data_key::<Imu>(0, "/ghnet/gnss0/heading"),
            format!("0/ghnet/gnss0/heading/sensor_msgs::msg::dds_::Imu_/{IMU_TYPE_HASH}")
        );
        assert_eq!(
            node_token_key(3, "aac3178e146ba6f1fc6e6a4085e77f21"),
            "@ros2_lv/3/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/ghnet"
        );
        assert_eq!(
            publisher_token_key::<DiagnosticArray>(3, "ab", 1, "/diagnostics"),
            format!("@ros2_lv/3/ab/0/1/MP/%/%/ghnet/%diagnostics/diagnostic_msgs::msg::dds_::DiagnosticArray_/{DIAGNOSTIC_ARRAY_TYPE_HASH}/::,10:,:,:,,")
        );
    }

    #[test]
    fn attachment_is_seq_time_and_length_prefixed_id() {
        let gid = [0xAB; 16];
        let a = attachment(1, 0x0102_0304_0506_0708, &gid);
        assert_eq!(a[..8], [1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(a[8..16], [8, 7, 6, 5, 4, 3, 2, 1]);
        assert_eq!(a[16], 16);
        assert_eq!(a[17..], gid);
    }

    #[test]
    fn payload_starts_with_the_cdr_le_header() {
        let t = crate::msg::Time { sec: 1, nanosec: 2 };
        assert_eq!(
            cdr_payload(&t).unwrap(),
            [0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]
        );
    }
}
