//! The model unit tests run against. The daemon's logic (checks, bookkeeping, status
//! mapping, wire echo) must not depend on how good the weights are, so tests assert
//! only model-independent facts and accept `Ok` or `LowSpeed` for valid input.
//! `paper-s1` is the smaller built-in; `tests/e2e.rs` uses it too.

use ghnet_inference::Model;

/// Built-in model used by the daemon's tests.
pub(crate) const TEST_MODEL: &str = "paper-s1";

pub(crate) fn load() -> Model {
    Model::builtin(TEST_MODEL).expect("built-in test model")
}
