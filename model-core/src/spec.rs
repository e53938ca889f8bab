//! The host's owned description of a table ([`TableSpec`], serde), its
//! encoder to format v1 ([`TableSpec::encode`], which re-parses what it wrote
//! so nothing invalid ever leaves the host) and the f64 reference evaluation
//! ([`TableSpec::eval_f64`]) that the f32 and fixed-point evaluators are
//! tested against. Host only (`std` feature).

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::eval::Inputs;
use crate::limits::MAX_TEMPS;
use crate::table::{
    self, Envelope, InputScaling, Monomial, TableError, CHANNEL_NAME_LEN, CRC32, CRC_LEN,
    FIXED_LEN, FORMAT_VERSION, MAGIC, UNITS_NM_MC,
};

/// One polynomial coefficient: the monomial's exponents `[a, b, c]` and its coefficient.
pub type PolyCoef = (Monomial, f64);

/// The host's description of a table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TableSpec {
    /// Creation time, seconds since the Unix epoch.
    pub created_unix_s: i64,
    /// Hash of the source data (SHA-256 by convention).
    pub source_hash: [u8; 32],
    /// Temperature channel names (≤ 4, each 1–16 bytes of UTF-8), in input order.
    pub channels: Vec<String>,
    /// Envelope (travel, max correction, slew, temperature and tool ranges).
    pub envelope: Envelope,
    /// Input scaling for polynomials.
    pub scaling: InputScaling,
    /// Which outputs (ex, ey, ez) the table provides.
    pub outputs: [bool; 3],
    /// The terms, summed per output.
    pub terms: Vec<TermSpec>,
}

/// One term. Outputs are 0 = ex, 1 = ey, 2 = ez; axes 0 = x, 1 = y, 2 = z.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TermSpec {
    /// Σ c · u_x^a u_y^b u_z^c, c in nm.
    Poly { output: u8, coefs: Vec<PolyCoef> },
    /// Σ_k sin_nm[k−1]·sin(2πk·p/period) + cos_nm[k−1]·cos(2πk·p/period), k = 1..=4.
    Periodic {
        output: u8,
        axis: u8,
        period_nm: i32,
        sin_nm: Vec<f64>,
        cos_nm: Vec<f64>,
    },
    /// (T − T_ref) · Σ c · monomial, c in nm/K (a single `[0,0,0]` coefficient = thermal alone).
    Thermal {
        output: u8,
        channel: u8,
        t_ref_mc: i32,
        coefs_nm_per_k: Vec<PolyCoef>,
    },
    /// amplitude · rev, rev ∈ [−1, 1] from a [`crate::DirTracker`] with this transition length.
    Reversal {
        output: u8,
        axis: u8,
        transition_nm: i32,
        amplitude_nm: f64,
    },
    /// tool_nm · Σ c · monomial, c in nm per nm of arm (i.e. radians).
    Abbe { output: u8, coefs: Vec<PolyCoef> },
    /// A tanh MLP.
    Mlp(MlpSpec),
    /// A grid table.
    Grid(GridSpec),
}

/// Where an MLP input comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MlpSource {
    /// Position of axis 0..=2, nm.
    Pos(u8),
    /// Temperature channel, m°C.
    Temp(u8),
}

/// An MLP input with its min-max scaling (min ↦ −1, max ↦ +1, in the source's unit: nm or m°C).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlpInputSpec {
    /// The source.
    pub source: MlpSource,
    /// Maps to −1.
    pub min: f64,
    /// Maps to +1.
    pub max: f64,
}

/// A dense layer: `weights` row-major with one row per unit (units × inputs), `bias` per unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayerSpec {
    /// units × inputs, row-major.
    pub weights: Vec<f64>,
    /// One per unit.
    pub bias: Vec<f64>,
}

/// A tanh MLP (tansig hidden layers, purelin output, mapminmax scaling).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlpSpec {
    /// Output indices fed by the net's outputs, ascending.
    pub outputs: Vec<u8>,
    /// Inputs with their scaling.
    pub inputs: Vec<MlpInputSpec>,
    /// 1 or 2 tanh layers of ≤ 32 units.
    pub hidden: Vec<LayerSpec>,
    /// The linear output layer (one unit per output).
    pub output: LayerSpec,
    /// Output scaling: −1 ↦ min, +1 ↦ max, nm.
    pub out_min_nm: Vec<f64>,
    /// See `out_min_nm`.
    pub out_max_nm: Vec<f64>,
}

/// One axis of a grid; `nodes == 1` means the grid does not vary along it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GridAxisSpec {
    /// Node count (1..=1024).
    pub nodes: u16,
    /// Position of node 0, nm.
    pub origin_nm: i32,
    /// Spacing, nm (> 0).
    pub step_nm: i32,
}

/// A grid table with multilinear interpolation, held at its edges.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridSpec {
    /// Output index.
    pub output: u8,
    /// x, y, z axes.
    pub axes: [GridAxisSpec; 3],
    /// Values, x fastest, then y, then z, nm.
    pub values_nm: Vec<f64>,
}

/// Inputs of the f64 reference.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InputsF64 {
    /// Positions, nm.
    pub pos_nm: [f64; 3],
    /// Reversal state, −1..1.
    pub rev: [f64; 3],
    /// Temperatures, °C.
    pub temp_c: [f64; MAX_TEMPS],
    /// Tool arm, nm.
    pub tool_nm: f64,
}

impl From<&Inputs> for InputsF64 {
    fn from(i: &Inputs) -> Self {
        InputsF64 {
            pos_nm: i.pos_nm.map(|p| p as f64),
            rev: i.rev_q30.map(|r| r as f64 / (1u64 << 30) as f64),
            temp_c: i.temp_mc.map(|t| t as f64 / 1000.0),
            tool_nm: i.tool_nm as f64,
        }
    }
}

/// Why a spec cannot be encoded.
#[derive(Clone, Debug, PartialEq)]
pub enum EncodeError {
    /// A term's vectors have inconsistent lengths or out-of-range sizes.
    Shape { term: usize, what: &'static str },
    /// A channel name is empty, longer than 16 bytes or contains NUL; or more than 4 channels.
    ChannelName { channel: usize },
    /// The table would exceed a flash slot.
    TooLarge { bytes: usize },
    /// The encoded bytes fail validation.
    Invalid(TableError),
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Shape { term, what } => write!(f, "term {term}: {what}"),
            Self::ChannelName { channel } => write!(f, "bad temperature channel name #{channel}"),
            Self::TooLarge { bytes } => write!(
                f,
                "table of {bytes} bytes exceeds the {} byte slot",
                table::MAX_TABLE_LEN
            ),
            Self::Invalid(e) => write!(f, "encoded table is invalid: {e}"),
        }
    }
}

impl std::error::Error for EncodeError {}

struct W(Vec<u8>);
impl W {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u16(&mut self, v: u16) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn poly(&mut self, coefs: &[PolyCoef]) {
        self.u16(coefs.len().min(u16::MAX as usize) as u16);
        self.u16(0);
        for (m, c) in coefs {
            self.0.extend_from_slice(&[m[0], m[1], m[2], 0]);
            self.f64(*c);
        }
    }
}

fn mono_value(u: &[f64; 3], m: Monomial) -> f64 {
    u[0].powi(m[0] as i32) * u[1].powi(m[1] as i32) * u[2].powi(m[2] as i32)
}

fn poly_value(u: &[f64; 3], coefs: &[PolyCoef]) -> f64 {
    coefs.iter().map(|&(m, c)| c * mono_value(u, m)).sum()
}

impl TableSpec {
    /// Encode as format v1 (and validate the result with [`table::parse`]).
    pub fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        if self.channels.len() > MAX_TEMPS {
            return Err(EncodeError::ChannelName { channel: MAX_TEMPS });
        }
        for (i, c) in self.channels.iter().enumerate() {
            if c.is_empty() || c.len() > CHANNEL_NAME_LEN || c.contains('\0') {
                return Err(EncodeError::ChannelName { channel: i });
            }
        }
        let mut w = W(Vec::with_capacity(1024));
        w.0.extend_from_slice(&MAGIC);
        w.u16(FORMAT_VERSION);
        w.u16(0);
        w.u32(0); // total length, patched below
        w.u16(self.terms.len().min(u16::MAX as usize) as u16);
        w.u8(self.channels.len() as u8);
        w.u8(UNITS_NM_MC);
        w.0.extend_from_slice(&self.created_unix_s.to_le_bytes());
        w.0.extend_from_slice(&self.source_hash);
        for ch in 0..MAX_TEMPS {
            let mut name = [0u8; CHANNEL_NAME_LEN];
            if let Some(c) = self.channels.get(ch) {
                name[..c.len()].copy_from_slice(c.as_bytes());
            }
            w.0.extend_from_slice(&name);
        }
        let e = &self.envelope;
        for v in e
            .travel_min_nm
            .iter()
            .chain(&e.travel_max_nm)
            .chain(&e.max_corr_nm)
        {
            w.i32(*v);
        }
        w.i32(e.max_slew_nm_per_ms);
        for v in e.temp_min_mc.iter().chain(&e.temp_max_mc) {
            w.i32(*v);
        }
        w.i32(e.tool_min_nm);
        w.i32(e.tool_max_nm);
        for v in self
            .scaling
            .centre_nm
            .iter()
            .chain(&self.scaling.half_span_nm)
        {
            w.i32(*v);
        }
        let mask = self
            .outputs
            .iter()
            .enumerate()
            .fold(0u8, |m, (i, &p)| if p { m | 1 << i } else { m });
        w.u8(mask);
        w.0.extend_from_slice(&[0, 0, 0]);
        debug_assert_eq!(w.0.len(), FIXED_LEN);
        for (ti, t) in self.terms.iter().enumerate() {
            let shape = |what| EncodeError::Shape { term: ti, what };
            let hdr = w.0.len();
            let (kind, outs, aux) = match t {
                TermSpec::Poly { output, .. } => (1u8, 1u8 << (output & 7), 0u8),
                TermSpec::Periodic { output, axis, .. } => (2, 1 << (output & 7), *axis),
                TermSpec::Thermal {
                    output, channel, ..
                } => (3, 1 << (output & 7), *channel),
                TermSpec::Reversal { output, axis, .. } => (4, 1 << (output & 7), *axis),
                TermSpec::Abbe { output, .. } => (5, 1 << (output & 7), 0),
                TermSpec::Mlp(m) => (6, m.outputs.iter().fold(0u8, |a, &o| a | 1 << (o & 7)), 0),
                TermSpec::Grid(g) => (7, 1 << (g.output & 7), 0),
            };
            w.0.extend_from_slice(&[kind, outs, aux, 0]);
            w.u32(0); // body length, patched below
            match t {
                TermSpec::Poly { coefs, .. } | TermSpec::Abbe { coefs, .. } => w.poly(coefs),
                TermSpec::Thermal {
                    t_ref_mc,
                    coefs_nm_per_k,
                    ..
                } => {
                    w.i32(*t_ref_mc);
                    w.u32(0);
                    w.poly(coefs_nm_per_k);
                }
                TermSpec::Periodic {
                    period_nm,
                    sin_nm,
                    cos_nm,
                    ..
                } => {
                    if sin_nm.len() != cos_nm.len() {
                        return Err(shape("sin_nm and cos_nm differ in length"));
                    }
                    w.i32(*period_nm);
                    w.u8(sin_nm.len().min(255) as u8);
                    w.0.extend_from_slice(&[0, 0, 0]);
                    for (a, b) in sin_nm.iter().zip(cos_nm) {
                        w.f64(*a);
                        w.f64(*b);
                    }
                }
                TermSpec::Reversal {
                    transition_nm,
                    amplitude_nm,
                    ..
                } => {
                    w.i32(*transition_nm);
                    w.u32(0);
                    w.f64(*amplitude_nm);
                }
                TermSpec::Mlp(m) => {
                    let n_in = m.inputs.len();
                    let n_out = m.outputs.len();
                    if m.hidden.is_empty() || m.hidden.len() > table::MAX_HIDDEN_LAYERS {
                        return Err(shape("an MLP needs 1 or 2 hidden layers"));
                    }
                    if m.hidden
                        .iter()
                        .any(|l| l.bias.len() > table::MAX_HIDDEN_UNITS)
                    {
                        return Err(shape(
                            "an MLP hidden layer holds at most 32 units (the table format's and the firmware's limit): fit a smaller network",
                        ));
                    }
                    if m.out_min_nm.len() != n_out || m.out_max_nm.len() != n_out {
                        return Err(shape("output scaling length differs from the output count"));
                    }
                    let mut prev = n_in;
                    for l in m.hidden.iter().chain(std::iter::once(&m.output)) {
                        let units = l.bias.len();
                        if units == 0 || units > 255 || l.weights.len() != units * prev {
                            return Err(shape("layer weights must be units × inputs"));
                        }
                        prev = units;
                    }
                    if m.output.bias.len() != n_out {
                        return Err(shape("output layer width differs from the output count"));
                    }
                    if n_in > 255 {
                        return Err(shape("too many MLP inputs"));
                    }
                    w.u8(n_in as u8);
                    w.u8(m.hidden.len() as u8);
                    w.u8(m.hidden[0].bias.len() as u8);
                    w.u8(m.hidden.get(1).map_or(0, |l| l.bias.len() as u8));
                    for i in &m.inputs {
                        let src = match i.source {
                            MlpSource::Pos(a) => a,
                            MlpSource::Temp(c) => 3u8.saturating_add(c),
                        };
                        w.0.extend_from_slice(&[src, 0, 0, 0]);
                        w.f64(i.min);
                        w.f64(i.max);
                    }
                    for (lo, hi) in m.out_min_nm.iter().zip(&m.out_max_nm) {
                        w.f64(*lo);
                        w.f64(*hi);
                    }
                    for l in m.hidden.iter().chain(std::iter::once(&m.output)) {
                        for v in l.weights.iter().chain(&l.bias) {
                            w.f64(*v);
                        }
                    }
                }
                TermSpec::Grid(g) => {
                    let n: usize = g.axes.iter().map(|a| a.nodes as usize).product();
                    if g.values_nm.len() != n {
                        return Err(shape(
                            "grid value count differs from the product of node counts",
                        ));
                    }
                    for a in &g.axes {
                        w.u16(a.nodes);
                        w.u16(0);
                        w.i32(a.origin_nm);
                        w.i32(a.step_nm);
                    }
                    for v in &g.values_nm {
                        w.f64(*v);
                    }
                }
            }
            let body_len = (w.0.len() - hdr - table::TERM_HEADER_LEN) as u32;
            w.0[hdr + 4..hdr + 8].copy_from_slice(&body_len.to_le_bytes());
        }
        let total = w.0.len() + CRC_LEN;
        if total > table::MAX_TABLE_LEN {
            return Err(EncodeError::TooLarge { bytes: total });
        }
        w.0[8..12].copy_from_slice(&(total as u32).to_le_bytes());
        let crc = CRC32.checksum(&w.0);
        w.u32(crc);
        table::parse(&w.0).map_err(EncodeError::Invalid)?;
        Ok(w.0)
    }

    /// Decode a parsed table back into its spec, the inverse of
    /// [`TableSpec::encode`]: `from_table(&parse(&spec.encode()?)?) == spec`
    /// and re-encoding gives the same bytes (both proptested). With it the
    /// host evaluates any `.bin` in f64 ([`TableSpec::eval_f64`]), e.g. to
    /// check a table someone else exported. Total: `parse` has validated
    /// every field the accessors read.
    pub fn from_table(t: &table::Table<'_>) -> TableSpec {
        use table::TermView;
        let poly = |c: table::PolyCoefs<'_>| c.iter().collect::<Vec<PolyCoef>>();
        let terms = t
            .terms()
            .map(|term| match term.view() {
                TermView::Poly { output, coefs } => TermSpec::Poly {
                    output: output as u8,
                    coefs: poly(coefs),
                },
                TermView::Abbe { output, coefs } => TermSpec::Abbe {
                    output: output as u8,
                    coefs: poly(coefs),
                },
                TermView::Thermal {
                    output,
                    channel,
                    t_ref_mc,
                    coefs,
                } => TermSpec::Thermal {
                    output: output as u8,
                    channel: channel as u8,
                    t_ref_mc,
                    coefs_nm_per_k: poly(coefs),
                },
                v @ TermView::Periodic {
                    output,
                    axis,
                    period_nm,
                    harmonics,
                    ..
                } => {
                    let (sin_nm, cos_nm) = (1..=harmonics).map(|k| v.harmonic(k)).unzip();
                    TermSpec::Periodic {
                        output: output as u8,
                        axis: axis as u8,
                        period_nm,
                        sin_nm,
                        cos_nm,
                    }
                }
                TermView::Reversal {
                    output,
                    axis,
                    transition_nm,
                    amplitude_nm,
                } => TermSpec::Reversal {
                    output: output as u8,
                    axis: axis as u8,
                    transition_nm,
                    amplitude_nm,
                },
                TermView::Mlp { outputs, net } => {
                    let inputs = (0..net.n_inputs())
                        .map(|i| {
                            let r = net.input(i);
                            MlpInputSpec {
                                source: if r.source < 3 {
                                    MlpSource::Pos(r.source)
                                } else {
                                    MlpSource::Temp(r.source - 3)
                                },
                                min: r.min,
                                max: r.max,
                            }
                        })
                        .collect();
                    // Parameters in the table's order: per layer W (row-major,
                    // units × inputs) then b; hidden layers, then the output layer.
                    let mut k = 0;
                    let mut layer = |units: usize, prev: usize| {
                        let weights = (k..k + units * prev).map(|i| net.param(i)).collect();
                        k += units * prev;
                        let bias = (k..k + units).map(|i| net.param(i)).collect();
                        k += units;
                        LayerSpec { weights, bias }
                    };
                    let mut prev = net.n_inputs();
                    let mut hidden = Vec::new();
                    for &units in net.hidden() {
                        hidden.push(layer(units, prev));
                        prev = units;
                    }
                    let output = layer(net.n_outputs(), prev);
                    let (out_min_nm, out_max_nm) =
                        (0..net.n_outputs()).map(|j| net.output_range(j)).unzip();
                    TermSpec::Mlp(MlpSpec {
                        outputs: (0..3u8).filter(|o| outputs & (1 << o) != 0).collect(),
                        inputs,
                        hidden,
                        output,
                        out_min_nm,
                        out_max_nm,
                    })
                }
                TermView::Grid { output, grid } => TermSpec::Grid(GridSpec {
                    output: output as u8,
                    axes: core::array::from_fn(|a| {
                        let r = grid.axis(a);
                        GridAxisSpec {
                            nodes: r.nodes,
                            origin_nm: r.origin_nm,
                            step_nm: r.step_nm,
                        }
                    }),
                    values_nm: (0..grid.len()).map(|i| grid.value(i)).collect(),
                }),
            })
            .collect();
        TableSpec {
            created_unix_s: t.created_unix_s(),
            source_hash: t.source_hash(),
            channels: (0..t.channel_count())
                .map(|ch| t.channel_name(ch).unwrap_or_default().to_string())
                .collect(),
            envelope: t.envelope(),
            scaling: t.scaling(),
            outputs: core::array::from_fn(|o| t.has_output(o)),
            terms,
        }
    }

    /// The f64 reference: the model's corrections in nm, without the envelope
    /// (no clamping of inputs or outputs). Absent outputs are 0.
    pub fn eval_f64(&self, inp: &InputsF64) -> [f64; 3] {
        let mut u = [0.0; 3];
        for (a, ua) in u.iter_mut().enumerate() {
            *ua = (inp.pos_nm[a] - self.scaling.centre_nm[a] as f64)
                / self.scaling.half_span_nm[a] as f64;
        }
        let mut out = [0.0f64; 3];
        for t in &self.terms {
            match t {
                TermSpec::Poly { output, coefs } => {
                    out[*output as usize % 3] += poly_value(&u, coefs)
                }
                TermSpec::Periodic {
                    output,
                    axis,
                    period_nm,
                    sin_nm,
                    cos_nm,
                } => {
                    let period = *period_nm as f64;
                    let r = inp.pos_nm[*axis as usize % 3].rem_euclid(period);
                    let mut v = 0.0;
                    for (k, (a, b)) in sin_nm.iter().zip(cos_nm).enumerate() {
                        let ph = 2.0 * std::f64::consts::PI * (k + 1) as f64 * r / period;
                        v += a * ph.sin() + b * ph.cos();
                    }
                    out[*output as usize % 3] += v;
                }
                TermSpec::Thermal {
                    output,
                    channel,
                    t_ref_mc,
                    coefs_nm_per_k,
                } => {
                    let dt_k =
                        inp.temp_c[*channel as usize % MAX_TEMPS] - *t_ref_mc as f64 / 1000.0;
                    out[*output as usize % 3] += dt_k * poly_value(&u, coefs_nm_per_k);
                }
                TermSpec::Reversal {
                    output,
                    axis,
                    amplitude_nm,
                    ..
                } => {
                    out[*output as usize % 3] += amplitude_nm * inp.rev[*axis as usize % 3];
                }
                TermSpec::Abbe { output, coefs } => {
                    out[*output as usize % 3] += inp.tool_nm * poly_value(&u, coefs)
                }
                TermSpec::Mlp(m) => {
                    let mut x: Vec<f64> = m
                        .inputs
                        .iter()
                        .map(|i| {
                            let v = match i.source {
                                MlpSource::Pos(a) => inp.pos_nm[a as usize % 3],
                                MlpSource::Temp(c) => inp.temp_c[c as usize % MAX_TEMPS] * 1000.0,
                            };
                            2.0 * (v - i.min) / (i.max - i.min) - 1.0
                        })
                        .collect();
                    for l in &m.hidden {
                        x = dense(l, &x).into_iter().map(f64::tanh).collect();
                    }
                    let y = dense(&m.output, &x);
                    for (j, &o) in m.outputs.iter().enumerate() {
                        let (lo, hi) = (m.out_min_nm[j], m.out_max_nm[j]);
                        out[o as usize % 3] += (y[j] + 1.0) * (hi - lo) / 2.0 + lo;
                    }
                }
                TermSpec::Grid(g) => out[g.output as usize % 3] += grid_f64(g, &inp.pos_nm),
            }
        }
        for (o, v) in out.iter_mut().enumerate() {
            if !self.outputs[o] {
                *v = 0.0;
            }
        }
        out
    }
}

fn dense(l: &LayerSpec, x: &[f64]) -> Vec<f64> {
    let n = x.len();
    l.bias
        .iter()
        .enumerate()
        .map(|(j, b)| b + (0..n).map(|i| l.weights[j * n + i] * x[i]).sum::<f64>())
        .collect()
}

fn grid_f64(g: &GridSpec, pos: &[f64; 3]) -> f64 {
    let mut idx = [0usize; 3];
    let mut t = [0.0f64; 3];
    for a in 0..3 {
        let ax = g.axes[a];
        if ax.nodes < 2 {
            continue;
        }
        let span = (ax.nodes - 1) as f64 * ax.step_nm as f64;
        let d = (pos[a] - ax.origin_nm as f64).clamp(0.0, span);
        let f = d / ax.step_nm as f64;
        let i = (f.floor() as usize).min(ax.nodes as usize - 2);
        idx[a] = i;
        t[a] = f - i as f64;
    }
    let nx = g.axes[0].nodes as usize;
    let nxy = nx * g.axes[1].nodes as usize;
    let mut v = 0.0;
    for corner in 0..8 {
        let mut wgt = 1.0;
        let mut off = 0;
        for a in 0..3 {
            let hi = corner >> a & 1 == 1;
            let stride = [1, nx, nxy][a];
            if g.axes[a].nodes < 2 {
                if hi {
                    wgt = 0.0;
                }
                continue;
            }
            wgt *= if hi { t[a] } else { 1.0 - t[a] };
            off += (idx[a] + hi as usize) * stride;
        }
        if wgt != 0.0 {
            v += wgt * g.values_nm[off];
        }
    }
    v
}
