//! ROS names: the topic of a source, the rule that maps ghnet source names onto ROS
//! names, frame ids, domain ids.
//!
//! ghnet source names are `A-Z a-z 0-9 _ -`, starting with a letter or digit. A ROS
//! name token is `A-Z a-z 0-9 _`, must not start with a digit and must not contain
//! `__`. The mapping ([`ros_token`]):
//!
//! 1. every `-` becomes `_`;
//! 2. runs of `_` become one `_`;
//! 3. a name that then starts with a digit gets `s_` in front.
//!
//! So `gnss-front` → `gnss_front`, `2nd--rx` → `s_2nd_rx`, `gnss0` stays `gnss0`.
//! Two sources that map to one token would share a topic: [`TopicMap`] refuses that.

use std::collections::BTreeMap;

use thiserror::Error;

/// The ROS node name of the bridge.
pub const NODE_NAME: &str = "ghnet";

/// Highest ROS domain id: DDS derives ports from it, and 232 is the last whose ports
/// fit (ROS 2 documents 0–232; 0–101 avoids ephemeral ports on Linux).
pub const MAX_DOMAIN_ID: u32 = 232;

/// A name the bridge cannot use.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum RosNameError {
    /// Domain id outside `0..=232`.
    #[error("domain id {0} is out of range (0 to {MAX_DOMAIN_ID})")]
    DomainId(u32),
    /// A frame id that tf2 and ROS tools cannot use.
    #[error("frame id `{0}` is not a valid ROS name: tokens of letters, digits and single underscores separated by '/', none starting with a digit, no leading or trailing '/'")]
    FrameId(String),
    /// Two sources whose topics would be the same.
    #[error("sources `{0}` and `{1}` both map to the ROS topic {2}; rename one")]
    Collision(String, String, String),
}

/// The ROS name token for a ghnet source name (rule in the module doc).
pub fn ros_token(source: &str) -> String {
    let mut out = String::with_capacity(source.len() + 2);
    for c in source.chars() {
        let c = if c == '-' { '_' } else { c };
        if !(c == '_' && out.ends_with('_')) {
            out.push(c);
        }
    }
    if out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert_str(0, "s_");
    }
    out
}

/// `/ghnet/<token>/heading`: the topic of a source's headings.
pub fn heading_topic(source: &str) -> String {
    format!("/{NODE_NAME}/{}/heading", ros_token(source))
}

/// Checks a domain id (0–232).
pub fn check_domain_id(id: u32) -> Result<u16, RosNameError> {
    if id > MAX_DOMAIN_ID {
        return Err(RosNameError::DomainId(id));
    }
    Ok(id as u16)
}

/// Checks a frame id: one or more ROS tokens separated by `/` (`gnss`,
/// `base_link`, `robot1/gnss`). tf2 refuses a leading `/`.
pub fn check_frame_id(frame: &str) -> Result<(), RosNameError> {
    let token_ok = |t: &str| {
        t.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
            && t.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            && !t.contains("__")
    };
    if frame.is_empty() || !frame.split('/').all(token_ok) {
        return Err(RosNameError::FrameId(frame.to_owned()));
    }
    Ok(())
}

/// Which source has which topic; refuses a second source on a taken topic.
#[derive(Debug, Default)]
pub struct TopicMap {
    by_topic: BTreeMap<String, String>,
}

impl TopicMap {
    /// Adds `source`; its topic, or [`RosNameError::Collision`] naming both sources.
    pub fn insert(&mut self, source: &str) -> Result<String, RosNameError> {
        let topic = heading_topic(source);
        match self.by_topic.get(&topic) {
            Some(other) if other != source => Err(RosNameError::Collision(
                other.clone(),
                source.to_owned(),
                topic,
            )),
            _ => {
                self.by_topic.insert(topic.clone(), source.to_owned());
                Ok(topic)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_names_map_by_the_documented_rule() {
        assert_eq!(heading_topic("gnss0"), "/ghnet/gnss0/heading");
        assert_eq!(ros_token("gnss-front"), "gnss_front");
        assert_eq!(ros_token("2nd--rx"), "s_2nd_rx");
        assert_eq!(ros_token("a__b"), "a_b");
        assert_eq!(ros_token("0"), "s_0");
        assert_eq!(ros_token("rx-"), "rx_");
    }

    #[test]
    fn every_valid_source_name_gives_a_valid_ros_name() {
        let alphabet = ['a', 'Z', '0', '9', '_', '-'];
        for a in alphabet {
            for b in alphabet {
                for c in alphabet {
                    let source: String = [a, b, c].iter().collect();
                    if ghnet_client::validate_source_name(&source).is_err() {
                        continue;
                    }
                    let topic = heading_topic(&source);
                    let base = topic.trim_start_matches('/');
                    assert!(check_frame_id(base).is_ok(), "{source} → {topic}");
                }
            }
        }
    }

    #[test]
    fn colliding_sources_are_refused() {
        let mut map = TopicMap::default();
        map.insert("gnss-a").unwrap();
        map.insert("gnss-a").unwrap();
        let err = map.insert("gnss_a").unwrap_err();
        assert_eq!(
            err.to_string(),
            "sources `gnss-a` and `gnss_a` both map to the ROS topic /ghnet/gnss_a/heading; rename one"
        );
    }

    #[test]
    fn frame_ids_and_domain_ids_are_checked() {
        for ok in ["gnss", "base_link", "robot1/gnss_antenna", "_x"] {
            assert!(check_frame_id(ok).is_ok(), "{ok}");
        }
        for bad in [
            "", "/gnss", "gnss/", "1gnss", "a b", "gn-ss", "a__b", "a//b",
        ] {
            assert!(check_frame_id(bad).is_err(), "{bad}");
        }
        assert_eq!(check_domain_id(232), Ok(232));
        assert_eq!(check_domain_id(233), Err(RosNameError::DomainId(233)));
    }
}
