//! GNSS velocity simulation: the paper's S1 grid and a realistic consumer receiver.
//!
//! Both generators are seeded ([`ChaCha8Rng::seed_from_u64`](rand::SeedableRng::seed_from_u64)) so that a data set is
//! reproduced from `(parameters, seed)` alone; the same inputs give byte-identical CSV.
//! Conventions: velocities in NED (north, east, down) in m/s; heading ψ in degrees
//! clockwise from true north, ψ = atan2(v_E, v_N) wrapped to [0, 360).
//!
//! * [`simulate_s1`] follows the GHNet paper's S1 protocol exactly (a discrete grid of
//!   speeds and headings in 0..90°, white noise σ = 0.01 m/s). It is what the paper
//!   trained on, and its prior is what [`crate::bayes::BayesS1`] integrates over.
//! * [`simulate_realistic`] models what a consumer receiver actually delivers: tracks
//!   of stops, slow manoeuvres, turns and straight runs at 5–10 Hz, over the full
//!   circle, with varying and time-correlated noise, mm/s quantisation, course freezing
//!   at low speed, glitches and a rough reported speed accuracy. A model that is only
//!   good on S1 will show it here.

mod realistic;
mod s1;
mod sample;

pub use realistic::{simulate_realistic, RealisticParams};
pub use s1::{simulate_s1, S1Params};
pub(crate) use sample::{
    correlated_step, log_uniform, uniform, NOISE_CORRELATED_SHARE, NOISE_WHITE_SHARE,
};
pub use sample::{read_csv, spread_velocities, write_csv, Sample, SimError, Split};

#[cfg(test)]
mod tests {
    use super::sample::heading_deg;
    use super::*;
    use std::collections::{HashMap, HashSet};

    fn csv_bytes(samples: &[Sample]) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.csv");
        write_csv(&path, samples).unwrap();
        std::fs::read(path).unwrap()
    }

    fn small_realistic() -> RealisticParams {
        RealisticParams {
            samples: 20_000,
            ..RealisticParams::default()
        }
    }

    /// Both parameter sets flattened into one command, as a CLI may do.
    #[derive(clap::Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        s1: S1Params,
        #[command(flatten)]
        realistic: RealisticParams,
    }

    #[test]
    fn clap_defaults_match_default_and_flags_do_not_clash() {
        use clap::{CommandFactory, Parser};
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from(["x"]).unwrap();
        assert_eq!(cli.s1, S1Params::default());
        assert_eq!(cli.realistic, RealisticParams::default());
        let cli = Cli::try_parse_from([
            "x",
            "--sigma",
            "0.05",
            "--samples",
            "10",
            "--test-fraction",
            "0.3",
            "--realistic-test-fraction",
            "0.1",
        ])
        .unwrap();
        assert_eq!((cli.s1.sigma, cli.realistic.samples), (0.05, 10));
        assert_eq!(
            (cli.s1.test_fraction, cli.realistic.test_fraction),
            (0.3, 0.1)
        );
    }

    #[test]
    fn simulations_are_deterministic_per_seed() {
        let s1 = S1Params {
            speed_max: 0.5,
            heading_max: 10.0,
            ..S1Params::default()
        };
        let realistic = RealisticParams {
            samples: 5_000,
            ..RealisticParams::default()
        };
        let runs: [&dyn Fn(u64) -> Vec<u8>; 2] =
            [&|seed| csv_bytes(&simulate_s1(&s1, seed)), &|seed| {
                csv_bytes(&simulate_realistic(&realistic, seed))
            }];
        for run in runs {
            let a = run(7);
            assert_eq!(a, run(7));
            assert_ne!(a, run(8));
        }
    }

    #[test]
    fn csv_round_trips_including_nan() {
        let s = simulate_realistic(&small_realistic(), 3);
        assert!(s.iter().any(|x| x.speed_acc.is_nan()));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.csv");
        write_csv(&path, &s).unwrap();
        let header = std::fs::read_to_string(&path).unwrap();
        assert!(header.starts_with(
            "t_s,track,v_north,v_east,v_down,speed_acc,true_heading_deg,true_speed,sigma_v,split\n"
        ));
        let back = read_csv(&path).unwrap();
        assert_eq!(back.len(), s.len());
        for (a, b) in s.iter().zip(&back) {
            // NaN != NaN, so compare the bit-exact CSV-relevant fields one by one.
            assert_eq!(a.speed_acc.is_nan(), b.speed_acc.is_nan());
            let mut a2 = a.clone();
            let mut b2 = b.clone();
            a2.speed_acc = 0.0;
            b2.speed_acc = 0.0;
            assert_eq!(a2, b2);
        }
    }

    #[test]
    fn s1_count_and_grid_are_exact() {
        let p = S1Params::default();
        let s = simulate_s1(&p, 0);
        assert_eq!(s.len(), 36 * 181 * 10);
        let mut cells: HashMap<(u32, u32), usize> = HashMap::new();
        for x in &s {
            // Speeds are decimal multiples of 0.1 stored as the nearest f32.
            let i = (x.true_speed as f64 / 0.1).round();
            assert_eq!(x.true_speed, (i * 0.1) as f32);
            // Headings are multiples of 0.5, exact in binary.
            let j = x.true_heading_deg * 2.0;
            assert_eq!(j, j.round());
            *cells.entry((i as u32, j as u32)).or_default() += 1;
        }
        assert_eq!(cells.len(), 36 * 181);
        assert!(cells.values().all(|&c| c == 10));
        let max_i = cells.keys().map(|k| k.0).max().unwrap();
        let max_j = cells.keys().map(|k| k.1).max().unwrap();
        assert_eq!((max_i, max_j), (35, 180));
        let n_test = s.iter().filter(|x| x.split == Split::Test).count();
        assert_eq!(n_test, (0.2 * s.len() as f64).round() as usize);
        assert!(s.iter().all(|x| x.split != Split::Val));
    }

    #[test]
    fn s1_noise_has_the_configured_sigma() {
        let p = S1Params::default();
        let s = simulate_s1(&p, 5);
        let n = s.len() as f64;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for x in &s {
            let (sin, cos) = (x.true_heading_deg as f64).to_radians().sin_cos();
            let e = x.v_north as f64 - x.true_speed as f64 * cos;
            let f = x.v_east as f64 - x.true_speed as f64 * sin;
            sum += e + f;
            sum2 += e * e + f * f;
        }
        let mean = sum / (2.0 * n);
        let sd = (sum2 / (2.0 * n)).sqrt();
        assert!(mean.abs() < 2e-4, "noise mean {mean}");
        assert!((sd - 0.01).abs() < 2e-4, "noise sd {sd}");
    }

    #[test]
    fn realistic_statistics_are_as_configured() {
        let p = RealisticParams {
            samples: 100_000,
            ..RealisticParams::default()
        };
        let s = simulate_realistic(&p, 11);
        assert_eq!(s.len(), p.samples);
        let n = s.len() as f64;
        let low = s.iter().filter(|x| x.true_speed < 3.0).count() as f64 / n;
        assert!(low > 0.6, "share below 3 m/s: {low}");
        let max_speed = s.iter().map(|x| x.true_speed).fold(0.0, f32::max);
        assert!(max_speed > 10.0, "max speed {max_speed}");
        let stopped = s.iter().filter(|x| x.true_speed == 0.0).count() as f64 / n;
        assert!(stopped > 0.02, "share at standstill {stopped}");

        let smin = s.iter().map(|x| x.sigma_v).fold(f32::INFINITY, f32::min);
        let smax = s.iter().map(|x| x.sigma_v).fold(0.0, f32::max);
        assert!((0.02 * 0.999..0.03).contains(&smin), "sigma min {smin}");
        assert!((0.35..=0.5 * 1.001).contains(&smax), "sigma max {smax}");

        // Glitches: a horizontal innovation of at least glitch_min far beyond 6σ.
        let mut glitches = 0;
        for x in &s {
            let (sin, cos) = (x.true_heading_deg as f64).to_radians().sin_cos();
            let e = (x.v_north as f64 - x.true_speed as f64 * cos)
                .hypot(x.v_east as f64 - x.true_speed as f64 * sin);
            if e > (6.0 * x.sigma_v as f64).max(1.5) {
                glitches += 1;
            }
        }
        let rate = glitches as f64 / n;
        assert!(rate > 0.5e-3 && rate < 1.5e-3, "glitch rate {rate}");

        // Headings cover the circle: every 45° sector holds a fair share.
        let mut sectors = [0usize; 8];
        for x in &s {
            sectors[(x.true_heading_deg / 45.0) as usize % 8] += 1;
        }
        assert!(sectors.iter().all(|&c| c as f64 > 0.05 * n), "{sectors:?}");

        // Quantised to mm/s.
        assert!(s.iter().all(|x| ((x.v_north as f64) * 1000.0
            - (x.v_north as f64 * 1000.0).round())
        .abs()
            < 1e-3));
        // Reported accuracy is within the configured factor of the true σ when known.
        for x in s.iter().filter(|x| !x.speed_acc.is_nan()) {
            let f = x.speed_acc / x.sigma_v;
            assert!((0.65..=1.55).contains(&f), "sAcc factor {f}");
        }
    }

    #[test]
    fn realistic_freezes_course_at_low_speed() {
        let p = RealisticParams {
            samples: 30_000,
            p_freeze_track: 1.0,
            p_glitch: 0.0,
            ..RealisticParams::default()
        };
        let s = simulate_realistic(&p, 4);
        // Within a track, consecutive slow measurements keep the previous direction.
        // Only after a first valid course in the track (before it there is nothing to
        // keep), and above 0.04 m/s so that mm/s quantisation moves the direction < 1°.
        let (mut slow_pairs, mut same_dir) = (0, 0);
        let mut had_course = false;
        for w in s.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if a.track != b.track {
                had_course = false;
                continue;
            }
            let mb = (b.v_north as f64).hypot(b.v_east as f64);
            let ma = (a.v_north as f64).hypot(a.v_east as f64);
            had_course |= ma >= 0.1;
            if had_course && mb < 0.09 && ma < 0.09 && mb > 0.04 && ma > 0.04 {
                slow_pairs += 1;
                let da = heading_deg(a.v_north as f64, a.v_east as f64);
                let db = heading_deg(b.v_north as f64, b.v_east as f64);
                let d = (da - db).rem_euclid(360.0);
                if d.min(360.0 - d) < 3.0 {
                    same_dir += 1;
                }
            }
        }
        assert!(slow_pairs > 100, "too few slow pairs: {slow_pairs}");
        assert_eq!(same_dir, slow_pairs);
    }

    #[test]
    fn realistic_splits_are_whole_tracks() {
        let s = simulate_realistic(&small_realistic(), 9);
        let mut split_of: HashMap<u32, Split> = HashMap::new();
        for x in &s {
            let e = split_of.entry(x.track).or_insert(x.split);
            assert_eq!(*e, x.split, "track {} spans splits", x.track);
        }
        let sets: Vec<HashSet<u32>> = [Split::Train, Split::Val, Split::Test]
            .iter()
            .map(|sp| {
                split_of
                    .iter()
                    .filter(|(_, v)| **v == *sp)
                    .map(|(k, _)| *k)
                    .collect()
            })
            .collect();
        assert!(sets.iter().all(|set| !set.is_empty()));
        let n = split_of.len() as f64;
        let test_share = sets[2].len() as f64 / n;
        assert!((test_share - 0.15).abs() < 0.05, "test share {test_share}");
    }
}
