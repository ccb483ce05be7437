//! The σ maps of a temporal model: its errors streamed over tracks, and the monotone
//! maps from raw to calibrated σ fitted per class of epoch (car or not, moving or
//! standing, clean receiver, turning) so that the shares within 1σ and 2σ meet their
//! bars, standing cars counted per stop.

use std::sync::Arc;

use ghnet_inference::head::wrap_rad;
use ghnet_inference::modes::{SigmaMap, SigmaMaps, StepState, TURN_SPEED};
use ghnet_inference::params::ParamSet;
use ghnet_inference::stream::{Epoch, StreamPredictor};
use ghnet_inference::weights::{ModelKind, ModelMeta};
use ghnet_inference::Model;

use crate::logs::LogTrack;

/// What a streamed run answered, per epoch: wrapped error and reported σ (radians),
/// and whether the vehicle was known to be a car.
#[derive(Debug, Clone, Default)]
pub struct Streamed {
    /// Wrapped error, radians.
    pub err: Vec<f32>,
    /// Reported σ, radians.
    pub sigma: Vec<f32>,
    /// The history knew the vehicle to be a car.
    pub car: Vec<bool>,
    /// The epoch moved (its course was measured, [`Step::moving`](ghnet_inference::modes::Step::moving)).
    pub moving: Vec<bool>,
    /// The receiver was clean ([`ghnet_inference::modes::clean`]) when the vehicle last
    /// moved (what a standing car's σ map is chosen by).
    pub clean: Vec<bool>,
    /// Measured speed, m/s (whether a moving epoch's σ has the turn term).
    pub speed: Vec<f32>,
    /// The epoch is its track's first (where a stop cannot continue).
    pub first: Vec<bool>,
}

/// Whether the epoch between states `a` and `b` moved, as the model decides it
/// ([`StepState::moving_now`]). A history's first epoch and those before its first
/// motion count as standing: they answer the uniform σ, which no map fits.
fn moved_now(a: &StepState, b: &StepState) -> bool {
    b.moving_now() && a.has_prior && b.has_prior && b.moved
}

/// Stream `model` over `tracks` (a fresh history per track).
pub fn stream_errors(model: &Arc<Model>, tracks: &[LogTrack]) -> Streamed {
    let mut sp = StreamPredictor::new(model.clone());
    let mut out = Streamed::default();
    for t in tracks {
        let mut h = sp.history();
        for i in 0..t.len() {
            let e = Epoch {
                t_s: t.t_s[i],
                v_north: t.v_north[i],
                v_east: t.v_east[i],
                speed_acc: t.speed_acc[i],
            };
            let before = *h.state();
            let p = sp.predict(&mut h, &e);
            out.moving.push(moved_now(&before, h.state()));
            out.err
                .push(wrap_rad((p.heading_deg - t.truth_deg[i]).to_radians()));
            out.sigma.push(p.std_deg.to_radians());
            out.car.push(h.state().vehicle.car);
            out.clean.push(h.state().held_clean);
            out.speed.push(e.v_north.hypot(e.v_east));
            out.first.push(i == 0);
        }
    }
    out
}

/// One of a temporal model's σ maps (a field of [`SigmaMaps`]), named as in the model
/// file's `sigma_map` (what `ghnet info` prints): `ghnet calibrate --maps` refits some
/// and keeps the rest, so a choice to refit one map (the others' fits moving numbers
/// that should be judged on their own) is a command anyone can rerun, not an edit of
/// a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum MapName {
    /// Cars, moving.
    Car,
    /// Other vehicles, moving.
    Platform,
    /// Cars, standing.
    CarStill,
    /// Cars, standing, on a clean receiver.
    CarStillClean,
    /// Other vehicles, standing.
    PlatformStill,
    /// Cars turning at speed.
    CarTurn,
}

impl MapName {
    /// The epochs a class map is fitted on (car, moving, clean receiver: only a standing
    /// car's map tells clean receivers apart), the share within 2σ it is fitted to, and
    /// its label; `None` for the turn map, fitted on the class maps' σ.
    fn class(self) -> Option<(bool, bool, bool, f64, &'static str)> {
        Some(match self {
            MapName::Car => (true, true, false, TARGET_2SIGMA, "cars, moving"),
            MapName::Platform => (false, true, false, TARGET_2SIGMA, "others, moving"),
            MapName::CarStill => (true, false, false, TARGET_2SIGMA_STOP, "cars, standing"),
            MapName::CarStillClean => (
                true,
                false,
                true,
                TARGET_2SIGMA_STOP,
                "cars, standing, clean receiver",
            ),
            MapName::PlatformStill => (false, false, false, TARGET_2SIGMA, "others, standing"),
            MapName::CarTurn => return None,
        })
    }

    /// Every map, in the order [`calibrate`] fits them.
    pub const ALL: [MapName; 6] = [
        MapName::Car,
        MapName::Platform,
        MapName::CarStill,
        MapName::CarStillClean,
        MapName::PlatformStill,
        MapName::CarTurn,
    ];
}

/// The model with its σ maps fitted on its streamed errors over `tracks` (the network
/// and the filter as they are: headings do not change, only σ). The scatter floor
/// ([`SigmaMaps::scatter_k`]) is kept and left out of the fit: it is for receivers
/// unlike the training ones. A class that `tracks` barely show (fewer epochs than
/// `MIN_CLASS_EPOCHS`, or stops than `MIN_CLASS_STOPS`: a user's car log has a
/// minute of a vehicle not yet known to be a car and no platform standing) keeps the
/// map `meta` had, the starting model's: fitted on a few dozen epochs, a map is that
/// log's luck, and on none it is the identity (the raw σ, uncalibrated).
pub fn calibrate(params: ParamSet, meta: ModelMeta, tracks: &[LogTrack]) -> Model {
    calibrate_maps(params, meta, tracks, &MapName::ALL)
}

/// [`calibrate`] for the maps in `only`; every other map is kept as `meta` has it. Each
/// class map is fitted on the raw model's errors whatever the others are, so refitting
/// one gives the map a whole calibration would; the turn map is fitted on the class
/// maps the result has.
pub fn calibrate_maps(
    params: ParamSet,
    mut meta: ModelMeta,
    tracks: &[LogTrack],
    only: &[MapName],
) -> Model {
    // The raw model: identity maps (its σ is what the maps read), the choice of σ kept.
    let mut given = match &mut meta.kind {
        ModelKind::Temporal { sigma_map, .. } => {
            let given = std::mem::take(sigma_map);
            sigma_map.moving_without_y2 = given.moving_without_y2;
            given
        }
        _ => SigmaMaps::default(),
    };
    let (yaw_s, moving_without_y2, scatter_k) =
        (given.yaw_s, given.moving_without_y2, given.scatter_k);
    let raw = Arc::new(Model::new(params.clone(), meta.clone()));
    let run = stream_errors(&raw, tracks);
    // The maps are fitted without the scatter floor, which covers what they cannot
    // know: receivers unlike the training ones.
    let mut maps = SigmaMaps {
        moving_without_y2,
        ..SigmaMaps::default()
    };
    for name in MapName::ALL {
        let Some((car, moving, clean, target, label)) = name.class() else {
            continue;
        };
        let split = car && !moving;
        let of_class = |i: usize| {
            run.car[i] == car && run.moving[i] == moving && (!split || run.clean[i] == clean)
        };
        *maps.map_mut(car, moving, clean) = if !only.contains(&name) {
            eprintln!("σ map ({label}): not asked for: kept as it was");
            *given.map_mut(car, moving, clean)
        } else if thin_class(&run, of_class, split, label) {
            *given.map_mut(car, moving, clean)
        } else {
            fit_class(&run, of_class, target, split, label)
        };
    }
    if yaw_s > 0.0 {
        maps.yaw_s = yaw_s;
        let label = "cars, moving, turn";
        maps.car_turn = if !only.contains(&MapName::CarTurn) {
            eprintln!("σ map ({label}): not asked for: kept as it was");
            given.car_turn
        } else {
            // The turn map, on the class maps' σ with the turn term (identity turn map),
            // over the epochs that get it.
            let run = stream_errors(&Arc::new(with_maps(&params, &meta, maps)), tracks);
            let of_class = |i: usize| run.car[i] && run.moving[i] && run.speed[i] >= TURN_SPEED;
            if thin_class(&run, of_class, false, label) {
                given.car_turn
            } else {
                fit_class(&run, of_class, TARGET_2SIGMA, false, label)
            }
        };
    }
    maps.scatter_k = scatter_k;
    with_maps(&params, &meta, maps)
}

/// Fewest epochs of a class [`calibrate`] fits a map on: a hundred per knot.
const MIN_CLASS_EPOCHS: usize = 100 * ghnet_inference::modes::SIGMA_KNOTS;

/// Fewest stops of a standing car's class [`calibrate`] fits a map on (it is fitted per
/// stop): two per knot. Few, because a receiver's held headings differ more than a
/// map shows: on a simulated RTKLIB car, a standing map fitted on the 29 stops of a
/// 20-minute log took the next 20 minutes to 76% within 1σ, the shipped map to 83%.
const MIN_CLASS_STOPS: usize = 2 * ghnet_inference::modes::SIGMA_KNOTS;

/// Whether `run` holds too few epochs of the class `of_class` selects (or, `per_stop`,
/// too few of its stops) to fit a map on ([`MIN_CLASS_EPOCHS`], [`MIN_CLASS_STOPS`]);
/// says so, with the `label`, when it does.
fn thin_class(
    run: &Streamed,
    of_class: impl Fn(usize) -> bool,
    per_stop: bool,
    label: &str,
) -> bool {
    let (idx, starts) = class_epochs(run, of_class);
    let (epochs, stops) = (idx.len(), starts.iter().filter(|&&b| b).count());
    let thin = epochs < MIN_CLASS_EPOCHS || (per_stop && stops < MIN_CLASS_STOPS);
    if thin {
        let of = if per_stop {
            format!(" ({stops} stops)")
        } else {
            String::new()
        };
        eprintln!("σ map ({label}): {epochs} epochs{of}, too few to fit: kept as it was");
    }
    thin
}

/// The epochs of `run` that `of_class` selects, and for each whether it starts a stop
/// (a run of the class): the track's first epoch, or the previous epoch not of the
/// class.
fn class_epochs(run: &Streamed, of_class: impl Fn(usize) -> bool) -> (Vec<usize>, Vec<bool>) {
    let idx: Vec<usize> = (0..run.err.len()).filter(|&i| of_class(i)).collect();
    let starts = idx
        .iter()
        .enumerate()
        .map(|(k, &i)| run.first[i] || k == 0 || idx[k - 1] != i - 1)
        .collect();
    (idx, starts)
}

/// The model with the σ maps of its moving epochs scaled to fit `tracks` (a user's
/// log): the maps of cars (with their turn map) and of other vehicles, each by one
/// factor in [0.5, 2] chosen so that its epochs there reach 92% (`RESCALE_2SIGMA`) within
/// 2σ with the share within 1σ nearest 68.3%, only where `tracks` hold at least
/// `min_epochs` of its epochs; every other map, the turn term and the scatter floor
/// kept. One factor, not a new map: a log of minutes holds a few dozen of a class's
/// tail errors, too few to place a map's twelve knots, while the maps' shape (σ
/// against the filter's σ) is fitted on hundreds of drives. Moving epochs are where a
/// receiver's noise and lag show; a log holds too few stops to fit a standing map per
/// stop. Also returns the classes scaled, with their factors (none: the model as it
/// was).
pub fn rescale_moving(
    model: &Model,
    tracks: &[LogTrack],
    min_epochs: usize,
) -> (Model, Vec<(&'static str, f32)>) {
    let ModelKind::Temporal {
        sigma_map: given, ..
    } = model.meta().kind
    else {
        return (model.clone(), Vec::new());
    };
    let params = model.params();
    // Per factor, the shares within 1σ and 2σ of each class's moving epochs.
    let mut rows: Vec<(f32, [(f64, f64); 2])> = Vec::new();
    let mut counts = [0usize; 2];
    for k in 0..=30 {
        let f = 0.5 * 4f32.powf(k as f32 / 30.0);
        let run = stream_errors(
            &Arc::new(with_maps(params, model.meta(), scaled(given, f, f))),
            tracks,
        );
        let mut shares = [(0.0, 0.0); 2];
        for (c, share) in shares.iter_mut().enumerate() {
            let of = |i: usize| run.moving[i] && run.car[i] == (c == 0);
            counts[c] = (0..run.err.len()).filter(|&i| of(i)).count();
            *share = shares_within(&run, of);
        }
        rows.push((f, shares));
    }
    let mut factors = [1.0f32; 2];
    let mut chosen = Vec::new();
    for (c, label) in ["cars, moving", "others, moving"].into_iter().enumerate() {
        if counts[c] < min_epochs {
            continue;
        }
        let reaching = rows.iter().filter(|r| r.1[c].1 >= RESCALE_2SIGMA);
        let best = reaching
            .min_by(|a, b| {
                (a.1[c].0 - 0.683)
                    .abs()
                    .total_cmp(&(b.1[c].0 - 0.683).abs())
            })
            .or(rows.last());
        if let Some(&(f, _)) = best {
            factors[c] = f;
            chosen.push((label, f));
        }
    }
    let maps = scaled(given, factors[0], factors[1]);
    (with_maps(params, model.meta(), maps), chosen)
}

/// `maps` with the reported σ of cars' moving maps (`car`, `car_turn`) times `car` and
/// other vehicles' (`platform`) times `other`.
fn scaled(maps: SigmaMaps, car: f32, other: f32) -> SigmaMaps {
    let times = |m: SigmaMap, f: f32| SigmaMap {
        reported_deg: m.reported_deg.map(|y| y * f),
        ..m
    };
    SigmaMaps {
        car: times(maps.car, car),
        car_turn: times(maps.car_turn, car),
        platform: times(maps.platform, other),
        ..maps
    }
}

/// Shares of the epochs of `run` that `of` selects within 1σ and 2σ (reported σ, the
/// uniform one included).
pub fn shares_within(run: &Streamed, of: impl Fn(usize) -> bool) -> (f64, f64) {
    let idx: Vec<usize> = (0..run.err.len()).filter(|&i| of(i)).collect();
    let n = idx.len().max(1) as f64;
    let within = |k: f32| {
        let n_in = idx
            .iter()
            .filter(|&&i| run.err[i].abs() <= k * run.sigma[i]);
        n_in.count() as f64 / n
    };
    (within(1.0), within(2.0))
}

/// The model of `params` and `meta` with σ maps `maps`.
fn with_maps(params: &ParamSet, meta: &ModelMeta, maps: SigmaMaps) -> Model {
    let mut meta = meta.clone();
    if let ModelKind::Temporal { sigma_map, .. } = &mut meta.kind {
        *sigma_map = maps;
    }
    Model::new(params.clone(), meta)
}

/// The σ map fitted on the epochs of `run` that `of_class` selects, its coverage logged.
///
/// A standing class (`per_stop`) is fitted per stop as well as per epoch: a held
/// heading repeats one error for the whole stop and a filter fuses it once
/// (`client/README.md`), so a stop counts once in the map's quantiles (each epoch
/// weighs 1/its stop's length) and must reach the 2σ share per stop; per epoch it
/// must still reach it and stay under the 1σ bar. Fitted per epoch alone, long stops
/// (long waits after a clean stop, small errors) outweighed the short ones where
/// held errors are large, and held-out simulated cars put 89.4% of their stops
/// within 2σ.
fn fit_class(
    run: &Streamed,
    of_class: impl Fn(usize) -> bool,
    target: f64,
    per_stop: bool,
    label: &str,
) -> SigmaMap {
    let (idx, starts) = class_epochs(run, of_class);
    let e: Vec<f32> = idx.iter().map(|&i| run.err[i]).collect();
    let s: Vec<f32> = idx.iter().map(|&i| run.sigma[i]).collect();
    let ones = vec![1.0; e.len()];
    let stop_w = if per_stop {
        stop_weights(&starts)
    } else {
        ones.clone()
    };
    let map = fit_sigma_map(&e, &s, &stop_w, target);
    let (c1, c2) = coverage(&map, &e, &s, &ones);
    let per = if per_stop {
        let (d1, d2) = coverage(&map, &e, &s, &stop_w);
        let n = starts.iter().filter(|&&b| b).count();
        format!("; {:.1}% / {:.1}% of {n} stops", 100.0 * d1, 100.0 * d2)
    } else {
        String::new()
    };
    eprintln!(
        "σ map ({label}): within 1σ {:.1}%, 2σ {:.1}% of {} epochs{per}",
        100.0 * c1,
        100.0 * c2,
        e.len()
    );
    map
}

/// Weights that make each run (a stop) weigh 1 in all: `1/len` for each of its
/// epochs; a run starts where `starts` is true.
fn stop_weights(starts: &[bool]) -> Vec<f64> {
    let mut w = vec![0.0; starts.len()];
    let mut i = 0;
    while i < starts.len() {
        let len = 1 + starts[i + 1..].iter().take_while(|&&b| !b).count();
        w[i..i + len].fill(1.0 / len as f64);
        i += len;
    }
    w
}

/// Shares within 1σ and 2σ of `errs` under σ map `map`, each error weighing its
/// `weights` entry (errors and raw σ in radians; the uniform σ stays as it is).
pub fn coverage(map: &SigmaMap, errs: &[f32], sigma: &[f32], weights: &[f64]) -> (f64, f64) {
    let (mut c1, mut c2, mut n) = (0.0, 0.0, 0.0);
    let cap = ghnet_inference::head::MAX_STD_DEG.to_radians();
    for ((e, s), w) in errs.iter().zip(sigma).zip(weights) {
        let r = if *s >= 0.999 * cap {
            cap
        } else {
            map.apply(s.to_degrees()).to_radians()
        };
        c1 += w * f64::from(u8::from(e.abs() <= r));
        c2 += w * f64::from(u8::from(e.abs() <= 2.0 * r));
        n += w;
    }
    let n = if n > 0.0 { n } else { 1.0 };
    (c1 / n, c2 / n)
}

/// Share of errors within 1σ the fitted map aims at overall (a Gaussian's is 68.3%;
/// the bar is 60–76%).
const TARGET_1SIGMA: f64 = 0.68;
/// Share within 2σ it must reach overall (the bar is 90%), with a margin.
const TARGET_2SIGMA: f64 = 0.91;
/// Share of stops within 2σ for standing cars (counted per stop; the bar is 90%),
/// with a margin: a test set's share per stop moves by about a point (a few hundred
/// stops).
const TARGET_2SIGMA_STOP: f64 = 0.92;
/// Share within 2σ a factor fitted on a user's log must reach there ([`rescale_moving`]):
/// a point over the maps' target, since the minutes of a log it is fitted on meet the
/// tails of its later minutes less surely than a map fitted on hundreds of drives.
const RESCALE_2SIGMA: f64 = 0.92;
/// The bars per epoch, which a map fitted per stop must still meet: at least
/// this share within 2σ...
const BAR_2SIGMA: f64 = 0.90;
/// ...and at most this share within 1σ.
const BAR_1SIGMA_MAX: f64 = 0.76;

/// A monotone σ map from (wrapped error, raw σ) pairs in radians, each weighing its
/// `weights` entry (all 1 per epoch; 1/stop length per stop): the raw σ split into
/// [`SIGMA_KNOTS`](ghnet_inference::modes::SIGMA_KNOTS) bins of equal weight; in each,
/// the σ that puts a share `a` of the errors within 1σ, raised if needed so that a
/// share `b` falls within 2σ; made non-decreasing (pool adjacent violators). `(a, b)`
/// are searched so that overall `target_2sigma` of the errors fall within 2σ and the
/// share within 1σ is as near `TARGET_1SIGMA` as that allows: heavy tails (a
/// direction misread costs 180°) make a single Gaussian scale miss one of the two.
/// With weights other than 1, the shares are reached under those weights and, per
/// epoch, the 2σ share must still reach the bar and the 1σ share stay under it.
pub fn fit_sigma_map(errs: &[f32], sigma: &[f32], weights: &[f64], target_2sigma: f64) -> SigmaMap {
    let ones = vec![1.0; errs.len()];
    let weighted = weights.iter().any(|&w| w != 1.0);
    let mut best = (f64::INFINITY, SigmaMap::default());
    for ai in 0..=14 {
        let a = 0.50 + 0.02 * ai as f64;
        for bi in 0..=10 {
            let b = 0.86 + 0.012 * bi as f64;
            let map = binned_map(errs, sigma, weights, a, b);
            let (c1, c2) = coverage(&map, errs, sigma, weights);
            let mut cost = (c1 - TARGET_1SIGMA).abs() + 10.0 * (target_2sigma - c2).max(0.0);
            if weighted {
                let (e1, e2) = coverage(&map, errs, sigma, &ones);
                cost += 10.0 * ((BAR_2SIGMA - e2).max(0.0) + (e1 - BAR_1SIGMA_MAX).max(0.0));
            }
            if cost < best.0 {
                best = (cost, map);
            }
        }
    }
    best.1
}

/// The map of [`fit_sigma_map`] for fixed shares `a` (1σ) and `b` (2σ) per bin.
fn binned_map(errs: &[f32], sigma: &[f32], weights: &[f64], a: f64, b: f64) -> SigmaMap {
    use ghnet_inference::modes::SIGMA_KNOTS;
    let cap = ghnet_inference::head::MAX_STD_DEG.to_radians() * 0.999;
    let mut pairs: Vec<(f32, f32, f64)> = sigma
        .iter()
        .zip(errs)
        .zip(weights)
        .filter(|((s, e), _)| s.is_finite() && **s < cap && e.is_finite())
        .map(|((s, e), w)| (*s, e.abs(), *w))
        .collect();
    if pairs.len() < 10 * SIGMA_KNOTS {
        return SigmaMap::default();
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0));
    // Bin edges: the last index whose preceding weight is within each k/SIGMA_KNOTS of
    // the total (with unit weights, ⌊k·n/SIGMA_KNOTS⌋, bins of equal count).
    let mut cum = vec![0.0f64];
    for p in &pairs {
        cum.push(cum[cum.len() - 1] + p.2);
    }
    let total = cum[pairs.len()];
    let edges: Vec<usize> = (0..=SIGMA_KNOTS)
        .map(|k| {
            let target = total * k as f64 / SIGMA_KNOTS as f64 + 1e-9 * total;
            (cum.partition_point(|&c| c <= target) - 1).min(pairs.len())
        })
        .collect();
    let mut map = SigmaMap::default();
    let mut bin_w = [0.0f64; SIGMA_KNOTS];
    for k in 0..SIGMA_KNOTS {
        let bin =
            &pairs[edges[k].min(pairs.len() - 1)..edges[k + 1].max(edges[k] + 1).min(pairs.len())];
        let mut e: Vec<(f32, f64)> = bin.iter().map(|p| (p.1, p.2)).collect();
        e.sort_by(|x, y| x.0.total_cmp(&y.0));
        let s = weighted_quantile(&e, a)
            .max(0.5 * weighted_quantile(&e, b))
            .max(1e-4);
        map.raw_deg[k] = bin[bin.len() / 2].0.to_degrees();
        map.reported_deg[k] = s.to_degrees().min(ghnet_inference::head::MAX_STD_DEG);
        bin_w[k] = bin.iter().map(|p| p.2).sum();
    }
    isotonic(&mut map.reported_deg, &bin_w);
    for k in 1..SIGMA_KNOTS {
        // Equal raw knots (a σ that repeats) would make a step; nudge them apart.
        if map.raw_deg[k] <= map.raw_deg[k - 1] {
            map.raw_deg[k] = map.raw_deg[k - 1] * 1.0001 + 1e-6;
        }
    }
    map
}

/// The `p` quantile of values sorted ascending, each with a weight: the first value
/// whose running weight exceeds `p` of the total (with unit weights, element
/// `⌊p·n⌋`).
fn weighted_quantile(sorted: &[(f32, f64)], p: f64) -> f32 {
    let total: f64 = sorted.iter().map(|x| x.1).sum();
    let mut acc = 0.0;
    for (v, w) in sorted {
        acc += w;
        if acc > p * total {
            return *v;
        }
    }
    sorted.last().map_or(0.0, |x| x.0)
}

/// Pool adjacent violators: `y` made non-decreasing, least squares with `w`.
fn isotonic(y: &mut [f32], w: &[f64]) {
    let mut blocks: Vec<(f64, f64, usize)> = Vec::new(); // (mean, weight, len)
    for (v, wt) in y.iter().zip(w) {
        blocks.push((*v as f64, *wt, 1));
        while blocks.len() > 1 && blocks[blocks.len() - 2].0 > blocks[blocks.len() - 1].0 {
            let (m2, w2, l2) = blocks.pop().expect("two blocks");
            let (m1, w1, l1) = blocks.pop().expect("two blocks");
            blocks.push(((m1 * w1 + m2 * w2) / (w1 + w2), w1 + w2, l1 + l2));
        }
    }
    let mut i = 0;
    for (m, _, l) in blocks {
        for v in &mut y[i..i + l] {
            *v = m as f32;
        }
        i += l;
    }
}

/// Mean absolute error of radians, in degrees.
pub fn mean_abs_deg(errs: &[f32]) -> f32 {
    (errs.iter().map(|e| e.abs() as f64).sum::<f64>() / errs.len().max(1) as f64).to_degrees()
        as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn each_stop_weighs_one() {
        let w = stop_weights(&[true, false, false, true, true, false]);
        let want = [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, 1.0, 0.5, 0.5];
        for (a, b) in w.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        // Unit weights: element ⌊p·n⌋, as an unweighted quantile.
        let v: Vec<(f32, f64)> = (0..10).map(|i| (i as f32, 1.0)).collect();
        assert_eq!(weighted_quantile(&v, 0.68), 6.0);
        assert_eq!(weighted_quantile(&v, 0.0), 0.0);
    }

    /// Shares within 1σ and 2σ of the moving epochs of vehicles not known to be cars.
    fn platform_shares(model: &Model, tracks: &[LogTrack]) -> (f64, f64) {
        let run = stream_errors(&Arc::new(model.clone()), tracks);
        shares_within(&run, |i| run.moving[i] && !run.car[i])
    }

    /// A platform map twice as wide as the shipped one is scaled down on a robot's log,
    /// one half as wide (short of the 2σ target there) up: the robot's moving epochs
    /// then reach the target, the wide map's with a share within 1σ nearer 68% than
    /// before. The car maps, without epochs there, stay as they are.
    #[test]
    fn a_mis_scaled_platform_map_is_scaled_back_on_a_robot_log() {
        let p = crate::drive::DriveParams {
            tracks: 4,
            track_min_s: 150.0,
            track_max_s: 200.0,
            receivers: vec![crate::drive::ReceiverKind::Rtklib],
            rates_hz: vec![5],
            ..crate::drive::DriveParams::default().robots()
        };
        let tracks = crate::logs::simulated(&p, 5);
        let shipped = Model::builtin("ghnet-temporal").expect("built in");
        let ModelKind::Temporal { sigma_map, .. } = shipped.meta().kind else {
            panic!("a temporal model");
        };
        for wrong in [2.0f32, 0.5] {
            let maps = scaled(sigma_map, 1.0, wrong);
            let m = with_maps(shipped.params(), shipped.meta(), maps);
            let (fixed, classes) = rescale_moving(&m, &tracks, 1000);
            assert_eq!(classes.len(), 1, "{classes:?}");
            let (class, f) = classes[0];
            assert_eq!(class, "others, moving");
            assert!((f < 1.0) == (wrong > 1.0), "map × {wrong}: factor {f}");
            let ModelKind::Temporal { sigma_map: got, .. } = fixed.meta().kind else {
                panic!("a temporal model");
            };
            assert_eq!(got.car, sigma_map.car);
            let (b1, b2) = platform_shares(&m, &tracks);
            let (a1, a2) = platform_shares(&fixed, &tracks);
            assert!(a2 >= RESCALE_2SIGMA, "map × {wrong}: {b2} → {a2} within 2σ");
            if b2 >= RESCALE_2SIGMA {
                let nearer = (a1 - 0.683).abs() < (b1 - 0.683).abs();
                assert!(nearer, "map × {wrong}: {b1} → {a1} within 1σ");
            }
        }
    }

    /// Calibrated on a short car log, the classes it hardly shows (a vehicle not yet
    /// known to be a car, platforms standing) keep the starting model's maps instead of
    /// maps fitted on a few dozen epochs or the identity, while the moving cars' map,
    /// with thousands of epochs, is fitted anew. Asked for that map alone
    /// ([`calibrate_maps`], `ghnet calibrate --maps car`), it gets the same fit and the
    /// turning cars' map, which the whole calibration refits too, stays.
    #[test]
    fn a_short_car_log_keeps_the_maps_of_classes_it_hardly_shows() {
        let p = crate::drive::DriveParams {
            tracks: 1,
            platform_share: 0.0,
            track_min_s: 600.0,
            track_max_s: 600.0,
            receivers: vec![crate::drive::ReceiverKind::Ublox],
            rates_hz: vec![5],
            ..crate::drive::DriveParams::default()
        };
        let tracks = crate::logs::simulated(&p, 9);
        let shipped = Model::builtin("ghnet-temporal").expect("built in");
        let ModelKind::Temporal { sigma_map: was, .. } = shipped.meta().kind else {
            panic!("a temporal model");
        };
        let m = calibrate(shipped.params().clone(), shipped.meta().clone(), &tracks);
        let ModelKind::Temporal { sigma_map: got, .. } = m.meta().kind else {
            panic!("a temporal model");
        };
        assert_eq!(got.platform, was.platform);
        assert_eq!(got.platform_still, was.platform_still);
        assert_ne!(got.car, was.car, "moving cars: fitted on the log");
        assert!(!got.car.is_identity());
        // Asked for the moving cars' map alone, the same fit, and every other map as
        // it was, the ones the log refits above included.
        assert_ne!(
            got.car_turn, was.car_turn,
            "turning cars: fitted on the log"
        );
        let one = calibrate_maps(
            shipped.params().clone(),
            shipped.meta().clone(),
            &tracks,
            &[MapName::Car],
        );
        let ModelKind::Temporal { sigma_map: one, .. } = one.meta().kind else {
            panic!("a temporal model");
        };
        assert_eq!(one.car, got.car);
        assert_eq!(
            SigmaMaps {
                car: was.car,
                ..one
            },
            was,
            "only the moving cars' map refitted"
        );
    }

    /// Long stops with small errors and many short ones with large errors, all with
    /// the same raw σ: fitted per epoch, the map covers the epochs and misses the short
    /// stops (under 92% within 2σ); fitted per stop, at least 92% of stops fall within
    /// 2σ while the epochs still meet the bars.
    #[test]
    fn a_per_stop_fit_covers_the_stops_a_per_epoch_fit_misses() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut e, mut s, mut starts) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..400 {
            // One stop in four is short (3 epochs) and poor (errors up to 4°); the
            // others last 30 epochs and hold up to 1.6°.
            let (len, scale) = if k % 4 == 0 { (3, 2.5f32) } else { (30, 1.0) };
            let err = (scale * rng.random_range(0.0f32..1.6)).to_radians();
            let raw = (2.0f32 + rng.random_range(0.0..0.5)).to_radians();
            for j in 0..len {
                e.push(err);
                s.push(raw);
                starts.push(j == 0);
            }
        }
        let ones = vec![1.0; e.len()];
        let w = stop_weights(&starts);
        let per_epoch = fit_sigma_map(&e, &s, &ones, 0.91);
        let per_stop = fit_sigma_map(&e, &s, &w, 0.92);
        let (_, epoch_fit_stops) = coverage(&per_epoch, &e, &s, &w);
        let (_, stop_fit_stops) = coverage(&per_stop, &e, &s, &w);
        let (e1, e2) = coverage(&per_stop, &e, &s, &ones);
        assert!(epoch_fit_stops < 0.92, "{epoch_fit_stops}");
        assert!(stop_fit_stops >= 0.92, "{stop_fit_stops}");
        assert!(e2 >= BAR_2SIGMA && e1 <= BAR_1SIGMA_MAX, "{e1} {e2}");
    }
}
