//! How long a stop outlives the motion: the longest run of `Held` answers while the
//! receiver reads [`HELD_MOVING_SPEED`] or faster, a column of every streamed table.

use ghnet_inference::Status;

use crate::logs::LogTrack;

/// Measured speed (m/s) from which a `Held` answer counts in a row's `held_moving_s`.
pub const HELD_MOVING_SPEED: f32 = 1.0;

/// The longest run (s) of `held` epochs at [`HELD_MOVING_SPEED`] or faster in `t`, each
/// epoch lasting until the next (the last as long as the one before it), at most the
/// track's usual interval: a fix gap after a held epoch is not time held.
fn longest_held_moving(t: &LogTrack, held: impl Fn(usize) -> bool) -> f64 {
    let usual = usual_interval(&t.t_s);
    let (mut run, mut longest) = (0.0f64, 0.0f64);
    for i in 0..t.len() {
        let fast = t.v_north[i].hypot(t.v_east[i]) >= HELD_MOVING_SPEED;
        run = if held(i) && fast {
            let dt = match (t.t_s.get(i + 1), i.checked_sub(1)) {
                (Some(next), _) => next - t.t_s[i],
                (None, Some(prev)) => t.t_s[i] - t.t_s[prev],
                (None, None) => 0.0,
            };
            run + dt.min(usual)
        } else {
            0.0
        };
        longest = longest.max(run);
    }
    longest
}

/// The median interval (s) between successive epochs of a track, at most 1 s (1 s
/// for a track of one epoch): its receiver's rate, whatever its fix gaps.
fn usual_interval(t_s: &[f64]) -> f64 {
    let mut dts: Vec<f64> = t_s.windows(2).map(|w| w[1] - w[0]).collect();
    if dts.is_empty() {
        return 1.0;
    }
    let mid = dts.len() / 2;
    let (_, median, _) = dts.select_nth_unstable_by(mid, f64::total_cmp);
    median.clamp(0.0, 1.0)
}

/// The longest run (s) of `Held` answers (`status`, per epoch of `tracks`
/// concatenated) among the epochs `idx` at [`HELD_MOVING_SPEED`] or faster; `None`
/// without status.
pub(super) fn held_moving(tracks: &[LogTrack], status: &[Status], idx: &[usize]) -> Option<f64> {
    let n: usize = tracks.iter().map(LogTrack::len).sum();
    if status.len() != n {
        return None;
    }
    let mut held = vec![false; n];
    for &i in idx {
        held[i] = status[i] == Status::Held;
    }
    let (mut start, mut longest) = (0, 0.0f64);
    for t in tracks {
        let s0 = start;
        longest = longest.max(longest_held_moving(t, |i| held[s0 + i]));
        start += t.len();
    }
    Some(longest)
}
