//! An untrained, deterministic model for unit tests: the daemon's logic (checks,
//! bookkeeping, status mapping, wire echo) must not depend on the quality of the
//! built-in weights. `tests/e2e.rs` has the same helper for a model file.

use ghnet_models::head::Head;
use ghnet_models::params::ParamSet;
use ghnet_models::weights::FORMAT;
use ghnet_models::{Arch, Model, ModelMeta};
use rand::SeedableRng;

pub(crate) fn untrained(name: &str) -> Model {
    let arch = Arch::tiny(3);
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let params = ParamSet::init(&arch, &mut rng);
    let meta = ModelMeta {
        format: FORMAT.into(),
        name: name.into(),
        architecture: arch,
        activation: "gelu_tanh".into(),
        head: Head::Residual {
            range_deg: [0.0, 360.0],
        },
        input_scale_mps: 5.0,
        heading_range_deg: [0.0, 360.0],
        sigma_scale: 1.0,
        training_data: serde_json::Value::Null,
        training: serde_json::Value::Null,
        metrics: serde_json::Value::Null,
    };
    Model::new(params, meta)
}
