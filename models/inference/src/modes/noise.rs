//! Noise on both sides of the filter: the receiver's velocity σ and the course σ it
//! gives at a speed (the measurement), and the heading's random walk and steering
//! noise (the prior).

use super::creep::steady_creep;
use super::params::ModeParams;
use super::release::{RELEASE_LOW_RATE_DT, RELEASE_NOISE_CAP};
use super::scatter::SCATTER_SMOOTH_DT;
use super::state::StepState;
use super::vehicle::{acc_ratio_factor, Platform, Vehicle, ACC_RATIO_QUANTILE};
use crate::head::MAX_STD_DEG;

#[inline]
pub(super) fn cap2() -> f32 {
    let c = MAX_STD_DEG.to_radians();
    c * c
}

/// Speed corrected for noise (`√(|v|² − 2σ²)`, 0 inside the noise) and the course's σ
/// `σ/ŝ` capped at the uniform σ.
#[inline]
pub(super) fn measurement(speed: f32, sigma: f32) -> (f32, f32) {
    let cap = MAX_STD_DEG.to_radians();
    let s2 = speed * speed - 2.0 * sigma * sigma;
    if s2 > 0.0 {
        let shat = s2.sqrt();
        (shat, (sigma / shat).min(cap))
    } else {
        (0.0, cap)
    }
}

/// Track the low quantile of slow speeds (a stopped receiver's noise) and whether the
/// receiver holds static ([`Vehicle::observe_hold`]).
///
/// The estimate starts at a guess: the reported accuracy, or 0.1 m/s without one. A
/// receiver that holds static keeps at least that guess. Its exact zeros at rest measure
/// its hold, not its noise; learnt from, they drove the estimate to 1e-20 m/s and below,
/// a value no training receiver shows. The network reads the estimate's log, and on such
/// a receiver doubted every answer, so moving platforms got the uniform σ at 0.5–1 m/s
/// and standing cars 75°. The consumer sections of models/reports/unmet.md show the
/// effect. Nor is such a receiver ever [`clean`](crate::modes::clean): its noise at
/// rest is not seen to be under its sAcc.
#[inline]
pub(super) fn update_noise(mp: &ModeParams, v: &mut Vehicle, speed: f32, acc: f32) {
    v.observe_hold(speed);
    let guess = if acc.is_finite() { acc } else { 0.1 } * mp.quantile_factor();
    if !v.noise.is_finite() {
        v.noise = guess;
    }
    if v.holds_static() {
        v.noise = v.noise.max(guess);
        return;
    }
    if speed < mp.noise_speed {
        v.noise = quantile_step(v.noise, speed, mp.noise_quantile, mp.noise_rate);
        if acc.is_finite() && acc > 0.0 {
            update_acc_ratio(mp, v, speed / acc);
        }
    }
}

/// Slow epochs over which the step of [`Vehicle::acc_ratio`] shrinks from 0.5 to
/// `noise_rate` (the step is `0.5·n₀/(n + n₀)` until then). At 1 Hz a receiver's
/// first stops give a few dozen slow epochs, too few for the running quantile's own
/// step to leave its start (the sAcc taken as honest) soon: without the larger first
/// steps the 1 Hz u-blox sAcc × 3 robots gained half as much.
pub const ACC_RATIO_WARMUP: f32 = 20.0;

/// One slow epoch's `x` = speed / sAcc into [`Vehicle::acc_ratio`] (starting at the
/// ratio an honest receiver shows, the Rayleigh quantile of [`ACC_RATIO_QUANTILE`]).
#[inline]
fn update_acc_ratio(mp: &ModeParams, v: &mut Vehicle, x: f32) {
    if !v.acc_ratio.is_finite() {
        v.acc_ratio = acc_ratio_factor();
    }
    let warm = 0.5 * ACC_RATIO_WARMUP / (v.acc_ratio_n as f32 + ACC_RATIO_WARMUP);
    let step = mp.noise_rate.max(warm);
    v.acc_ratio_n = v.acc_ratio_n.saturating_add(1);
    v.acc_ratio = quantile_step(v.acc_ratio, x, ACC_RATIO_QUANTILE, step);
}

/// One step of a running `tau` quantile `q` (log units, `step` per sample) towards
/// sample `x`: down by `step` (scaled) when `x` is under it, up otherwise, so that it
/// settles where a share `tau` of the samples lies below.
#[inline]
fn quantile_step(q: f32, x: f32, tau: f32, step: f32) -> f32 {
    let below = if x < q { 1.0 } else { 0.0 };
    q * (step * (tau - below) / tau.max(1.0 - tau)).exp()
}

/// The velocity noise σ (m/s) of this epoch.
fn sigma_v(mp: &ModeParams, v: &Vehicle, acc: f32) -> f32 {
    let known = acc.is_finite();
    if !v.car {
        return platform_sigma_v(mp, acc);
    }
    let est = mp.noise_k * v.noise / mp.quantile_factor();
    let rep = if known { mp.acc_k * acc } else { mp.sigma_none };
    est.max(rep).max(mp.sigma_floor)
}

/// A platform's velocity noise σ (m/s): its receiver's accuracy, or `tip_sigma_none`.
pub(super) fn platform_sigma_v(mp: &ModeParams, acc: f32) -> f32 {
    if acc.is_finite() {
        (mp.tip_acc_k * acc).max(mp.sigma_floor)
    } else {
        mp.tip_sigma_none
    }
}

/// Times the noise a standing car's receiver has shown at rest (its running low
/// quantile of slow speeds, [`Vehicle::noise`]) that bounds the σ_v by which the glitch
/// gate judges the car's epochs (`gate_sigma`).
pub const GATE_REST_NOISE_K: f32 = 2.0;

/// The σ_v (m/s) the glitch gate allows for (three of them) at this epoch: `sig`, the
/// σ_v of [`measured`], but for a standing car whose receiver reports an sAcc and shows
/// its noise at rest at most [`GATE_REST_NOISE_K`] times that noise. A pessimistic sAcc
/// (three times the noise) let glitch spikes of 3–4 m/s at a stand through the gate as
/// departures, and the stand then held their course: with the bound the u-blox
/// sAcc × 3 cars of `models/reports/unmet.md` at 5 and 10 Hz answer 3.6% better (1 Hz
/// unchanged); on simulated drives of two other sets of seeds such cars gained
/// 1.3–3.8%, sAcc × 2 ones up to 0.5%, and one RTKLIB section lost 0.45% at a single
/// stand whose glitch, taken without the bound, happened to point near the truth.
/// Twice rather than 1.5 times: at 1.5 a 5 Hz departure stayed `Held` 0.4 s longer.
#[inline]
pub(super) fn gate_sigma(mp: &ModeParams, st: &StepState, sig: f32, acc: f32) -> f32 {
    if st.car_stands() && acc.is_finite() && !st.vehicle.holds_static() {
        sig.min((GATE_REST_NOISE_K * mp.rest_noise(&st.vehicle)).max(mp.sigma_floor))
    } else {
        sig
    }
}

/// Times its course scatter at speed ([`Vehicle::scatter`]) that bounds the σ_v by which
/// a released car whose receiver holds static measures its slow courses.
///
/// Such a receiver reads exactly zero at rest, so it never shows its noise there and
/// the rest-noise bound on a pessimistic sAcc ([`ModeParams::trusted_acc`]) cannot
/// apply; its courses at speed show it instead. Taken at its word, a u-blox with its
/// static hold on reporting three times its sAcc (1.2 m/s against 0.4 m/s of noise)
/// put a car driving off at 1.5 m/s under the measurement's cap: its answers were the
/// stand's heading, `Held`, for over 3 s of steady driving (the u-blox-hold sAcc × 3
/// car sections of `models/reports/unmet.md`). The scatter is measured at 3 m/s and
/// faster over 30 s; 1.5 times it leaves room for the noisier sky of slow driving: by
/// the scatter itself, 1 Hz drives (whose scatter rests on few courses) lost at
/// 2–5 m/s.
///
/// [`Vehicle::scatter`]: crate::modes::Vehicle::scatter
/// [`ModeParams::trusted_acc`]: crate::modes::ModeParams::trusted_acc
pub const HOLD_SCATTER_K: f32 = 1.5;

/// The velocity noise (m/s) a car's receiver has shown: at rest (its running estimate,
/// as [`ModeParams::trusted_acc`] takes it), or for a receiver that holds static in its
/// courses at speed ([`HOLD_SCATTER_K`] times its scatter); at least `sigma_floor`.
/// Infinite for other vehicles, and before a static-hold receiver's scatter is measured.
#[inline]
fn shown_noise(mp: &ModeParams, v: &Vehicle) -> f32 {
    if !v.car {
        f32::INFINITY
    } else if !v.holds_static() {
        mp.rest_noise(v).max(mp.sigma_floor)
    } else if v.scatter.is_finite() {
        (HOLD_SCATTER_K * v.scatter.sqrt()).max(mp.sigma_floor)
    } else {
        f32::INFINITY
    }
}

/// This epoch's velocity noise σ_v, noise-corrected speed, course σ (radians) and
/// whether it moves. Released ([`StepState::released`]), the motion is real even when
/// the noise estimate (inflated by slow driving) calls it noise: it is then measured as
/// a platform would measure it, by the receiver's own accuracy, and a car's by at most
/// the noise its receiver has shown (`shown_noise`). By a pessimistic sAcc (three
/// times the noise) a released car's slow course carried no heading: one that left an
/// unsure stand at 1.7 m/s kept answering the stand's heading, 78° off, as `Ok`. (The
/// held heading is not forgotten: cars that turn as they pull away are released off its
/// axis too, and lost more than they gained.)
#[inline]
pub(super) fn measured(
    mp: &ModeParams,
    st: &StepState,
    speed: f32,
    acc: f32,
) -> (f32, f32, f32, bool) {
    let released = st.released();
    let sig = sigma_v(mp, &st.vehicle, acc);
    let (shat, r) = measurement(speed, sig);
    if released && r >= mp.moving_r {
        let sig = platform_sigma_v(mp, acc).min(shown_noise(mp, &st.vehicle));
        let (shat, r) = measurement(speed, sig);
        return (sig, shat, r, true);
    }
    (sig, shat, r, r < mp.moving_r || released)
}

/// [`measured`] for a standing car whose receiver holds static, on epochs under
/// [`RELEASE_LOW_RATE_DT`] apart: by at least the noise its courses at speed have shown
/// (`shown_noise`, [`HOLD_SCATTER_K`] times its scatter), at most the release rule's cap
/// on a noise estimate ([`RELEASE_NOISE_CAP`]). The σ_v, speed, course σ and whether it
/// moves; `base` (what [`measured`] gave) where that noise is not larger or not yet
/// measured, or the epoch is no such stand's.
///
/// Such a receiver's zeros hide its noise at rest, so its σ_v there is a guess (its sAcc,
/// or 0.1 m/s without one), and a noisy one's blips between the zeros (0.5–0.9 m/s,
/// their course held for a few epochs by the noise's correlation) read as motion under
/// that guess: the stand's heading followed them tens of degrees off, and a true
/// departure along the body was then refused by the axis rule (simulated consumer and
/// snap cars at 5 and 10 Hz, `models/reports/unmet.md`). Its courses at speed show the
/// noise the zeros hide, as they do for a released car's bound in [`measured`]. Capped,
/// a steady 1 m/s still moves (uncapped, a 5 Hz consumer car's creep along its axis was
/// `Held` for 1.8 s). At lower rates the noise at rest is independent from one epoch to
/// the next, no blip holds its course, and the 1 Hz sections lost up to 1% by the
/// floor. The glitch gate keeps `base`: with this σ_v a departure's first epochs went
/// unconfirmed and stayed `Held` for 1.6 s at 5 Hz, and glitch bursts passed a stand.
#[inline]
pub(super) fn at_shown_noise(
    mp: &ModeParams,
    st: &StepState,
    speed: f32,
    dt: f32,
    base: (f32, f32, f32, bool),
) -> (f32, f32, f32, bool) {
    let stand = st.car_stands() && st.vehicle.holds_static() && !st.released();
    if !stand || dt >= RELEASE_LOW_RATE_DT {
        return base;
    }
    let shown = shown_noise(mp, &st.vehicle).min(RELEASE_NOISE_CAP);
    if !shown.is_finite() || shown <= base.0 {
        return base;
    }
    let (shat, r) = measurement(speed, shown);
    (shown, shat, r, r < mp.moving_r)
}

/// The course σ (radians) the filter's gain weighs this epoch's course by: `r`, the one
/// from the σ_v in use, or for a vehicle not known to be a car the one from
/// [`ModeParams::gain_acc`] (the sAcc brought down to the noise its receiver has shown
/// at rest, where the reported sAcc is pessimistic) when it moves, and when it does not
/// too where it may be creeping ([`weighs_rest_by_gain`]). Under a pessimistic sAcc a
/// robot's creep off a spin (0.1–0.5 m/s) is no motion and carried no heading: it
/// answered the heading from before the spin (the u-blox sAcc × 3 robots of
/// `models/reports/unmet.md`, 25% worse than atan2 at 0.05–0.5 m/s). Where `gain_acc`
/// keeps the sAcc, `r` already is that course σ: a platform's σ_v is
/// [`platform_sigma_v`] of the sAcc.
#[inline]
pub(super) fn gain_r(
    mp: &ModeParams,
    st: &StepState,
    v: [f32; 2],
    acc: f32,
    r: f32,
    (moving, dt): (bool, f32),
) -> f32 {
    if st.vehicle.car || (!moving && !weighs_rest_by_gain(mp, st, v, acc, dt)) {
        return r;
    }
    let speed = v[0].hypot(v[1]);
    let gain = mp.gain_acc(&st.vehicle, acc);
    if !acc.is_finite() || gain == acc {
        return r;
    }
    measurement(speed, platform_sigma_v(mp, gain)).1
}

/// Whether a vehicle not known to be a car weighs an epoch under the motion bar by
/// [`ModeParams::gain_acc`] as it weighs its motion: a declared [`Platform::Robot`]
/// and an `auto` vehicle seen to turn in place ([`Vehicle::turns_in_place`]) always,
/// another `auto` vehicle when its velocity `v` is a steady creep over the sAcc it has
/// earned ([`steady_creep`] from the velocity before it, `dt` s earlier). On the u-blox
/// sAcc × 3 robots of `models/reports/unmet.md`, `auto` kept the reported sAcc at
/// every such epoch and answered 11–16% worse than atan2, three times the cost of
/// `--platform robot`; a robot not yet seen to turn creeps off its first spins too.
/// Noise at rest seldom stays over that sAcc on a steady course from one epoch to the
/// next, so a car's stands keep the reported sAcc nearly always (the car sections of
/// `models/reports/unmet.md` moved by at most 0.6%). Seen to turn, the stands of a
/// robot with such an sAcc follow their noise's courses as a declared robot's do: one
/// simulated RTKLIB robot of the held-out platforms (sAcc 2.6 times its noise at rest)
/// lost 3° at its stops.
#[inline]
fn weighs_rest_by_gain(mp: &ModeParams, st: &StepState, v: [f32; 2], acc: f32, dt: f32) -> bool {
    let vehicle = &st.vehicle;
    match vehicle.platform {
        Platform::Robot => true,
        Platform::Car => false,
        Platform::Auto if vehicle.turns_in_place() => true,
        Platform::Auto => steady_creep(v, st.prev_v, mp.trusted_acc(vehicle, acc), dt),
    }
}

/// The prior variance (radians²) of a step from `st` after `dt` before any steering:
/// the class's random walk (a car's is small: cars do not turn in place; a platform
/// `moving` on epochs at most [`SCATTER_SMOOTH_DT`] apart does not spin either,
/// [`ModeParams::q_move_deg`]).
#[inline]
pub(super) fn walk_variance(mp: &ModeParams, st: &StepState, dt: f32, moving: bool) -> f32 {
    let q = if st.vehicle.car {
        mp.q_still_deg
    } else if moving && dt <= SCATTER_SMOOTH_DT {
        mp.q_move_deg
    } else {
        mp.q_tip_deg
    }
    .to_radians();
    random_walk_variance(st.log_sigma, q, dt)
}

/// The prior variance (radians², capped at the uniform one) of a heading with `log σ`
/// `log_sigma` after a random walk of `q` rad/√s for `dt`: the mode filter's and `kf`'s.
#[inline]
pub(crate) fn random_walk_variance(log_sigma: f32, q: f32, dt: f32) -> f32 {
    ((2.0 * log_sigma).exp() + q * q * dt).min(cap2())
}

/// `p_walk` (the walk, [`walk_variance`]) plus the steering noise of the distance
/// driven at speed `shat` over `dt` (path curvature `k_max` when slow, lateral
/// acceleration `a_lat` at speed).
#[inline]
pub(super) fn driving_variance(mp: &ModeParams, p_walk: f32, shat: f32, dt: f32) -> f32 {
    let w = mp.k_max * shat.min(mp.a_lat / (mp.k_max * shat.max(1e-3)));
    (p_walk + w * w * dt).min(cap2())
}
