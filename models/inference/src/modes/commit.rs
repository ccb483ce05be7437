//! The second half of an epoch: the network's gain, reverse and σ corrections applied
//! to the step, the heading, the yaw rate and the clocks updated.

use super::release::off_axis;
use super::state::{Step, StepState};
use super::vehicle::{Platform, TURN_IN_PLACE_DEG, TURN_RUN_S, TURN_STAND_S, TURN_SURE_DEG};
use crate::head::{facing, wrap_rad, MAX_STD_DEG};

/// Logit the rule's reverse decision contributes (`+` reversing, `−` forward): the
/// network overrides the rule only when its own logit outweighs this.
pub const REVERSE_PRIOR: f32 = 4.0;

/// Time constant of the yaw rate's smoothing, s ([`StepState::yaw`]): long enough
/// that a 10 Hz receiver's course noise does not read as turning, short enough to
/// follow a junction turn (a few seconds).
pub const YAW_TAU_S: f32 = 1.0;

/// Time constant of the yaw rate a lagging receiver's course is led by, s
/// ([`StepState::turn`]): twice [`YAW_TAU_S`], since the lead multiplies its noise by
/// the lag and a course is too noisy to differentiate at the rate a turn's σ uses.
pub const LEAD_YAW_TAU_S: f32 = 2.0;

/// The gain from the Kalman gain `k` and the network's log-odds correction `y`:
/// `k·eʸ / (1 − k + k·eʸ)`; exactly 0 when `k` is 0 (a stop stays held) and `k` at `y = 0`.
#[inline]
pub fn corrected_gain(k: f32, y: f32) -> f32 {
    if k <= 0.0 {
        return 0.0;
    }
    let e = y.clamp(-30.0, 30.0).exp();
    k * e / (1.0 - k + k * e)
}

/// The innovation `d` (radians, the course as the mode faces minus the prior) a
/// standing car's heading is fed with. Under the motion bar ([`Step::moving`]) a
/// standing car's course still feeds its held heading with the small gain its σ gives,
/// and a car creeps either way: a course more than a quarter turn off the heading is
/// a creep backwards (or noise), so it pulls the heading towards its reverse, along
/// the car's axis, not a fraction of the way across the half turn. Fed as it was, a
/// car creeping backwards at 0.5 m/s turned its held heading by 25° the wrong way in
/// one 1 Hz epoch and drove off on it (simulated NMEA cars, models/reports/unmet.md).
/// Which way the car faces is the direction rules' and the network's call, on moving
/// epochs.
#[inline]
fn stand_innovation(st: &StepState, step: &Step, d: f32) -> f32 {
    if st.car_stands() && !step.moving && d.abs() > 0.5 * std::f32::consts::PI {
        wrap_rad(d + std::f32::consts::PI)
    } else {
        d
    }
}

/// The reverse logit: the rule's `±REVERSE_PRIOR` plus the network's `y`.
#[inline]
pub fn reverse_logit(rule_reverse: bool, y: f32) -> f32 {
    if rule_reverse {
        REVERSE_PRIOR + y
    } else {
        y - REVERSE_PRIOR
    }
}

/// Metres without a stand after which a history's vehicle is taken to drive forward
/// ([`StepState::sense_known`]): a back-out of a parking space is a car length or two.
pub const SENSE_RUN_M: f32 = 10.0;

/// The least σ (degrees) of an answer while the sense of travel is unknown: two σ
/// reach the half turn a back-out answered as forward is off by. A misread is a jump,
/// not a spread, so no σ describes it; this one keeps it inside 2σ (the car
/// sections' 0.5–2 m/s rows of models/reports/unmet.md: half of the simulator's car
/// drives start by backing out).
pub const SENSE_SIGMA_DEG: f32 = 90.0;

/// What [`commit`] decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// Heading, radians (not wrapped).
    pub psi: f32,
    /// The filter's `log σ` after the step (σ in radians).
    pub log_sigma: f32,
    /// Gain used (1 after a jump).
    pub gain: f32,
}

/// The second half of an epoch: the network's outputs `y` (gain, reverse, σ) applied to
/// `step`, the heading state of `st` updated. Zero outputs are the mode filter itself.
pub fn commit(st: &mut StepState, step: &Step, y: &[f32], dt: f32) -> Decision {
    let cap = MAX_STD_DEG.to_radians();
    let logit = reverse_logit(step.rule_reverse, y[1]);
    let (psi, var, gain) = if step.hold {
        (step.prior, cap * cap, 0.0)
    } else {
        let reverse = if st.vehicle.car {
            logit > 0.0
        } else {
            step.rule_reverse
        };
        let z = facing(step.course, reverse);
        let d = stand_innovation(st, step, wrap_rad(z - step.prior));
        st.t_mode = if reverse != st.reverse {
            0.0
        } else {
            st.t_mode
        };
        st.reverse = reverse;
        // Overruling the rule never averages across a half turn: the heading jumps.
        if reverse != step.rule_reverse
            && step.moving
            && !step.glitch
            && d.abs() > 0.5 * std::f32::consts::PI
        {
            (z, step.r2, 1.0)
        } else {
            let g = corrected_gain(step.k, y[0]);
            let v = (1.0 - g) * (1.0 - g) * step.p + g * g * step.r2;
            (step.prior + g * d, v, g)
        }
    };
    let log_sigma = 0.5 * var.max(1e-12).ln();
    update_yaw(st, step, psi, gain, dt);
    advance_clocks(st, step, dt);
    st.psi = wrap_rad(psi);
    st.log_sigma = log_sigma.min(cap.ln());
    st.has_prior = true;
    watch_turn_in_place(st, step);
    Decision {
        psi: psi + lead(st, step, dt),
        log_sigma: st.log_sigma,
        gain,
    }
}

/// Whether an `auto` vehicle not known to be a car turned in place
/// ([`Vehicle::turns`]): after a stand of [`TURN_STAND_S`], its departure points off
/// the axis of the heading it stood with, and keeps on for [`TURN_RUN_S`] (a glitch
/// burst does not). That heading is the last of a run of steady motion as long.
///
/// [`Vehicle::turns`]: super::vehicle::Vehicle::turns
fn watch_turn_in_place(st: &mut StepState, step: &Step) {
    if st.vehicle.car || st.vehicle.platform != Platform::Auto {
        // A car's heading is not watched: a demoted car starts afresh.
        (st.stand_psi, st.stood, st.turn_seen) = (f32::NAN, false, false);
        return;
    }
    if !step.moving || step.glitch {
        st.stood |= st.t_still >= TURN_STAND_S && st.stand_psi.is_finite();
        st.turn_seen = false;
        return;
    }
    if !st.released() {
        st.turn_seen = false;
        return;
    }
    if st.stood {
        st.turn_seen = off_axis(step.course, st.stand_psi) > TURN_IN_PLACE_DEG.to_radians();
        st.stood = false;
    }
    if st.motion.t >= TURN_RUN_S {
        st.vehicle.turns |= st.turn_seen;
        st.turn_seen = false;
        st.stand_psi = if st.log_sigma < TURN_SURE_DEG.to_radians().ln() {
            st.psi
        } else {
            f32::NAN
        };
    }
}

/// The yaw rate after a step to heading `psi` with gain `gain` (1 after a jump): the
/// heading's change since the step's prior (the rules' half turns are already in the
/// prior), smoothed; a jump across a half turn is a misread direction, not a turn,
/// and leaves it as it was; a glitch too; anything else not moving ends it.
fn update_yaw(st: &mut StepState, step: &Step, psi: f32, gain: f32, dt: f32) {
    if step.glitch || (gain >= 1.0 && step.moving) {
        return;
    }
    if !step.moving || step.hold || dt <= 0.0 {
        (st.yaw, st.turn, st.turn_var) = (0.0, 0.0, 0.0);
        return;
    }
    let rate = wrap_rad(psi - step.prior) / dt;
    st.yaw += (dt / YAW_TAU_S).min(1.0) * (rate - st.yaw);
    // Leaving a stand, the step is from a held heading to the first course: a turn in
    // place or the held heading's error, not a rate the course will keep lagging by.
    if st.moving_now() {
        let a = (dt / LEAD_YAW_TAU_S).min(1.0);
        let e = rate - st.turn;
        st.turn_var += a * (e * e - st.turn_var);
        st.turn += a * e;
    } else {
        (st.turn, st.turn_var) = (0.0, 0.0);
    }
}

/// What the answer leads the filter's heading by (radians): a receiver whose velocity
/// lags by τ reads a steady turn at rate ω as a course `atan(ωτ)` behind the heading;
/// a car's antenna `L` ahead of its rear axle (the point without sideways velocity)
/// moves at `(u, ω·L)` in body axes, so its course leads the heading by `atan(ω·L/u)`
/// forward and, reversing, trails it (turned by a half turn) by `atan(ω·L/|u|)`: the
/// answer takes that out ([`Step::lever_s`]). The filter itself follows the course
/// (its state is not led); only a moving epoch's answer is, with the slowly filtered
/// yaw rate [`StepState::turn`] shrunk by its own noise (`ω·ω²/(ω² + var)`, the
/// variance from the rates' scatter around it): where the course is too noisy to
/// differentiate (slow, poor sky, glitches), the lead fades.
#[inline]
fn lead(st: &StepState, step: &Step, dt: f32) -> f32 {
    if (step.lead_s <= 0.0 && step.lever_s <= 0.0) || step.hold || !step.moving || step.glitch {
        return 0.0;
    }
    let a = (dt / LEAD_YAW_TAU_S).min(1.0);
    let t2 = st.turn * st.turn;
    let den = t2 + st.turn_var * a / (2.0 - a);
    let w = if den > 0.0 { st.turn * t2 / den } else { 0.0 };
    (w * step.lead_s).atan() - lever(w, st.reverse, step)
}

/// The lead (radians) a car's antenna course has over its heading at yaw rate `w`
/// ([`lead`]): `atan(w·lever_s)`, the product capped at [`Step::lever_max`] and
/// falling to 0 at twice it (no car turns that tight: not a car's turn).
#[inline]
fn lever(w: f32, reverse: bool, step: &Step) -> f32 {
    let m = step.lever_max;
    if step.lever_s <= 0.0 || m <= 0.0 {
        return 0.0;
    }
    let x = w * step.lever_s;
    let kept = if x.abs() <= m {
        x.abs()
    } else {
        (2.0 * m - x.abs()).max(0.0)
    };
    let lead = kept.copysign(x).atan();
    if reverse {
        -lead
    } else {
        lead
    }
}

fn advance_clocks(st: &mut StepState, step: &Step, dt: f32) {
    // A glitch changes nothing: a standing vehicle stays standing through one, a moving
    // one moving (at speed, the gate's `max_skips` rule applies, not a stand's).
    let moved = step.moving && !step.glitch;
    st.t_still = if (step.glitch && st.moving_now()) || moved {
        0.0
    } else {
        st.t_still + dt
    };
    if moved {
        st.run_m += step.speed * dt;
        st.sense_known |= st.run_m >= SENSE_RUN_M;
        st.sense_doubt &= st.run_m < SENSE_RUN_M;
    } else if !st.moving_now() {
        st.run_m = 0.0;
    }
    if moved && !step.hold {
        st.t_mode += dt;
    }
    if !step.glitch {
        st.prev_speed = step.speed;
    }
    // Every used epoch is the gate's reference, a standing car's noise included: it
    // leaves rest from rest, not from the speed it stopped at.
    if !step.glitch || !st.prev_v[0].is_finite() {
        let (s, c) = step.course.sin_cos();
        st.prev_v = [step.speed * c, step.speed * s];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step of a car at 1 m/s whose lever arm reads `lever_s` = 1.25 s, `k_max·L`
    /// = 0.25.
    fn car_step() -> Step {
        Step {
            k: 0.5,
            moving: true,
            hold: false,
            sigma_v: 0.1,
            lever_s: 1.25,
            lever_max: 0.25,
            ..Step::holding(0.0, 0.0, 0.0, 1.0, 0.1)
        }
    }

    /// The lever's lead is `atan(ω·lever_s)`, the opposite reversing; a car turns no
    /// tighter than it steers, so the product is capped at `k_max·L` and fades to 0
    /// at twice it (a yaw rate no car reaches at that speed is not a car's turn).
    #[test]
    fn the_lever_is_capped_at_a_cars_tightest_turn() {
        let step = car_step();
        let w = 0.1;
        assert!((lever(w, false, &step) - 0.125f32.atan()).abs() < 1e-6);
        assert!((lever(w, true, &step) + 0.125f32.atan()).abs() < 1e-6);
        assert!((lever(-0.2, false, &step) - (-0.25f32).atan()).abs() < 1e-6);
        assert!((lever(0.3, false, &step) - 0.125f32.atan()).abs() < 1e-6);
        assert_eq!(lever(0.5, false, &step), 0.0);
        let platform = Step {
            lever_s: 0.0,
            lever_max: 0.0,
            ..step
        };
        assert_eq!(lever(w, false, &platform), 0.0);
    }
}
