//! The auto-decoder network (DeepSDF): `f(z, p) → signed distance`, latent `z` concatenated to
//! the point, one skip connection re-injecting the input at the middle layer, SiLU activations
//! (smooth normals: the surfaces are mirrors).
//!
//! | tensor | shape | meaning |
//! |---|---|---|
//! | `l0.weight`, `l0.bias` | W×(L+3), W | input `[z; p]` → hidden |
//! | `l1.*` | W×W, W | hidden |
//! | `l2.*` | W×(W+L+3), W | skip: `[h1; z; p]` → hidden |
//! | `l3.*` | W×W, W | hidden |
//! | `l4.*` | 1×W, 1 | output |
//! | `latents` | N×L | the training shapes' codes |
//!
//! Files are `safetensors` (f32) with string metadata (category, command, seed, figures). The
//! frozen network evaluates in f64 (weights widened at load) with a hand-written reverse pass
//! for ∂f/∂p and ∂f/∂z; training and latent inference use candle (see `train`, `infer`),
//! batched evaluation and the placed fit the split layers of `shared.rs`.

use crate::SdfError;
use crate::families::Category;
use crate::shared::SharedLatentNet;
use candle_core::{Device, Tensor};
use irmirror_render::baked::BakedSdf;
use nalgebra::Vector3;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

/// Latent dimension of the shipped priors.
pub const LATENT: usize = 32;
/// Hidden width of the shipped priors.
pub const WIDTH: usize = 128;
/// Number of linear layers.
pub const LAYERS: usize = 5;
/// Distances are clamped to ±this in the loss (DeepSDF's δ), normalised units.
pub const CLAMP: f64 = 0.1;

/// `silu(x)` and its derivative.
#[inline]
fn silu(x: f64) -> (f64, f64) {
    let s = 1.0 / (1.0 + (-x).exp());
    (x * s, s * (1.0 + x * (1.0 - s)))
}

/// A frozen auto-decoder.
#[derive(Clone, Debug)]
pub struct SdfNet {
    /// The category it models.
    pub category: Category,
    /// Latent dimension L.
    pub latent_dim: usize,
    /// Hidden width W.
    pub width: usize,
    /// Per layer: weights (row-major fan_out × fan_in) and biases.
    pub(crate) weights: Vec<(Vec<f64>, Vec<f64>)>,
    /// Codes of the training shapes (rows of length L).
    pub train_latents: Vec<Vec<f64>>,
    /// Free-form provenance (command, seed, figures).
    pub metadata: BTreeMap<String, String>,
}

fn layer_shapes(l: usize, w: usize) -> [(usize, usize); LAYERS] {
    [(w, l + 3), (w, w), (w, w + l + 3), (w, w), (1, w)]
}

impl SdfNet {
    /// A network from per-layer `(weights, biases)` in f32 (candle's training output).
    pub fn from_parts(
        category: Category,
        latent_dim: usize,
        width: usize,
        layers: Vec<(Vec<f32>, Vec<f32>)>,
        latents: Vec<Vec<f32>>,
        metadata: BTreeMap<String, String>,
    ) -> Result<Self, SdfError> {
        let shapes = layer_shapes(latent_dim, width);
        if layers.len() != LAYERS {
            return Err(SdfError::Invalid(format!(
                "{} layers, expected {LAYERS}",
                layers.len()
            )));
        }
        for (k, ((w, b), (o, i))) in layers.iter().zip(shapes).enumerate() {
            if w.len() != o * i || b.len() != o {
                return Err(SdfError::Invalid(format!(
                    "layer {k}: {} weights / {} biases, expected {o}×{i} / {o}",
                    w.len(),
                    b.len()
                )));
            }
        }
        if width == 0 || width > 512 || latent_dim == 0 || latent_dim > 64 {
            return Err(SdfError::Invalid(format!(
                "width {width} / latent {latent_dim} outside 1…512 / 1…64"
            )));
        }
        if latents.iter().any(|z| z.len() != latent_dim) {
            return Err(SdfError::Invalid(
                "a training latent has the wrong length".into(),
            ));
        }
        let widen = |v: &Vec<f32>| v.iter().map(|x| f64::from(*x)).collect::<Vec<f64>>();
        Ok(Self {
            category,
            latent_dim,
            width,
            weights: layers.iter().map(|(w, b)| (widen(w), widen(b))).collect(),
            train_latents: latents.iter().map(widen).collect(),
            metadata,
        })
    }

    /// The shipped prior of `category` (`assets/object_priors`, built into the binary), parsed
    /// once per process.
    pub fn builtin(category: Category) -> Result<Arc<SdfNet>, SdfError> {
        static CACHE: std::sync::OnceLock<[Result<Arc<SdfNet>, String>; 3]> =
            std::sync::OnceLock::new();
        let cache = CACHE.get_or_init(|| {
            let parse = |b: &[u8]| {
                SdfNet::from_bytes(b)
                    .map(Arc::new)
                    .map_err(|e| e.to_string())
            };
            [
                parse(include_bytes!(
                    "../../../assets/object_priors/bowl.safetensors"
                )),
                parse(include_bytes!(
                    "../../../assets/object_priors/mug.safetensors"
                )),
                parse(include_bytes!(
                    "../../../assets/object_priors/car.safetensors"
                )),
            ]
        });
        let k = Category::LEARNED
            .iter()
            .position(|c| *c == category)
            .ok_or(SdfError::NoPrior(category))?;
        cache[k].clone().map_err(|reason| SdfError::Weights {
            path: format!("built-in {} prior", category.name()),
            reason,
        })
    }

    /// Loads a prior, checking every tensor's shape.
    pub fn load(path: &Path) -> Result<Self, SdfError> {
        let bytes = std::fs::read(path).map_err(|e| SdfError::Weights {
            path: path.display().to_string(),
            reason: format!("cannot read: {e}"),
        })?;
        Self::from_bytes(&bytes).map_err(|e| SdfError::Weights {
            path: path.display().to_string(),
            reason: e.to_string(),
        })
    }

    /// Parses a prior from safetensors bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, SdfError> {
        let bad = |r: String| SdfError::Invalid(r);
        let st = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let (_, meta) =
            safetensors::SafeTensors::read_metadata(bytes).map_err(|e| bad(e.to_string()))?;
        let metadata: BTreeMap<String, String> = meta
            .metadata()
            .clone()
            .unwrap_or_default()
            .into_iter()
            .collect();
        let category = metadata
            .get("category")
            .and_then(|c| c.parse::<Category>().ok())
            .filter(|c| c.has_learned_prior())
            .ok_or_else(|| bad("metadata has no known `category`".into()))?;
        let get = |name: &str| -> Result<(Vec<usize>, Vec<f32>), SdfError> {
            let t = st
                .tensor(name)
                .map_err(|_| bad(format!("missing tensor `{name}`")))?;
            if t.dtype() != safetensors::Dtype::F32 {
                return Err(bad(format!(
                    "tensor `{name}` is {:?}, expected F32",
                    t.dtype()
                )));
            }
            let v = t
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            Ok((t.shape().to_vec(), v))
        };
        let (s0, _) = get("l0.weight")?;
        if s0.len() != 2 || s0[1] < 4 {
            return Err(bad(format!(
                "tensor `l0.weight` has shape {s0:?}, expected [W, L+3]"
            )));
        }
        let (width, latent_dim) = (s0[0], s0[1] - 3);
        let mut layers = Vec::new();
        for (k, (o, i)) in layer_shapes(latent_dim, width).into_iter().enumerate() {
            let (sw, w) = get(&format!("l{k}.weight"))?;
            let (sb, b) = get(&format!("l{k}.bias"))?;
            if sw != [o, i] || sb != [o] {
                return Err(bad(format!(
                    "layer l{k} has shapes {sw:?}/{sb:?}, expected [{o}, {i}]/[{o}]"
                )));
            }
            layers.push((w, b));
        }
        let (sl, lat) = get("latents")?;
        if sl.len() != 2 || sl[1] != latent_dim {
            return Err(bad(format!(
                "tensor `latents` has shape {sl:?}, expected [N, {latent_dim}]"
            )));
        }
        let latents = lat.chunks(latent_dim).map(<[f32]>::to_vec).collect();
        Self::from_parts(category, latent_dim, width, layers, latents, metadata)
    }

    /// Writes the prior (f32 safetensors with metadata; `category` is added).
    pub fn save(&self, path: &Path) -> Result<(), SdfError> {
        let narrow = |v: &[f64]| {
            v.iter()
                .flat_map(|x| (*x as f32).to_le_bytes())
                .collect::<Vec<u8>>()
        };
        let mut bufs: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
        for (k, ((w, b), (o, i))) in self
            .weights
            .iter()
            .zip(layer_shapes(self.latent_dim, self.width))
            .enumerate()
        {
            bufs.push((format!("l{k}.weight"), vec![o, i], narrow(w)));
            bufs.push((format!("l{k}.bias"), vec![o], narrow(b)));
        }
        let flat: Vec<f64> = self.train_latents.iter().flatten().copied().collect();
        bufs.push((
            "latents".into(),
            vec![self.train_latents.len(), self.latent_dim],
            narrow(&flat),
        ));
        let views: Vec<(String, safetensors::tensor::TensorView)> = bufs
            .iter()
            .map(|(n, s, d)| {
                Ok((
                    n.clone(),
                    safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), d)?,
                ))
            })
            .collect::<Result<_, safetensors::SafeTensorError>>()
            .map_err(|e| SdfError::Invalid(e.to_string()))?;
        let mut meta: HashMap<String, String> = self.metadata.clone().into_iter().collect();
        meta.insert("category".into(), self.category.name().into());
        let bytes = safetensors::serialize(views, Some(meta))
            .map_err(|e| SdfError::Invalid(e.to_string()))?;
        let tmp = path.with_extension("safetensors.partial");
        std::fs::write(&tmp, bytes)
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(|e| SdfError::Weights {
                path: path.display().to_string(),
                reason: format!("cannot write: {e}"),
            })
    }

    /// The weights as candle tensors (f32, `[fan_out, fan_in]` and `[fan_out]`).
    pub fn tensors(&self, device: &Device) -> Result<Vec<(Tensor, Tensor)>, SdfError> {
        layer_shapes(self.latent_dim, self.width)
            .iter()
            .zip(&self.weights)
            .map(|((o, i), (w, b))| {
                let w32: Vec<f32> = w.iter().map(|x| *x as f32).collect();
                let b32: Vec<f32> = b.iter().map(|x| *x as f32).collect();
                Ok((
                    Tensor::from_vec(w32, (*o, *i), device)?,
                    Tensor::from_vec(b32, *o, device)?,
                ))
            })
            .collect()
    }

    /// `f(z, p)` for many points at once (f32, the shared latent's split layers: see
    /// `shared.rs`; points in parallel chunks).
    pub fn eval_batch(&self, z: &[f64], points: &[Vector3<f64>]) -> Result<Vec<f64>, SdfError> {
        if z.len() != self.latent_dim {
            return Err(SdfError::Invalid(format!(
                "latent of length {}, expected {}",
                z.len(),
                self.latent_dim
            )));
        }
        Ok(SharedLatentNet::<f32>::new(self)
            .forward(z, points, false)
            .0)
    }

    /// Mean of the training latents (the starting point of latent inference).
    pub fn mean_latent(&self) -> Vec<f64> {
        let n = self.train_latents.len().max(1) as f64;
        (0..self.latent_dim)
            .map(|k| self.train_latents.iter().map(|z| z[k]).sum::<f64>() / n)
            .collect()
    }

    /// `f(z, p)` with `(∂f/∂z, ∂f/∂p)`, f64 (reference path; [`LatentSdf`] is the fast one).
    pub fn eval_full(&self, z: &[f64], p: &Vector3<f64>) -> (f64, Vec<f64>, Vector3<f64>) {
        let (l, w) = (self.latent_dim, self.width);
        let mut x: Vec<f64> = z.to_vec();
        x.extend_from_slice(p.as_slice());
        let lin = |k: usize, input: &[f64]| -> Vec<f64> {
            let (wt, b) = &self.weights[k];
            let n_in = input.len();
            b.iter()
                .enumerate()
                .map(|(o, bo)| {
                    bo + wt[o * n_in..(o + 1) * n_in]
                        .iter()
                        .zip(input)
                        .map(|(a, c)| a * c)
                        .sum::<f64>()
                })
                .collect()
        };
        let act = |a: &[f64]| -> (Vec<f64>, Vec<f64>) { a.iter().map(|v| silu(*v)).unzip() };
        let (h0, d0) = act(&lin(0, &x));
        let (h1, d1) = act(&lin(1, &h0));
        let mut in2 = h1.clone();
        in2.extend_from_slice(&x);
        let (h2, d2) = act(&lin(2, &in2));
        let (h3, d3) = act(&lin(3, &h2));
        let f = lin(4, &h3)[0];
        // Reverse pass.
        let back = |k: usize, g: &[f64], n_in: usize| -> Vec<f64> {
            let wt = &self.weights[k].0;
            let mut out = vec![0.0; n_in];
            for (o, go) in g.iter().enumerate() {
                for (i, oi) in out.iter_mut().enumerate() {
                    *oi += wt[o * n_in + i] * go;
                }
            }
            out
        };
        let g3: Vec<f64> = self.weights[4]
            .0
            .iter()
            .zip(&d3)
            .map(|(a, b)| a * b)
            .collect();
        let g2: Vec<f64> = back(3, &g3, w)
            .iter()
            .zip(&d2)
            .map(|(a, b)| a * b)
            .collect();
        let gin2 = back(2, &g2, w + l + 3);
        let g1: Vec<f64> = gin2[..w].iter().zip(&d1).map(|(a, b)| a * b).collect();
        let g0: Vec<f64> = back(1, &g1, w)
            .iter()
            .zip(&d0)
            .map(|(a, b)| a * b)
            .collect();
        let gx: Vec<f64> = back(0, &g0, l + 3)
            .iter()
            .zip(&gin2[w..])
            .map(|(a, b)| a + b)
            .collect();
        (
            f,
            gx[..l].to_vec(),
            Vector3::new(gx[l], gx[l + 1], gx[l + 2]),
        )
    }

    /// The shape of latent `z` as a field the renderer can trace.
    pub fn shape(self: &Arc<Self>, z: &[f64]) -> Result<LatentSdf, SdfError> {
        LatentSdf::new(self.clone(), z)
    }
}

/// One shape of a prior: the network with a fixed latent, the latent's contribution to the
/// first and skip layers folded into their biases (so a point costs only the p columns).
#[derive(Clone, Debug)]
pub struct LatentSdf {
    net: Arc<SdfNet>,
    /// The latent code.
    pub latent: Vec<f64>,
    bias0: Vec<f64>,
    bias2: Vec<f64>,
    /// The hidden `W × W` weights of layers 1, 2 (its hidden columns) and 3, transposed
    /// (input-major), for [`mat_vec`].
    hidden_t: [Vec<f64>; 3],
}

impl LatentSdf {
    /// Folds `z` into the network.
    pub fn new(net: Arc<SdfNet>, z: &[f64]) -> Result<Self, SdfError> {
        let (l, w) = (net.latent_dim, net.width);
        if z.len() != l || z.iter().any(|v| !v.is_finite()) {
            return Err(SdfError::Invalid(format!(
                "latent of length {} (finite: {}), expected {l} finite values",
                z.len(),
                z.iter().all(|v| v.is_finite())
            )));
        }
        let fold = |k: usize, n_in: usize, offset: usize| -> Vec<f64> {
            let (wt, b) = &net.weights[k];
            (0..w)
                .map(|o| {
                    b[o] + (0..l)
                        .map(|i| wt[o * n_in + offset + i] * z[i])
                        .sum::<f64>()
                })
                .collect()
        };
        let bias0 = fold(0, l + 3, 0);
        let bias2 = fold(2, w + l + 3, w);
        let transpose = |k: usize, n_in: usize| -> Vec<f64> {
            let wt = &net.weights[k].0;
            (0..w * w).map(|j| wt[(j % w) * n_in + j / w]).collect()
        };
        let hidden_t = [transpose(1, w), transpose(2, w + l + 3), transpose(3, w)];
        Ok(Self {
            net,
            latent: z.to_vec(),
            bias0,
            bias2,
            hidden_t,
        })
    }

    /// The field sampled on a grid of `cells` per axis across its bounding cube, in one batched
    /// pass, and interpolated ([`BakedSdf`]): what stage 2 traces (a value costs 64
    /// multiply–adds instead of the network's ≈ 140k flops).
    pub fn baked(self: &Arc<Self>, cells: usize) -> Result<BakedSdf, SdfError> {
        let inner: Arc<dyn irmirror_render::sdf::Sdf> = self.clone();
        BakedSdf::bake(inner, cells, |ps| self.net.eval_batch(&self.latent, ps))
            .map_err(SdfError::Invalid)
    }

    /// [`Self::baked`] with the network answering near the surface
    /// ([`BakedSdf::with_band`]): the band is twice the grid's largest error at the cell
    /// centres within [`CLAMP`] of the surface (where interpolation errs most), plus 0.005.
    pub fn baked_banded(self: &Arc<Self>, cells: usize) -> Result<BakedSdf, SdfError> {
        let baked = self.baked(cells)?;
        let probe = baked.cell_centres_near_surface(CLAMP);
        let values = self.net.eval_batch(&self.latent, &probe)?;
        let band = 2.0 * baked.max_error(&probe, &values) + 0.005;
        Ok(baked.with_band(band))
    }

    /// Signed distance alone: [`Self::value_grad`]'s forward pass (the same value to the bit)
    /// without the reverse pass — half the work, which is what sphere tracing's steps need.
    pub fn value(&self, p: &Vector3<f64>) -> f64 {
        let (mut h, mut d) = ([[0.0f64; 512]; 4], [[0.0f64; 512]; 4]);
        self.forward(p, &mut h, &mut d)
    }

    /// The `p` columns of layer `k` (`n_in` inputs), output `o`: only they remain of the input
    /// layers once the latent is folded into the biases.
    fn p_cols(&self, k: usize, n_in: usize, o: usize) -> Vector3<f64> {
        let r = &self.net.weights[k].0[o * n_in + n_in - 3..(o + 1) * n_in];
        Vector3::new(r[0], r[1], r[2])
    }

    /// The forward pass: the four hidden layers' activations `h` and SiLU's slopes `d`, and the
    /// value. Allocation-free: activations live on the stack (width ≤ 512, checked at load).
    fn forward(&self, p: &Vector3<f64>, h: &mut [[f64; 512]; 4], d: &mut [[f64; 512]; 4]) -> f64 {
        let (l, w) = (self.net.latent_dim, self.net.width);
        let wts = &self.net.weights;
        let (n0, n2) = (l + 3, w + l + 3);
        let mut acc = [0.0f64; 512];
        for o in 0..w {
            (h[0][o], d[0][o]) = silu(self.bias0[o] + self.p_cols(0, n0, o).dot(p));
        }
        mat_vec(&self.hidden_t[0], &h[0][..w], &mut acc[..w]);
        for o in 0..w {
            (h[1][o], d[1][o]) = silu(wts[1].1[o] + acc[o]);
        }
        mat_vec(&self.hidden_t[1], &h[1][..w], &mut acc[..w]);
        for o in 0..w {
            (h[2][o], d[2][o]) = silu(self.bias2[o] + acc[o] + self.p_cols(2, n2, o).dot(p));
        }
        mat_vec(&self.hidden_t[2], &h[2][..w], &mut acc[..w]);
        for o in 0..w {
            (h[3][o], d[3][o]) = silu(wts[3].1[o] + acc[o]);
        }
        wts[4].1[0] + dot(&wts[4].0, &h[3][..w])
    }

    /// Signed distance and its gradient with respect to the point (normalised frame).
    pub fn value_grad(&self, p: &Vector3<f64>) -> (f64, Vector3<f64>) {
        let (l, w) = (self.net.latent_dim, self.net.width);
        let wts = &self.net.weights;
        let (n0, n2) = (l + 3, w + l + 3);
        let (mut h, mut d) = ([[0.0f64; 512]; 4], [[0.0f64; 512]; 4]);
        let f = self.forward(p, &mut h, &mut d);
        let [h0, h1, h2, h3] = &mut h;
        let [d0, d1, d2, d3] = &d;
        // Reverse pass, reusing the activation buffers for gradients of the pre-activations.
        let g3 = &mut h3[..w];
        for o in 0..w {
            g3[o] = wts[4].0[o] * d3[o];
        }
        back_silu(&wts[3].0, w, g3, &d2[..w], &mut h2[..w]);
        back_silu(&wts[2].0, n2, &h2[..w], &d1[..w], &mut h1[..w]);
        back_silu(&wts[1].0, w, &h1[..w], &d0[..w], &mut h0[..w]);
        let mut gp = Vector3::zeros();
        for o in 0..w {
            gp += self.p_cols(2, n2, o) * h2[o] + self.p_cols(0, n0, o) * h0[o];
        }
        (f, gp)
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `acc = W x` from `W`'s transpose (`wt`, input-major rows of `acc.len()`): accumulated input
/// by input, so the compiler vectorises across outputs — a row-by-row dot product is one chain
/// of dependent additions per output (sphere tracing's single points spent half their time
/// there).
fn mat_vec(wt: &[f64], x: &[f64], acc: &mut [f64]) {
    let n = acc.len();
    acc.fill(0.0);
    // Four inputs per pass over `acc` (each output still adds them in input order).
    let mut blocks = x.chunks_exact(4);
    let mut i = 0;
    for xb in &mut blocks {
        let rows = &wt[i * n..(i + 4) * n];
        let (r0, rest) = rows.split_at(n);
        let (r1, rest) = rest.split_at(n);
        let (r2, r3) = rest.split_at(n);
        for ((((a, w0), w1), w2), w3) in acc.iter_mut().zip(r0).zip(r1).zip(r2).zip(r3) {
            *a = *a + w0 * xb[0] + w1 * xb[1] + w2 * xb[2] + w3 * xb[3];
        }
        i += 4;
    }
    for (k, xi) in blocks.remainder().iter().enumerate() {
        let row = &wt[(i + k) * n..(i + k + 1) * n];
        for (a, wv) in acc.iter_mut().zip(row) {
            *a += wv * xi;
        }
    }
}

/// `g_in = d_in ⊙ (Wᵀ g_out)` over the first `g_in.len()` input columns.
fn back_silu(wt: &[f64], n_in: usize, g_out: &[f64], d_in: &[f64], g_in: &mut [f64]) {
    g_in.fill(0.0);
    for (o, go) in g_out.iter().enumerate() {
        for (gi, wi) in g_in.iter_mut().zip(&wt[o * n_in..]) {
            *gi += wi * go;
        }
    }
    for (gi, di) in g_in.iter_mut().zip(d_in) {
        *gi *= di;
    }
}

impl irmirror_render::sdf::Sdf for LatentSdf {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.value(p)
    }
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.value_grad(p).1
    }
    fn bounding_radius(&self) -> f64 {
        1.0
    }
    /// Training clamps distances at [`CLAMP`]: beyond it the value is unconstrained (the car
    /// prior's rises ≈ 1.9 per unit along a camera ray), so sphere tracing steps at most that far.
    fn max_step(&self) -> f64 {
        CLAMP
    }
}

/// Batched forward pass in candle: `x` is `[N, L+3]` (latent then point), the result `[N]`.
pub(crate) fn forward(layers: &[(Tensor, Tensor)], x: &Tensor) -> candle_core::Result<Tensor> {
    let lin = |k: usize, h: &Tensor| h.matmul(&layers[k].0.t()?)?.broadcast_add(&layers[k].1);
    let h = lin(0, x)?.silu()?;
    let h = lin(1, &h)?.silu()?;
    let h = lin(2, &Tensor::cat(&[&h, x], 1)?)?.silu()?;
    let h = lin(3, &h)?.silu()?;
    lin(4, &h)?.squeeze(1)
}
