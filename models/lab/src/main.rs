//! `ghnet`: simulate, train, evaluate, export and run GHNet models from the command line.
//!
//! A thin layer over the `ghnet_inference` library; every subcommand's `--help` documents it.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

use ghnet_inference::simd::Kernel;
use ghnet_inference::{Model, Platform, DEFAULT_MODEL};
use ghnet_lab::make::{self, Recipe};
use ghnet_lab::sim::{self, RealisticParams, S1Params};
use ghnet_lab::temporal::MapName;
use ghnet_lab::{receiver_log, replay};

#[derive(Parser)]
#[command(
    name = "ghnet",
    version,
    about = "GHNet: GNSS heading from velocity, on faer"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant)] // parsed once
enum Cmd {
    /// Write a simulated data set as CSV (seeded, reproducible).
    Simulate {
        #[command(subcommand)]
        which: SimCmd,
    },
    /// Train a model from a shipped recipe (`paper-s1`, `ghnet-epoch`, `ghnet-temporal`,
    /// which also tunes and writes `kf`), or on your own logs with `--data`.
    Train {
        /// Recipe name.
        #[arg(long, required_unless_present = "data", conflicts_with = "data")]
        recipe: Option<String>,
        /// CSV log(s) with `truth_heading_deg` (see `ghnet_lab::logs` for the columns):
        /// trains a temporal model, the last 20% of each track (by time) for validation.
        #[arg(long)]
        data: Vec<PathBuf>,
        /// With `--data`: start from this model (fine-tune) instead of random weights.
        #[arg(long, requires = "data")]
        init: Option<String>,
        /// With `--data`: train a per-epoch model restricted to headings in `LO,HI`
        /// degrees, the paper's own protocol (its best result came from 0–90°).
        #[arg(long, requires = "data", value_parser = parse_range)]
        heading_range: Option<(f32, f32)>,
        /// Output safetensors file (default: `models/inference/weights/<recipe>.safetensors`).
        #[arg(long, required_unless_present = "recipe")]
        output: Option<PathBuf>,
        /// Override the recipe's seed for initialisation, shuffling and dropout.
        #[arg(long)]
        seed: Option<u64>,
        /// Override the recipe's maximum epochs.
        #[arg(long)]
        epochs: Option<usize>,
        /// What carries the receivers of `--data`: `auto` decides online, `car` never
        /// turns in place, `robot` turns in place; recorded in the model as its sources'
        /// default.
        #[arg(long, value_parser = parse_platform)]
        platform: Option<Platform>,
        /// Temporal recipes: JSON merged into the recipe's training configuration, for
        /// experiments, e.g. `{"lr": 5e-4, "modes": {"a_max": 6}}`.
        #[arg(long)]
        config: Option<String>,
        /// Hide the progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Evaluate a model on its held-out data (per-speed-bin tables, σ calibration, plot),
    /// or on your own log with `--data` (tables per speed band against atan2 and `kf`).
    Eval {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
        /// CSV log with `truth_heading_deg`: tables on it instead of the held-out data.
        #[arg(long)]
        data: Option<PathBuf>,
        /// The Kalman filter of the tables: a model name or path (default: the built-in
        /// `kf`), or `tuned`: a `kf` tuned on the `--data` log itself by grid search over
        /// its q and σ_v against the log's truth, the strongest a Kalman filter can do
        /// there (an oracle: the model under test never sees the truth).
        #[arg(long)]
        kf: Option<String>,
        /// With a stateful model: also plot heading against time (truth, atan2, kf, the
        /// model ±σ) of the first track to this SVG file.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Directory for `<name>.md`, `<name>.csv`, `<name>.json` and `<name>.svg`;
        /// without it the Markdown table goes to stdout.
        #[arg(long)]
        out_dir: Option<PathBuf>,
        /// What carries the receiver (`auto`, `car`, `robot`); default: the model's own.
        #[arg(long, value_parser = parse_platform)]
        platform: Option<Platform>,
    },
    /// Answer every row of a CSV log with heading, σ and status.
    Infer {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
        /// Input: CSV with `v_north` and `v_east` columns (m/s), or a receiver log
        /// (u-blox UBX, NMEA, gpsd JSON), one row per epoch with the receiver's own
        /// course beside ghnet's heading.
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (input columns plus heading_deg, heading_std_deg, status).
        #[arg(long)]
        output: PathBuf,
        /// Input format; detected when not given (CSV when its header names v_north).
        #[arg(long, value_enum)]
        format: Option<receiver_log::InputFormat>,
        /// What carries the receiver (`auto`, `car`, `robot`); default: the model's own.
        #[arg(long, value_parser = parse_platform)]
        platform: Option<Platform>,
    },
    /// Refit the σ maps of a temporal model on the training and validation tracks of
    /// the recipe in its metadata (headings unchanged): what training does last.
    Calibrate {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
        /// Output file.
        #[arg(long)]
        output: PathBuf,
        /// Refit only these maps (comma-separated, named as in `ghnet info`'s
        /// `sigma_map`) and keep the others; all when absent.
        #[arg(long, value_enum, value_delimiter = ',')]
        maps: Vec<MapName>,
    },
    /// Recompute the held-out metrics a temporal model stores (its recipe's test
    /// tracks, against the shipped kf) and write the model with them, weights
    /// unchanged: after a rule change moves what the shipped network streams.
    Restamp {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
        /// Output file (the shipped one: `models/inference/weights/<name>.safetensors`).
        #[arg(long)]
        output: PathBuf,
    },
    /// Write a model (built-in or file) to a safetensors file.
    Export {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
        /// Output file.
        #[arg(long)]
        output: PathBuf,
    },
    /// Print a model's metadata as JSON.
    Info {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
    },
    /// Measure inference speed in one run: batch-256 throughput and single-sample latency
    /// of the network and of the predictor, GELU throughput, and this core's peak FMA rate
    /// (GFLOP/s are 2 per multiply-add of the unpadded folded network, against that peak).
    /// Single-threaded; run on a quiet machine for numbers worth quoting.
    Bench {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
        /// Kernel for the network and GELU (the peak loop always uses the widest).
        #[arg(long, value_enum, default_value_t = KernelArg::Auto)]
        kernel: KernelArg,
        /// Seconds spent on each measurement.
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// Print one JSON object instead of a Markdown table.
        #[arg(long)]
        json: bool,
    },
    /// Print the raw network outputs for velocities read from standard input, one
    /// `v_north v_east` pair (m/s, separated by spaces or a comma) per line; for checking
    /// other runtimes (benches/ort_reference.py) against this one.
    Forward {
        /// Built-in model name or safetensors path.
        #[arg(long, default_value = DEFAULT_MODEL)]
        model: String,
    },
}

/// `--kernel` values.
#[derive(Clone, Copy, clap::ValueEnum)]
enum KernelArg {
    /// The widest kernel this CPU supports.
    Auto,
    /// AVX-512F.
    Avx512,
    /// AVX2 with FMA.
    Avx2,
    /// Plain Rust (compiler-vectorised).
    Portable,
}

impl KernelArg {
    fn resolve(self) -> Result<Kernel> {
        let k = match self {
            KernelArg::Auto => return Ok(Kernel::detect()),
            KernelArg::Avx512 => Kernel::Avx512,
            KernelArg::Avx2 => Kernel::Avx2Fma,
            KernelArg::Portable => Kernel::Portable,
        };
        if !k.is_available() {
            bail!("this CPU cannot run the {k} kernel");
        }
        Ok(k)
    }
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant)] // parsed once
enum SimCmd {
    /// The paper's S1 protocol: speed 0..3.5 step 0.1, heading 0..90 step 0.5, ten draws.
    S1 {
        #[command(flatten)]
        params: S1Params,
        /// Seed of noise and split.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output CSV.
        #[arg(long)]
        output: PathBuf,
    },
    /// Whole drives: cars that park, reverse and stop at junctions, and platforms that
    /// turn in place, seen by 1–10 Hz receivers (see `ghnet_lab::drive`).
    Drive {
        #[command(flatten)]
        params: ghnet_lab::drive::DriveParams,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output CSV (the log format `ghnet train --data` and `ghnet eval --data` read).
        #[arg(long)]
        output: PathBuf,
    },
    /// A real log seen by a noisier receiver: receiver noise added to its velocities
    /// (the drive simulator's model, a correlated and a white part per axis), its
    /// truth and time kept (see `ghnet_lab::noisy`).
    Noisy {
        /// Input log (CSV with truth, as `ghnet eval --data` reads).
        #[arg(long)]
        data: PathBuf,
        /// Noise σ per axis, m/s.
        #[arg(long)]
        sigma: f32,
        /// Correlation time of the noise's correlated part, s.
        #[arg(long, default_value_t = 2.0)]
        corr_s: f64,
        /// Drop the log's speed accuracy (a receiver that reports none); kept
        /// otherwise, so that it understates the added noise.
        #[arg(long)]
        no_acc: bool,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output CSV.
        #[arg(long)]
        output: PathBuf,
    },
    /// A realistic consumer receiver over the full circle.
    Realistic {
        #[command(flatten)]
        params: RealisticParams,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output CSV.
        #[arg(long)]
        output: PathBuf,
    },
}

mod bench;
mod commands;

/// `LO,HI` in degrees.
fn parse_range(s: &str) -> std::result::Result<(f32, f32), String> {
    let (a, b) = s.split_once(',').ok_or("expected LO,HI")?;
    let p = |x: &str| x.trim().parse::<f32>().map_err(|e| e.to_string());
    Ok((p(a)?, p(b)?))
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load(model: &str) -> Result<Arc<Model>> {
    Ok(Arc::new(Model::from_name_or_path(model)?))
}

/// `model`, with `platform` as its sources' default when given.
fn load_on(model: &str, platform: Option<Platform>) -> Result<Arc<Model>> {
    let m = Model::from_name_or_path(model)?;
    Ok(Arc::new(match platform {
        Some(p) => m.with_platform(p),
        None => m,
    }))
}

fn parse_platform(s: &str) -> Result<Platform, String> {
    s.parse()
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Simulate { which } => simulate(which),
        c @ Cmd::Train { .. } => train(c),
        Cmd::Eval {
            model,
            data,
            kf,
            plot,
            out_dir,
            platform,
        } => {
            let m = load_on(&model, platform)?;
            if data.is_some() || m.is_stateful() {
                commands::eval_stream(&m, data.as_deref(), kf.as_deref(), plot.as_deref())
            } else {
                commands::eval_epoch(&m, out_dir)
            }
        }
        Cmd::Infer {
            model,
            input,
            output,
            format,
            platform,
        } => infer(&load_on(&model, platform)?, &input, &output, format),
        Cmd::Calibrate {
            model,
            output,
            maps,
        } => {
            let maps = if maps.is_empty() {
                MapName::ALL.to_vec()
            } else {
                maps
            };
            make::temporal::calibrate_recipe_model(&model, &output, &maps)
        }
        Cmd::Restamp { model, output } => make::temporal::restamp_recipe_model(&model, &output),
        Cmd::Export { model, output } => {
            let m = load(&model)?;
            std::fs::write(&output, m.to_safetensors())
                .with_context(|| format!("writing {}", output.display()))?;
            eprintln!("wrote {} ({}) to {}", m.name(), m.id(), output.display());
            Ok(())
        }
        Cmd::Info { model } => {
            println!("{}", serde_json::to_string_pretty(load(&model)?.meta())?);
            Ok(())
        }
        Cmd::Bench {
            model,
            kernel,
            seconds,
            json,
        } => {
            let r = bench::run(&load(&model)?, kernel.resolve()?, seconds);
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!("{}", r.to_markdown());
            }
            Ok(())
        }
        Cmd::Forward { model } => {
            let m = load(&model)?;
            forward_stdin(&m)
        }
    }
}

/// `ghnet train ...`: a shipped recipe, or a temporal model on the user's logs.
fn train(cmd: Cmd) -> Result<()> {
    let Cmd::Train {
        recipe,
        data,
        init,
        heading_range,
        output,
        seed,
        epochs,
        config,
        quiet,
        platform,
    } = cmd
    else {
        unreachable!("called with Cmd::Train")
    };
    if !data.is_empty() {
        let output = output.context("--output is required with --data")?;
        return make::own::train_data(
            &data,
            &output,
            init.as_deref(),
            heading_range,
            seed,
            epochs,
            platform,
        );
    }
    // clap's `requires = "data"` does not fire for an empty `Vec`: check here, or a
    // recipe run would silently ignore them.
    if init.is_some() || heading_range.is_some() {
        bail!("--init and --heading-range need --data (a recipe trains from scratch)");
    }
    let recipe = recipe.context("--recipe or --data")?;
    let output =
        output.unwrap_or_else(|| format!("models/inference/weights/{recipe}.safetensors").into());
    if recipe.starts_with("ghnet-temporal") {
        return make::temporal::train_temporal_recipe(
            &recipe,
            &output,
            seed,
            epochs,
            config.as_deref(),
        );
    }
    let mut r = Recipe::named(&recipe).with_context(|| {
            format!("unknown recipe `{recipe}` (known: paper-s1, ghnet-epoch, ghnet-temporal, ghnet-temporal-car, ghnet-temporal-tip)")
        })?;
    r.train.seed = seed.unwrap_or(r.train.seed);
    r.train.epochs = epochs.unwrap_or(r.train.epochs);
    make::train_recipe(&r, &output, quiet)
}

/// `ghnet simulate ...`.
fn simulate(which: SimCmd) -> Result<()> {
    let (samples, output) = match which {
        SimCmd::Drive {
            params,
            seed,
            output,
        } => {
            let tracks = ghnet_lab::drive::simulate(&params, seed);
            ghnet_lab::logs::write_tracks_csv(&output, &tracks)?;
            let n: usize = tracks.iter().map(|t| t.samples.len()).sum();
            eprintln!(
                "wrote {} tracks, {n} epochs to {}",
                tracks.len(),
                output.display()
            );
            return Ok(());
        }
        SimCmd::Noisy {
            data,
            sigma,
            corr_s,
            no_acc,
            seed,
            output,
        } => {
            if !(sigma.is_finite() && sigma >= 0.0 && corr_s.is_finite() && corr_s >= 0.0) {
                bail!("--sigma and --corr-s must be finite and not negative");
            }
            let mut tracks = ghnet_lab::logs::read_truth_csv(&data)?;
            let noise = ghnet_lab::noisy::ReceiverNoise {
                sigma,
                corr_s,
                drop_acc: no_acc,
            };
            ghnet_lab::noisy::add_receiver_noise(&mut tracks, noise, seed);
            ghnet_lab::logs::write_log_csv(&output, &tracks)?;
            let n: usize = tracks.iter().map(|t| t.len()).sum();
            eprintln!("wrote {n} epochs to {}", output.display());
            return Ok(());
        }
        SimCmd::S1 {
            params,
            seed,
            output,
        } => (sim::simulate_s1(&params, seed), output),
        SimCmd::Realistic {
            params,
            seed,
            output,
        } => (sim::simulate_realistic(&params, seed), output),
    };
    sim::write_csv(&output, &samples).with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {} samples to {}", samples.len(), output.display());
    Ok(())
}

/// `ghnet infer`: answer every row of a CSV log.
fn infer(
    model: &Arc<Model>,
    input: &std::path::Path,
    output: &std::path::Path,
    format: Option<receiver_log::InputFormat>,
) -> Result<()> {
    let open =
        || File::open(input).with_context(|| format!("cannot open input {}", input.display()));
    // The first 64 KiB tell a CSV header from a receiver log; a CSV then streams.
    let mut head = Vec::new();
    open()?.take(1 << 16).read_to_end(&mut head)?;
    let receiver = match receiver_log::convert(&head, format)? {
        None => None,
        Some(_) => {
            let bytes =
                std::fs::read(input).with_context(|| format!("reading {}", input.display()))?;
            receiver_log::convert(&bytes, format)?
        }
    };
    let inp: Box<dyn Read> = match &receiver {
        Some(c) => Box::new(std::io::Cursor::new(c.csv.as_slice())),
        None => Box::new(BufReader::with_capacity(1 << 16, open()?)),
    };
    replay::refuse_same_file(&open()?, output)?;
    let out = File::create(output)
        .with_context(|| format!("cannot create output {}", output.display()))?;
    let out = BufWriter::with_capacity(1 << 16, out);
    // Every model through ghnetd's per-source rules, so a log answers here as it
    // would live (a per-epoch model has no history, but time going backwards is
    // `invalid` for it too).
    let s = replay::run(&mut replay::Streams::new(model.clone()), inp, out)
        .with_context(|| format!("{}", input.display()))?;
    if let Some(c) = &receiver {
        eprintln!("{} log: {}", c.format, c.stats);
    }
    let first = s
        .first_invalid_row
        .map(|r| format!(" (first at row {r})"))
        .unwrap_or_default();
    eprintln!(
        "{} rows, {} invalid{first} -> {}",
        s.rows,
        s.invalid,
        output.display()
    );
    Ok(())
}

/// Raw outputs for `v_north v_east` lines on stdin, one output line each.
fn forward_stdin(m: &Model) -> Result<()> {
    use std::io::{BufRead, Write};
    let Some(ghnet_inference::model::Engine::Epoch(net)) = Some(m.engine()) else {
        bail!(
            "forward prints a per-epoch network's outputs; {} is not one",
            m.name()
        );
    };
    let mut scratch = net.scratch(1);
    let mut y = vec![0.0f32; net.outputs()];
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    for (i, line) in std::io::stdin().lock().lines().enumerate() {
        let line = line?;
        let v: Vec<f32> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(str::parse)
            .collect::<Result<_, _>>()
            .with_context(|| format!("line {}: `{line}`", i + 1))?;
        let [vn, ve] = v[..] else {
            bail!("line {}: expected `v_north v_east`, got `{line}`", i + 1);
        };
        let x = ghnet_inference::head::scale_input(vn, ve, m.meta().input_scale_mps);
        net.forward_one(&x, &mut y, &mut scratch);
        let fields: Vec<String> = y.iter().map(|v| format!("{v:e}")).collect();
        writeln!(out, "{}", fields.join(" "))?;
    }
    out.flush()?;
    Ok(())
}
