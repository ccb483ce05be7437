//! The heading a car's stop holds: the approach's answers weighted by their σ, not the
//! last answer alone.
//!
//! A car's last epochs before it stands are its slowest, where the course is noisiest
//! (and a lagging receiver's speed still reads motion the car no longer has): the
//! filter follows them with the gain their σ gives, and one bad course there became
//! the heading the whole stop held. The answers of the seconds before, at speed, say
//! where the car faces as well (a braking car on a straight barely turns), each with
//! the σ it was answered with. A stop starts from their mean over the last
//! [`APPROACH_S`], weighted by `1/σ²`, unless the answers turned as the car came to
//! the stop ([`APPROACH_TURN_DEG_S`]). The stopped rows of the reports
//! (`models/reports/ghnet-temporal.md`, `car-nagoya.md`, `unmet.md`) show what it holds.

use crate::head::wrap_rad;

/// Seconds of answers the approach holds, in [`APPROACH_BUCKETS`] buckets of equal
/// length: a window, not a fading weight, because the answers of a slow turn into a
/// space carry no larger σ than a straight's (the turn term starts at
/// [`TURN_SPEED`](crate::modes::TURN_SPEED)), and a fading weight kept their pre-turn
/// headings in the mean.
pub const APPROACH_S: f32 = 5.0;

/// The turn rate (°/s, median over the window's buckets) from which a car is taken to
/// have turned into its stop (a parking manoeuvre, a corner): the mean would lag the
/// turn by about half the window, so the stop holds the last answer, as it would
/// without the approach. A braking car on a straight or a gentle curve stays under it.
pub const APPROACH_TURN_DEG_S: f32 = 6.0;

/// Buckets of the approach window.
pub const APPROACH_BUCKETS: usize = 5;

/// Seconds of motion without driving (under the release bar: a manoeuvre; glitches
/// the gate skipped do not count) since the approach's last answer after which a stop
/// whose heading has moved away from the approach ([`APPROACH_LEFT_DEG`]) holds its
/// last answer instead: the approach is from before the manoeuvre. The window itself
/// counts driving time, so that a braking car's last slow seconds (not driving at
/// 1 Hz) keep its answers from speed; counted in wall time, the shared real drive's
/// stops held headings up to 1.5° further off. Four seconds: at 1 Hz two noisy slow
/// courses before a stop are no manoeuvre (with two, a simulated u-blox car held a
/// course 126° off instead of its approach's 10°), while reversing into a space takes
/// longer.
pub const APPROACH_IDLE_S: f32 = 4.0;

/// How far (degrees) a stop's heading must have moved from its approach's mean, after
/// [`APPROACH_IDLE_S`] of manoeuvring, for the approach to be left behind. One bad
/// slow course at the end moves it less than its σ allows; a car that reversed into a
/// space turning as it went, more: on the shared real drive with 0.05 m/s of added
/// receiver noise (`models/reports/noisy-real.md`) one held its approach from before
/// the manoeuvre, 70° off with a σ of 1.5°, and then left that stand off its axis and
/// was taken for a robot.
pub const APPROACH_LEFT_DEG: f32 = 30.0;

/// Seconds of one bucket.
const BUCKET_S: f32 = APPROACH_S / APPROACH_BUCKETS as f32;

/// The approach window: per bucket of `APPROACH_S / APPROACH_BUCKETS` seconds, the
/// unit headings of its moving answers weighted by `1/σ²`, and their count:
/// `[Σw·cos ψ, Σw·sin ψ, Σw, n]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Approach {
    sums: [[f32; 4]; APPROACH_BUCKETS],
    /// The bucket answers go to now.
    newest: usize,
    /// Seconds into it.
    t: f32,
    /// Seconds of motion since the last answer ([`Approach::idle`]).
    idle: f32,
}

impl Approach {
    /// No answers.
    pub const EMPTY: Approach = Approach {
        sums: [[0.0; 4]; APPROACH_BUCKETS],
        newest: 0,
        t: 0.0,
        idle: 0.0,
    };

    /// The window's sums over all buckets, `[Σw·cos ψ, Σw·sin ψ, Σw, n]`.
    fn totals(&self) -> [f32; 4] {
        self.sums.iter().fold([0.0; 4], |t, b| {
            [t[0] + b[0], t[1] + b[1], t[2] + b[2], t[3] + b[3]]
        })
    }

    /// The mean weight of an answer in the window (0 when empty).
    fn typical_weight(&self) -> f32 {
        let [_, _, w, n] = self.totals();
        if n > 0.0 {
            w / n
        } else {
            0.0
        }
    }

    /// The weighted mean heading (radians), `None` when empty.
    fn mean(&self) -> Option<f32> {
        let [c, s, w, _] = self.totals();
        (w > 0.0 && c.hypot(s) > 0.0).then(|| s.atan2(c))
    }

    /// The median of the heading's turn (radians) from one bucket to the next, oldest
    /// to newest, over buckets with answers; 0 with fewer than two. A median, so that
    /// one bad course at the end (what the approach is for) does not read as a turn.
    fn turn_per_bucket(&self) -> f32 {
        let mut turns = [0.0f32; APPROACH_BUCKETS];
        let (mut n, mut last) = (0, None);
        for k in 1..=APPROACH_BUCKETS {
            let b = self.sums[(self.newest + k) % APPROACH_BUCKETS];
            if b[2] <= 0.0 {
                continue;
            }
            let m = b[1].atan2(b[0]);
            if let Some(l) = last {
                turns[n] = wrap_rad(m - l);
                n += 1;
            }
            last = Some(m);
        }
        if n == 0 {
            return 0.0;
        }
        let t = &mut turns[..n];
        t.sort_by(f32::total_cmp);
        if n % 2 == 1 {
            t[n / 2]
        } else {
            0.5 * (t[n / 2 - 1] + t[n / 2])
        }
    }

    /// Adds a driving epoch's answer (heading `psi`, radians, and its reported σ,
    /// degrees) after `dt`. An answer a half turn from the approach and about as sure
    /// as its answers (a misread sense put right) starts it again: the answers before
    /// it faced the other way.
    pub fn add(&mut self, psi: f32, std_deg: f32, dt: f32) {
        if !(std_deg.is_finite() && std_deg > 0.0 && psi.is_finite()) {
            return;
        }
        let wi = 1.0 / (std_deg * std_deg);
        // An answer a half turn from the approach with a σ at most twice its answers'
        // typical one is a misread sense put right; a less sure one is a glitch's, and
        // weighs what its σ says.
        if let Some(m) = self.mean() {
            let flipped = wrap_rad(psi - m).abs() > 0.5 * std::f32::consts::PI;
            if flipped && 4.0 * wi >= self.typical_weight() {
                *self = Approach::EMPTY;
            }
        }
        self.t += dt.max(0.0);
        let mut moved = 0;
        while self.t >= BUCKET_S && moved < APPROACH_BUCKETS {
            self.t -= BUCKET_S;
            self.newest = (self.newest + 1) % APPROACH_BUCKETS;
            self.sums[self.newest] = [0.0; 4];
            moved += 1;
        }
        self.t = self.t.min(BUCKET_S);
        self.idle = 0.0;
        let b = &mut self.sums[self.newest];
        *b = [
            b[0] + wi * psi.cos(),
            b[1] + wi * psi.sin(),
            b[2] + wi,
            b[3] + 1.0,
        ];
    }

    /// Counts `dt` seconds of motion that gave no answer to the approach (the car moved
    /// without driving).
    pub fn idle(&mut self, dt: f32) {
        self.idle += dt.max(0.0);
    }

    /// Whether a stop whose heading is `psi` (radians) has left the approach behind:
    /// after [`APPROACH_IDLE_S`] of motion without driving, its heading is more than
    /// [`APPROACH_LEFT_DEG`] from the approach's mean.
    pub fn left_behind(&self, psi: f32) -> bool {
        self.idle >= APPROACH_IDLE_S
            && self
                .mean()
                .is_some_and(|m| wrap_rad(psi - m).abs() > APPROACH_LEFT_DEG.to_radians())
    }

    /// Empties the approach and returns what a car's stop that begins now holds: the
    /// answers' mean (radians) and their weighted circular spread (radians,
    /// `√(−2 ln R)` of the mean resultant length `R`); `None` when there was no
    /// approach, or when the car turned as it came to the stop (its answers turned
    /// faster than [`APPROACH_TURN_DEG_S`]): then the mean lags the turn, and the last
    /// answer stays.
    pub fn take(&mut self) -> Option<(f32, f32)> {
        let a = std::mem::replace(self, Approach::EMPTY);
        let turning = a.turn_per_bucket().abs() > (APPROACH_TURN_DEG_S * BUCKET_S).to_radians();
        let [c, s, w, _] = a.totals();
        if turning || w <= 0.0 || c.hypot(s) <= 0.0 {
            return None;
        }
        let r = (c.hypot(s) / w).clamp(f32::MIN_POSITIVE, 1.0);
        Some((s.atan2(c), (-2.0 * r.ln()).max(0.0).sqrt()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An approach of answers `(heading °, σ °)` at `hz`.
    fn approached(hz: f32, answers: &[(f32, f32)]) -> Approach {
        let mut a = Approach::EMPTY;
        for &(deg, std) in answers {
            a.add(deg.to_radians(), std, 1.0 / hz);
        }
        a
    }

    /// The held heading in degrees, the approach emptied.
    fn stop(a: &mut Approach) -> Option<f32> {
        a.take().map(|(a, _)| a.to_degrees().rem_euclid(360.0))
    }

    /// A straight approach whose last answer went 50° astray (a noisy course at walking
    /// pace): the stop holds the approach's weighted mean, near the straight's heading.
    #[test]
    fn a_stop_holds_its_straight_approach_not_its_last_answer() {
        let mut answers = vec![(30.0, 2.0); 40];
        answers.push((80.0, 5.0));
        let mut a = approached(10.0, &answers);
        let held = stop(&mut a).expect("an approach");
        assert!((held - 30.0).abs() < 1.0, "held {held}");
        assert_eq!(a, Approach::EMPTY, "a stand empties it");
    }

    /// A car that drove north, then manoeuvred without driving for `idle` s and stands
    /// with its heading at `now` (degrees): whether its approach is left behind.
    fn left(idle: f32, now: f32) -> bool {
        let mut a = approached(5.0, &[(0.0, 2.0); 25]);
        for _ in 0..(idle * 5.0).round() as usize {
            a.idle(0.2);
        }
        a.left_behind(now.to_radians())
    }

    /// A stop after five seconds of reversing into a space (its heading now 60° from
    /// the approach) holds its last answer; after two seconds of slow noisy courses, or
    /// with its heading still near the approach's (a straight back-up), the approach
    /// stands; an answer puts the clock back.
    #[test]
    fn a_manoeuvre_leaves_the_approach_behind() {
        assert!(left(5.0, 60.0));
        assert!(left(5.0, -60.0));
        assert!(!left(2.0, 60.0), "two seconds are no manoeuvre");
        assert!(!left(5.0, 10.0), "near the approach's heading");
        let mut a = approached(5.0, &[(0.0, 2.0); 25]);
        (0..25).for_each(|_| a.idle(0.2));
        a.add(0.0, 2.0, 0.2);
        assert!(!a.left_behind(60f32.to_radians()), "an answer since");
    }

    /// The spread says how far the answers disagreed: none for one steady heading, about
    /// 5° for answers alternating 10° apart.
    #[test]
    fn the_spread_is_the_answers_disagreement() {
        let (_, steady) = approached(5.0, &[(30.0, 2.0); 20])
            .take()
            .expect("approach");
        assert!(steady.to_degrees() < 0.1, "{steady}");
        let zigzag: Vec<_> = (0..20)
            .map(|i| (25.0 + 10.0 * (i % 2) as f32, 2.0))
            .collect();
        let (m, spread) = approached(5.0, &zigzag).take().expect("approach");
        assert!((m.to_degrees() - 30.0).abs() < 0.1, "{m}");
        assert!((spread.to_degrees() - 5.0).abs() < 0.1, "{spread}");
    }

    /// Only the window counts: a heading driven ten seconds before the stop is out of it.
    #[test]
    fn the_approach_is_a_window() {
        let mut answers = vec![(120.0, 1.0); 100];
        answers.extend(vec![(30.0, 2.0); 60]);
        let held = stop(&mut approached(10.0, &answers)).expect("an approach");
        assert!((held - 30.0).abs() < 0.5, "held {held}");
    }

    /// A car that turned into its space at 10°/s holds its last answer (`None`: the
    /// mean would lag the turn by about 25°).
    #[test]
    fn a_turn_into_the_stop_holds_no_approach() {
        let turn: Vec<_> = (0..50).map(|i| (i as f32, 3.0)).collect();
        assert_eq!(stop(&mut approached(10.0, &turn)), None);
        let mut empty = Approach::EMPTY;
        assert_eq!(stop(&mut empty), None);
    }

    /// An answer a half turn from the approach and as sure as its answers (a misread
    /// sense put right) starts it again; an unsure one (a glitch's, σ 60°) only weighs
    /// its little.
    #[test]
    fn a_sense_put_right_restarts_the_approach() {
        let held = held_after_straight(&[(210.0, 2.0); 3]);
        assert!((held - 210.0).abs() < 0.5, "held {held}");
        let held = held_after_straight(&[(210.0, 60.0)]);
        assert!((held - 30.0).abs() < 0.5, "held {held}");
    }

    /// The held heading (degrees) after 2 s straight at 30° (10 Hz, σ 2°), then `more`.
    fn held_after_straight(more: &[(f32, f32)]) -> f32 {
        let mut answers = vec![(30.0, 2.0); 20];
        answers.extend_from_slice(more);
        stop(&mut approached(10.0, &answers)).expect("an approach")
    }
}
