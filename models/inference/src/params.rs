//! Named parameter tensors in PyTorch `state_dict` order, and the architecture they fill.
//!
//! All tensors live in one flat `Vec<f32>` so the optimiser can treat them as a single
//! vector, while each keeps its PyTorch name and shape (`conv{i}.weight` is `[out, in, 1]`,
//! `fc{i}.weight` is `[out, in]`, row-major like PyTorch). A row-major `[out, in]` block read
//! as a column-major faer matrix is `Wᵀ` (`in × out`), which is how [`ParamSet::matrix_t`]
//! hands it out without copying.

use serde::{Deserialize, Serialize};

/// Batch-norm epsilon, PyTorch's default, used by training and by folding.
pub const BN_EPS: f32 = 1e-5;

/// The layer sizes of a GHNet network.
///
/// The paper's Table I is `input 2 → conv 24, 48, 96, 192, 48 (kernel 1, each with batch norm
/// and GELU) → dropout → flatten → fc 60, 10, 5 → output`. We read the input `-1*1*2` as two
/// channels (v_N, v_E) of length one, so the first layer mixes both components; see
/// `models/README.md` for the parameter count this gives.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Arch {
    /// Input channels: 2 (v_N, v_E).
    pub input: usize,
    /// Output channels of the kernel-1 Conv1D layers.
    pub conv: Vec<usize>,
    /// Hidden fully connected sizes (no activation between them, as in the paper).
    pub fc: Vec<usize>,
    /// Network outputs; depends on the head (2 for `angle`, 3 for `residual`).
    pub output: usize,
    /// Epochs the fully connected head sees at once: 1 for the per-epoch models (the
    /// paper's), `W` for a temporal model, whose head flattens the last conv layer's
    /// features of the `W` most recent epochs (newest first), so `fc1` has
    /// `W·conv.last()` inputs. Absent in files of per-epoch models.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub window: usize,
}

fn one() -> usize {
    1
}

fn is_one(w: &usize) -> bool {
    *w == 1
}

impl Arch {
    /// Table I with `output` outputs.
    pub fn paper(output: usize) -> Self {
        Self {
            input: 2,
            conv: vec![24, 48, 96, 192, 48],
            fc: vec![60, 10, 5],
            output,
            window: 1,
        }
    }

    /// Table I over a causal window: `inputs` per-epoch features through the same five
    /// kernel-1 convolutions, then the fully connected 60, 10, 5 and `output` over the
    /// flattened features of the last `window` epochs.
    pub fn temporal(inputs: usize, window: usize, output: usize) -> Self {
        Self {
            input: inputs,
            window,
            ..Self::paper(output)
        }
    }

    /// A smaller network of the same shape, for quick tests.
    pub fn tiny(output: usize) -> Self {
        Self {
            input: 2,
            conv: vec![6, 8, 5],
            fc: vec![7, 4],
            output,
            window: 1,
        }
    }

    /// `(in, out)` of every fully connected layer including the output layer.
    pub fn fc_dims(&self) -> Vec<(usize, usize)> {
        let mut dims = Vec::new();
        let mut prev = *self.conv.last().unwrap_or(&self.input) * self.window.max(1);
        for &n in self.fc.iter().chain(std::iter::once(&self.output)) {
            dims.push((prev, n));
            prev = n;
        }
        dims
    }

    /// `(in, out)` of every convolution.
    pub fn conv_dims(&self) -> Vec<(usize, usize)> {
        let mut dims = Vec::new();
        let mut prev = self.input;
        for &n in &self.conv {
            dims.push((prev, n));
            prev = n;
        }
        dims
    }

    /// Every tensor this architecture has, in PyTorch `state_dict` order, with its shape and
    /// whether the optimiser trains it (running statistics are buffers).
    ///
    /// An architecture without outputs (the model-free `kf`) has no tensors.
    pub fn tensor_specs(&self) -> Vec<TensorSpec> {
        let mut specs = Vec::new();
        if self.output == 0 {
            return specs;
        }
        let spec = |name: String, shape: Vec<usize>, role| TensorSpec::new(name, shape, role);
        for (i, (cin, cout)) in self.conv_dims().into_iter().enumerate() {
            let l = i + 1;
            specs.push(spec(
                format!("conv{l}.weight"),
                vec![cout, cin, 1],
                Role::Weight,
            ));
            specs.push(spec(format!("conv{l}.bias"), vec![cout], Role::Bias));
            // Batch norm: γ and β train like biases (no decay); the running statistics
            // are buffers.
            for (name, role) in [
                ("weight", Role::Bias),
                ("bias", Role::Bias),
                ("running_mean", Role::Buffer),
                ("running_var", Role::Buffer),
            ] {
                specs.push(spec(format!("bn{l}.{name}"), vec![cout], role));
            }
        }
        for (i, (fin, fout)) in self.fc_dims().into_iter().enumerate() {
            let l = i + 1;
            specs.push(spec(format!("fc{l}.weight"), vec![fout, fin], Role::Weight));
            specs.push(spec(format!("fc{l}.bias"), vec![fout], Role::Bias));
        }
        specs
    }

    /// Number of trainable parameters, counted the way PyTorch's
    /// `sum(p.numel() for p in model.parameters())` does (running statistics excluded).
    pub fn trainable_parameters(&self) -> usize {
        self.tensor_specs()
            .iter()
            .filter(|s| s.role != Role::Buffer)
            .map(|s| s.len())
            .sum()
    }
}

/// How the optimiser treats a tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A weight matrix: trained, with weight decay.
    Weight,
    /// A bias or batch-norm affine parameter: trained, no weight decay.
    Bias,
    /// Batch-norm running statistics: updated by the forward pass, not by the optimiser.
    Buffer,
}

/// Name, shape and role of one tensor.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TensorSpec {
    /// PyTorch `state_dict` name.
    pub name: String,
    /// PyTorch shape.
    pub shape: Vec<usize>,
    /// Optimiser treatment.
    pub role: Role,
}

impl TensorSpec {
    fn new(name: String, shape: Vec<usize>, role: Role) -> Self {
        Self { name, shape, role }
    }
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    /// True for a zero-sized tensor (never produced by [`Arch`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// All tensors of a network in one flat vector.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSet {
    arch: Arch,
    specs: Vec<TensorSpec>,
    offsets: Vec<usize>,
    data: Vec<f32>,
}

impl ParamSet {
    /// Zeroed tensors for `arch` (running variances set to one, like a fresh PyTorch model).
    pub fn zeros(arch: &Arch) -> Self {
        let specs = arch.tensor_specs();
        let mut offsets = Vec::with_capacity(specs.len());
        let mut total = 0;
        for s in &specs {
            offsets.push(total);
            total += s.len();
        }
        let mut p = Self {
            arch: arch.clone(),
            specs,
            offsets,
            data: vec![0.0; total],
        };
        for l in 1..=arch.conv.len() {
            p.get_mut(&format!("bn{l}.running_var")).fill(1.0);
            p.get_mut(&format!("bn{l}.weight")).fill(1.0);
        }
        p
    }

    /// PyTorch's default initialisation (Kaiming-uniform weights and biases in
    /// `±1/sqrt(fan_in)`). `uniform(bound)` draws one value in `[-bound, bound)`: the
    /// caller brings a seeded generator (training is reproducible) and this crate needs
    /// no random-number dependency.
    pub fn init(arch: &Arch, mut uniform: impl FnMut(f32) -> f32) -> Self {
        let mut p = Self::zeros(arch);
        for i in 0..p.specs.len() {
            let spec = &p.specs[i];
            let is_linear = spec.name.starts_with("conv") || spec.name.starts_with("fc");
            if !is_linear {
                continue;
            }
            let fan_in = if spec.role == Role::Weight {
                spec.shape[1]
            } else {
                // bias: fan_in of the matching weight
                let wname = spec.name.replace(".bias", ".weight");
                let widx = p.index_of(&wname).expect("bias without weight");
                p.specs[widx].shape[1]
            };
            let bound = 1.0 / (fan_in as f32).sqrt();
            let range = p.range(i);
            for v in &mut p.data[range] {
                *v = uniform(bound);
            }
        }
        p
    }

    /// The architecture these tensors fill.
    pub fn arch(&self) -> &Arch {
        &self.arch
    }

    /// Tensor specs in `state_dict` order.
    pub fn specs(&self) -> &[TensorSpec] {
        &self.specs
    }

    /// The flat data vector.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The flat data vector, mutable (the optimiser's view).
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// Index of a tensor by name.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.specs.iter().position(|s| s.name == name)
    }

    /// Element range of tensor `i` in the flat vector.
    pub fn range(&self, i: usize) -> std::ops::Range<usize> {
        self.offsets[i]..self.offsets[i] + self.specs[i].len()
    }

    /// A tensor's elements by name. Panics on an unknown name: names come from [`Arch`],
    /// so a miss is a programming error, not bad input.
    pub fn get(&self, name: &str) -> &[f32] {
        let i = self
            .index_of(name)
            .unwrap_or_else(|| panic!("no tensor {name}"));
        &self.data[self.range(i)]
    }

    /// A tensor's elements by name, mutable.
    pub fn get_mut(&mut self, name: &str) -> &mut [f32] {
        let i = self
            .index_of(name)
            .unwrap_or_else(|| panic!("no tensor {name}"));
        let r = self.range(i);
        &mut self.data[r]
    }

    /// The `[out, in]` (or `[out, in, 1]`) weight `name` as the column-major `in × out`
    /// matrix `Wᵀ`, without copying.
    pub fn matrix_t(&self, name: &str) -> faer::MatRef<'_, f32> {
        let i = self
            .index_of(name)
            .unwrap_or_else(|| panic!("no tensor {name}"));
        let shape = &self.specs[i].shape;
        faer::MatRef::from_column_major_slice(&self.data[self.range(i)], shape[1], shape[0])
    }

    /// Number of trainable elements.
    pub fn trainable_len(&self) -> usize {
        self.arch.trainable_parameters()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The count models/README.md states, and why the paper's 70,709 is not reproducible.
    #[test]
    fn parameter_counts() {
        // Table I with one output, input read as 2 channels × length 1 (PyTorch counting).
        assert_eq!(Arch::paper(1).trainable_parameters(), 38_291);
        // Our heads: blend has 3 outputs, residual 4 (a row is 5 weights + 1 bias).
        assert_eq!(Arch::paper(3).trainable_parameters(), 38_303);
        assert_eq!(Arch::paper(4).trainable_parameters(), 38_309);
        // Batch-norm running statistics are buffers, not parameters: 2 × 408.
        let buffers: usize = Arch::paper(1)
            .tensor_specs()
            .iter()
            .filter(|s| s.role == Role::Buffer)
            .map(|s| s.len())
            .sum();
        assert_eq!(buffers, 816);
        // Reading the input as 1 channel × length 2 instead: conv1 has 24·1 weights and the
        // flatten gives 96 features, so fc1 has 96·60 weights.
        let alt = 38_291 - (24 * 2) + 24 - (48 * 60) + (96 * 60);
        assert_eq!(alt, 41_147);
    }

    #[test]
    fn matrix_view_is_the_transpose_of_the_pytorch_layout() {
        let arch = Arch::tiny(2);
        let mut p = ParamSet::zeros(&arch);
        // fc1.weight is [7, 5] row-major: element (o, i) at o*5 + i.
        for (k, v) in p.get_mut("fc1.weight").iter_mut().enumerate() {
            *v = k as f32;
        }
        let t = p.matrix_t("fc1.weight");
        assert_eq!((t.nrows(), t.ncols()), (5, 7));
        assert_eq!(t[(2, 3)], (3 * 5 + 2) as f32);
    }
}
