//! The first half of an epoch: time, noise, the glitch gate and the direction rules,
//! ending in the step the network corrects.

use super::noise::{
    at_shown_noise, cap2, driving_variance, gain_r, gate_sigma, measured, measurement,
    update_noise, walk_variance,
};
use super::params::ModeParams;
use super::release::{glitch, keep_or_restore_held, track_motion, RELEASE_SPEED};
use super::scatter::update_scatter;
use super::smooth::update_smooth;
use super::start::started;
use super::state::{Step, StepState};
use super::vehicle::{Platform, Vehicle, FAST_EPOCHS, SURE_CAR_SPEED};
use crate::head::{facing, wrap_rad, MAX_STD_DEG};

/// The first half of an epoch: time, noise, the rules; mutates the non-heading parts of
/// `st` and returns the step the network corrects. `kf_sigma_v` is the tuned `kf`'s σ_v
/// (the start convention); `acc` is sAcc or NaN.
pub fn prepare(
    mp: &ModeParams,
    kf_sigma_v: f32,
    st: &mut StepState,
    vn: f32,
    ve: f32,
    acc: f32,
    dt: f32,
) -> Step {
    let speed = vn.hypot(ve);
    let course = ve.atan2(vn);
    observe_receiver(mp, &mut st.vehicle, [vn, ve], speed, acc, dt);
    let trusted = mp.trusted_acc(&st.vehicle, acc); // whether it moves; σ keeps `acc`
    let run = track_motion(mp, st, vn, ve, trusted, dt);
    keep_or_restore_held(mp, st, run);
    let cap2 = cap2();
    let prior = prior(st, speed, course, kf_sigma_v);
    let mut step = Step::holding(course, prior, cap2, speed, trusted);
    if !st.has_prior {
        return step;
    }
    if !st.moved {
        let crept = started(mp, st, speed, course, acc, dt);
        if measurement(speed, kf_sigma_v).1 >= MAX_STD_DEG.to_radians() && !crept {
            return step;
        }
        st.moved = true;
    }
    step.hold = false;
    update_scatter(st, vn, ve, dt);
    let base = measured(mp, st, speed, acc);
    let (sig, shat, r, moving) = at_shown_noise(mp, st, speed, dt, base);
    let r_gain = gain_r(mp, st, [vn, ve], acc, r, (moving, dt));
    let p_walk = walk_variance(mp, st, dt, moving);
    // The gate first, by `base`: a glitch must neither change the direction nor count as driving.
    let gate_sig = gate_sigma(mp, st, base.0, acc);
    step.glitch = glitch(mp, st, vn, ve, speed, gate_sig, dt, base.3, p_walk, base.2);
    if !step.glitch {
        st.driving = st.released();
    }
    // A car whose speed is within its receiver's noise (under 3σ: 1% of a standing
    // receiver's epochs, 37% under the `√2σ` that `measurement` uses) is taken to stand.
    // So is a standing car whose receiver holds static, at any speed under the release
    // bar: that receiver's noise is a guess (its zeros show none), so a speed above 3σ
    // of it is no sign of motion, and speeds between its zeros are blips that turned
    // held headings by tens of degrees. The release rule says when such a car drives.
    let blip =
        st.car_stands() && st.vehicle.holds_static() && !st.released() && speed < RELEASE_SPEED;
    let car_at_rest = st.vehicle.car && ((!moving && speed < 3.0 * sig) || blip);
    // Steering turns the heading with distance driven: not over a glitch, nor over a
    // car at rest (its noise speed is no distance).
    let p = if !step.glitch && !car_at_rest {
        driving_variance(mp, p_walk, shat, dt)
    } else {
        p_walk
    };
    if moving && !step.glitch {
        direction_rules(mp, st, course, speed, p, dt, sig);
    }
    if speed <= mp.fast_speed {
        // "Continuously fast" ends at any slow epoch, moving or not: a platform's three
        // glitches, a stand, then two more made it a car.
        (st.t_fast, st.n_fast) = (0.0, 0);
    }
    (step.prior, step.p) = (st.psi, p);
    step.r2 = r_gain * r_gain;
    // A car at rest has no course: feeding its noise in turned held headings. (A slow
    // car above the noise still feeds, with the small gain its σ gives.)
    step.k = if step.glitch || car_at_rest || step.r2 >= cap2 * 0.999 {
        0.0
    } else {
        p / (p + step.r2)
    };
    step.rule_reverse = st.reverse;
    step.moving = moving;
    step.sigma_v = sig;
    step.lead_s = mp.lead_s(&st.vehicle, step.has_acc);
    (step.lever_s, step.lever_max) = mp.lever(&st.vehicle, speed, step.has_acc);
    step
}

/// What every epoch's velocity (`v`, north and east, m/s, of norm `speed`; sAcc `acc`,
/// `dt` s after the last) says about the receiver: its noise at rest and static hold
/// ([`update_noise`]), and whether its noise is smoothed ([`update_smooth`]).
fn observe_receiver(
    mp: &ModeParams,
    vehicle: &mut Vehicle,
    v: [f32; 2],
    speed: f32,
    acc: f32,
    dt: f32,
) {
    update_noise(mp, vehicle, speed, acc);
    update_smooth(vehicle, v, speed, dt);
}

/// The heading an epoch starts from ([`StepState::prior`]): after a fix gap a car's
/// course is noise under `kf`'s gate (a platform may have turned in place, so its
/// course always counts).
fn prior(st: &StepState, speed: f32, course: f32, kf_sigma_v: f32) -> f32 {
    let noise = measurement(speed, kf_sigma_v).1 >= MAX_STD_DEG.to_radians();
    st.prior(course, st.vehicle.car && noise)
}

/// Times the receiver's noise σ (m/s) by which a speed must exceed `escape_speed`, and
/// the epoch before it `0.7·escape_speed`, to show a vehicle faster than a car reverses
/// (the reverse mode ends, the sense of travel is known). A car backing up at
/// 1.5–1.8 m/s on a receiver with 0.3–0.4 m/s of noise reads over 2 m/s two epochs in
/// a row often enough that the bare bar ended its reverse mode while it still backed
/// up, a half turn off until it stopped: on simulated NMEA, RTKLIB and consumer cars
/// that was a large share of the error at 0.5–2 m/s (models/reports/unmet.md). Half a
/// σ gained as much there as a whole one on drives of other seeds, and delayed less a
/// forward departure misread as a reversal (the 2–5 m/s rows). A quiet receiver's bar
/// stays near `escape_speed`.
pub const ESCAPE_NOISE_K: f32 = 0.5;

/// The direction rules on a moving epoch: a car's departure against a sure heading
/// changes its mode, sustained speed ends a reversal (the heading was wrong by 180°) and
/// makes the vehicle a car. `sig` is the receiver's noise σ (m/s).
fn direction_rules(
    mp: &ModeParams,
    st: &mut StepState,
    course: f32,
    speed: f32,
    p: f32,
    dt: f32,
    sig: f32,
) {
    let z = facing(course, st.reverse);
    let d = wrap_rad(z - st.psi);
    let sure = mp.sure(p);
    let limit = if st.t_still > 0.0 {
        mp.flip_stop_deg
    } else {
        mp.flip_deg
    };
    let against = d.cos() < limit.to_radians().cos();
    // Forward is the likelier way out of a stop: a reversing car's departure along its
    // held heading drives forward, however unsure that heading or fast the departure.
    let leaves_forward = st.reverse && st.t_still > 0.0;
    if st.vehicle.car && against && (leaves_forward || (sure && speed < mp.flip_speed)) {
        st.reverse = !st.reverse;
        st.t_mode = 0.0;
    }
    // A platform leaving a stand against its held heading may be backing up, or may
    // have turned in place and drive forward: no course tells which. Along it, it
    // drives the way it faces.
    if st.t_still > 0.0 {
        st.sense_doubt = !st.vehicle.car && against;
    }
    let noise = ESCAPE_NOISE_K * sig;
    let fast = speed > mp.escape_speed + noise
        && st.prev_speed > 0.7 * mp.escape_speed + noise
        && dt <= 2.0;
    // Only a fast epoch that would start a run is checked: slow ones end it anyway.
    let counts =
        speed > mp.fast_speed && (st.n_fast > 0 || steers_in(mp, st, course, speed, sig, dt));
    (st.t_fast, st.n_fast) = if counts {
        (st.t_fast + dt, st.n_fast.saturating_add(1))
    } else {
        (0.0, 0)
    };
    if fast && st.reverse {
        st.reverse = false;
        st.t_mode = 0.0;
        st.psi += std::f32::consts::PI;
    }
    st.sense_known |= fast;
    st.sense_doubt &= !fast;
    // Several epochs as well as seconds: a run of glitches under poor sky lasts a few
    // epochs and must not make a slow platform a car.
    if st.t_fast >= mp.fast_secs
        && st.n_fast >= FAST_EPOCHS
        && st.vehicle.platform != Platform::Robot
    {
        st.vehicle.car = true;
    }
    // Faster than any robot for as long: a car for good.
    let v = &mut st.vehicle;
    v.t_sure = if counts && speed > SURE_CAR_SPEED {
        v.t_sure + dt
    } else {
        0.0
    };
    v.sure_car |= v.car && v.t_sure >= mp.fast_secs;
}

/// Times the course's noise (the receiver's noise σ over each epoch's speed) by which
/// a vehicle's first fast epoch may turn from the slower one before it beyond what a
/// car steers over the distance between them: turned further, it does not count
/// towards making the vehicle a car (a glitch burst out of a robot's creep).
pub const STEER_IN_NOISE_K: f32 = 2.0;

/// Whether a fast epoch (over `fast_speed`) that follows a slower one may start the
/// run that makes a vehicle a car: its course turned from the previous velocity's by
/// no more than a car steers (`k_max` over the distance between them) plus
/// [`STEER_IN_NOISE_K`] times both courses' noise. A glitch burst adds one offset to
/// a creeping robot's velocity for a few epochs, in any direction: at 1 Hz two bursts
/// back to back made five fast epochs in a row, a robot became a car, and its stands
/// then held a burst's heading while it crept on (simulated u-blox 1 Hz robots of
/// models/reports/unmet.md's seeds and of others). A car speeds up along its course; the
/// burst's first epoch turns it. Once started, the run's later epochs are not checked
/// (a car turns at speed), and a departure out of rest (the slow course is noise) is
/// not either. A car whose antenna leads its course into a sharp turn (the lever arm)
/// loses at most that epoch: the next one, steady, starts its run.
fn steers_in(mp: &ModeParams, st: &StepState, course: f32, speed: f32, sig: f32, dt: f32) -> bool {
    let prev = st.prev_v;
    let prev_speed = prev[0].hypot(prev[1]);
    if !(prev_speed.is_finite() && prev_speed > 2.0 * sig && dt > 0.0) {
        return true;
    }
    let turn = wrap_rad(course - prev[1].atan2(prev[0])).abs();
    let steer = mp.k_max * 0.5 * (speed + prev_speed) * dt;
    turn <= steer + STEER_IN_NOISE_K * (sig / prev_speed + sig / speed)
}
