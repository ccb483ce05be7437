//! Property-based fuzzing of every parser in ghnet-inference (proptest, modest case
//! counts so CI stays at a few seconds per target), plus one malformed-CSV run of the
//! real `ghnet infer` binary.
//!
//! - the CSV path of `ghnet infer` (`replay::run`): arbitrary bytes, arbitrary rows;
//! - the safetensors model loader (`weights::from_bytes`): arbitrary bytes, and
//!   mutations (byte flips, truncation) of a valid file;
//! - the model metadata (`ModelMeta`, JSON in the safetensors header): arbitrary
//!   values for each key, arbitrary architectures.
//!
//! Each must give `Ok` or an error value, never a panic or an abort.

use std::collections::HashMap;
use std::sync::{Arc, OnceLock};

use ghnet_inference::weights::{self, WeightsError};
use ghnet_inference::{Model, Predictor};
use ghnet_lab::replay;
use proptest::prelude::*;

fn model() -> Arc<Model> {
    static M: OnceLock<Arc<Model>> = OnceLock::new();
    M.get_or_init(|| Arc::new(Model::builtin(ghnet_inference::DEFAULT_MODEL).unwrap()))
        .clone()
}

fn valid_file() -> &'static [u8] {
    static B: OnceLock<Vec<u8>> = OnceLock::new();
    B.get_or_init(|| model().to_safetensors())
}

/// The metadata of the valid file as the string map safetensors stores.
fn valid_metadata() -> HashMap<String, String> {
    let (_, header) = safetensors::SafeTensors::read_metadata(valid_file()).unwrap();
    header.metadata().clone().unwrap()
}

/// The valid file's tensors with `md` as metadata.
fn with_metadata(md: HashMap<String, String>) -> Vec<u8> {
    let st = safetensors::SafeTensors::deserialize(valid_file()).unwrap();
    safetensors::serialize(st.tensors(), Some(md)).unwrap()
}

fn infer_bytes(input: &[u8]) -> Result<(Vec<u8>, replay::InferSummary), replay::InferError> {
    let mut out = Vec::new();
    let s = replay::run(&mut Predictor::new(model()), input, &mut out)?;
    Ok((out, s))
}

/// An error is one line (what the daemon and the CLI print).
fn one_line(e: &impl std::fmt::Display) -> bool {
    let s = e.to_string();
    !s.is_empty() && !s.contains('\n')
}

/// A CSV field: numbers, the special float spellings, junk, quotes and separators.
fn field() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f32>().prop_map(|v| v.to_string()),
        any::<u32>().prop_map(|b| f32::from_bits(b).to_string()),
        (-200.0f32..200.0).prop_map(|v| format!("{v}")),
        Just(String::new()),
        Just("NaN".to_owned()),
        Just("-inf".to_owned()),
        Just(" 1.5 ".to_owned()),
        "[ -~]{0,12}",
        "\"[a-z,\n]{0,6}\"",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Arbitrary bytes after a valid header: `Ok`, every row answered, never a panic.
    #[test]
    fn csv_arbitrary_bytes_after_a_header(body in proptest::collection::vec(any::<u8>(), 0..600)) {
        let mut input = b"t,v_north,v_east,speed_acc\n".to_vec();
        input.extend_from_slice(&body);
        let (out, s) = infer_bytes(&input).unwrap();
        prop_assert!(s.invalid <= s.rows);
        prop_assert_eq!(s.first_invalid_row.is_some(), s.invalid > 0);
        prop_assert!(out.starts_with(b"t,v_north,v_east,speed_acc,heading_deg,heading_std_deg,status\n"));
    }

    /// Arbitrary bytes with no header guarantee: `Ok` or a one-line error.
    #[test]
    fn csv_arbitrary_bytes(input in proptest::collection::vec(any::<u8>(), 0..400)) {
        match infer_bytes(&input) {
            Ok((_, s)) => prop_assert!(s.invalid <= s.rows),
            Err(e) => prop_assert!(one_line(&e), "{}", e),
        }
    }

    /// Rows of arbitrary fields: one output row per input row, `invalid` exactly when
    /// the velocity does not parse to finite components within 100 m/s.
    #[test]
    fn csv_rows_of_arbitrary_fields(rows in proptest::collection::vec((field(), field()), 1..40)) {
        let mut input = String::from("v_north,v_east\n");
        let mut want_invalid = 0u64;
        let mut n = 0u64;
        for (a, b) in &rows {
            // Quoted fields with newlines or commas are tested above; keep one line per
            // row here so rows can be counted.
            if a.contains(['\n', '"', ',', '\r']) || b.contains(['\n', '"', ',', '\r']) || (a.is_empty() && b.is_empty()) {
                continue;
            }
            input.push_str(&format!("{a},{b}\n"));
            n += 1;
            let parse = |s: &str| s.trim().parse::<f32>().unwrap_or(f32::NAN);
            let (vn, ve) = (parse(a), parse(b));
            if !(vn.is_finite() && ve.is_finite() && vn.hypot(ve) <= 100.0) {
                want_invalid += 1;
            }
        }
        let (out, s) = infer_bytes(input.as_bytes()).unwrap();
        prop_assert_eq!(s.rows, n, "{}", input);
        prop_assert_eq!(s.invalid, want_invalid, "{}", input);
        prop_assert_eq!(out.iter().filter(|&&b| b == b'\n').count() as u64, n + 1);
    }

    /// Arbitrary bytes are never a model.
    #[test]
    fn model_loader_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let e = weights::from_bytes(&bytes).unwrap_err();
        prop_assert!(one_line(&e), "{}", e);
    }

    /// A safetensors header claiming arbitrary sizes and offsets.
    #[test]
    fn model_loader_arbitrary_header(n in any::<u64>(), json in "[ -~]{0,80}", tail in proptest::collection::vec(any::<u8>(), 0..64)) {
        for len in [n, json.len() as u64] {
            let mut bytes = len.to_le_bytes().to_vec();
            bytes.extend_from_slice(json.as_bytes());
            bytes.extend_from_slice(&tail);
            if let Err(e) = weights::from_bytes(&bytes) {
                prop_assert!(one_line(&e), "{}", e);
            }
        }
    }

    /// Byte flips anywhere in a valid file: `Ok` (a changed weight) or an error; a
    /// flip in the tensor data that makes a weight NaN/inf names that tensor.
    #[test]
    fn model_loader_mutated_valid_file(flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4)) {
        let mut bytes = valid_file().to_vec();
        let header_end = 8 + u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        let mut in_data = true;
        for (i, x) in &flips {
            let at = i.index(bytes.len());
            in_data &= at >= header_end;
            bytes[at] ^= x | 1;
        }
        // Flips inside the header may still parse (a changed metadata string); flips
        // in the data only change weights.
        match weights::from_bytes(&bytes) {
            Ok(_) => {}
            Err(e) => {
                prop_assert!(one_line(&e), "{}", e);
                if in_data {
                    let named = matches!(e, WeightsError::NonFinite { ref name } if !name.is_empty());
                    prop_assert!(named, "data flips name a tensor: {}", e);
                }
            }
        }
    }

    /// Truncated valid files.
    #[test]
    fn model_loader_truncated_valid_file(cut in any::<prop::sample::Index>()) {
        let bytes = valid_file();
        let e = weights::from_bytes(&bytes[..cut.index(bytes.len())]).unwrap_err();
        prop_assert!(one_line(&e), "{}", e);
    }

    /// Each metadata key replaced by an arbitrary string, JSON value or number:
    /// `Ok` or an error naming a key; never a panic.
    #[test]
    fn model_metadata_arbitrary_values(key in prop::sample::select(vec![
        "format", "name", "architecture", "activation", "head", "input_scale_mps",
        "heading_range_deg", "sigma_scale", "accuracy_sigma_scale", "training_data",
        "training", "metrics",
    ]), value in prop_oneof![
        "[ -~]{0,40}",
        any::<f64>().prop_map(|v| v.to_string()),
        Just("null".to_owned()),
        Just("{}".to_owned()),
        Just("[]".to_owned()),
        Just("{\"kind\":\"residual\",\"range_deg\":[0,360]}".to_owned()),
        Just("{\"kind\":\"residual\",\"range_deg\":[1e30,-5]}".to_owned()),
        Just("{\"kind\":\"angle\",\"centre_deg\":1e39,\"half_range_deg\":-5}".to_owned()),
    ], remove in any::<bool>()) {
        let mut md = valid_metadata();
        if remove {
            md.remove(key);
        } else {
            md.insert(key.to_owned(), value);
        }
        match weights::from_bytes(&with_metadata(md)) {
            Ok((params, meta)) => {
                // What loads must also run.
                let m = Arc::new(Model::new(params, meta));
                let mut p = Predictor::new(m);
                let _ = p.predict_with_accuracy(3.0, 4.0, 0.1);
                let _ = p.predict(0.0, 0.0);
            }
            Err(e) => prop_assert!(one_line(&e), "{}", e),
        }
    }

    /// Arbitrary architectures in the metadata, including absurd sizes: an error (the
    /// tensors do not match) and never an allocation of the claimed size or a panic.
    #[test]
    fn model_metadata_arbitrary_architecture(
        input in prop_oneof![Just(2usize), any::<usize>(), 0usize..4],
        conv in proptest::collection::vec(prop_oneof![1usize..300, any::<usize>()], 0..8),
        fc in proptest::collection::vec(prop_oneof![1usize..100, any::<usize>()], 0..5),
        output in prop_oneof![2usize..5, any::<usize>()],
    ) {
        let arch = serde_json::json!({"input": input, "conv": conv, "fc": fc, "output": output});
        let mut md = valid_metadata();
        md.insert("architecture".into(), arch.to_string());
        let same = arch == serde_json::to_value(&model().meta().architecture).unwrap();
        match weights::from_bytes(&with_metadata(md)) {
            Ok(_) => prop_assert!(same),
            Err(e) => prop_assert!(one_line(&e), "{}", e),
        }
    }

    /// ModelMeta's JSON form (what `ghnet info` prints) from arbitrary JSON: `Ok` or
    /// `Err`, and what parses serialises back.
    #[test]
    fn model_meta_json(json in prop_oneof![
        "[ -~]{0,120}",
        Just(serde_json::to_string(model().meta()).unwrap()),
    ], cut in any::<prop::sample::Index>()) {
        let prefix: String = json.chars().take(cut.index(json.len() + 1)).collect();
        for text in [json.as_str(), prefix.as_str()] {
            if let Ok(meta) = serde_json::from_str::<ghnet_inference::ModelMeta>(text) {
                prop_assert!(serde_json::to_string(&meta).is_ok());
            }
        }
    }
}

/// The real `ghnet infer` on a malformed CSV: bad rows are answered `invalid` and
/// counted on stderr with the first one's row, exit 0; a wrong header is a one-line
/// error and a non-zero exit; no panic either way.
#[test]
fn ghnet_infer_binary_on_malformed_csv() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.csv");
    let output = dir.path().join("out.csv");
    std::fs::write(
        &input,
        b"t , v_north , v_east\r\n1,3,4\r\n\r\n2,NaN,4\r\n3,north,1\r\n4\r\n5,\xff,1\r\n6,3,4,extra\r\n",
    )
    .unwrap();
    let run = |input: &std::path::Path| {
        std::process::Command::new(env!("CARGO_BIN_EXE_ghnet"))
            .args(["infer", "--input"])
            .arg(input)
            .arg("--output")
            .arg(&output)
            .output()
            .unwrap()
    };
    let out = run(&input);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("6 rows, 5 invalid (first at row 2)"),
        "{stderr}"
    );
    let text = std::fs::read(&output).unwrap();
    let text = String::from_utf8_lossy(&text);
    let status: Vec<&str> = text
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap())
        .collect();
    assert_eq!(status.len(), 6, "{text}");
    // The long row (`6,3,4,extra`) too: its fields no longer match the header.
    assert_eq!(status[1..6], ["invalid"; 5], "{text}");

    std::fs::write(&input, "north,east\n1,2\n").unwrap();
    let out = run(&input);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    assert!(
        stderr.contains("`v_north`") && stderr.contains("line 1"),
        "{stderr}"
    );
    assert!(
        stderr.contains(&*input.to_string_lossy()),
        "names the file: {stderr}"
    );
}
