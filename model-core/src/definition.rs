//! A table's own definition — the f64 sum of its terms on inputs held to
//! its envelope, each output clamped to its max |correction| — evaluated
//! from the parsed bytes, without allocation (so the board runs it too),
//! and the check that the prepared model's fixed-point and f32 evaluations
//! stay within [`DEFINITION_BOUND_NM`] of it ([`check_definition`]).
//!
//! Why: a table can pass `parse` and load while its fixed point is far from
//! what its terms say — an Abbe term whose coefficients sum near the loader's
//! limit is rounded to 2^-16 before it is multiplied by an arm of up to 2^31
//! nm (tens of µm wrong), a network with 10^9 weights amplifies the Q28
//! rounding of its inputs past the whole range of tanh. `trueaxis export`
//! measures its table against the *fitted model*; this measures any table
//! against *itself*, which is what the board can check.
//!
//! The check has two parts:
//!
//! - **A static bound** ([`static_bound_nm`]) for the roundings whose size
//!   is the same everywhere but that show only where the definition is not
//!   clamped — possibly a band too thin for any sample (where a polynomial
//!   times a large factor is near 0, where a steep network's unit crosses
//!   0): a thermal or Abbe term's polynomial rounded to its binary scale
//!   before the factor multiplies it, an MLP's input and weight roundings
//!   carried through its layers (tanh is 1-Lipschitz), and in f32 the
//!   rounding of every term linear in its coefficients and of each
//!   output's sum (2^-24 of the magnitudes involved, which the
//!   coefficients bound).
//! - **The evaluations compared** on [`DEFINITION_POINTS`] inputs spread
//!   over the envelope ([`check_point`]): the eight travel corners, then
//!   the travel ends, the scaling centre and 1 nm beside it, the ends and
//!   middles of the temperature and tool ranges and the reversal states
//!   ±1, ½ and 0 combined by a fixed pseudo-random sequence, then as many
//!   uniform draws. Both evaluations (fixed point and f32) must be within
//!   the bound of the definition at every point: this covers what the
//!   static bound does not (sine, interpolation, anything the analysis
//!   missed).
//!
//! The bound is absolute: a realistic table is within 1 nm (the accuracy
//! tests of `tests/accuracy.rs`), so 100 nm refuses only tables whose
//! evaluation is not what they say. `tests/definition.rs` property-tests
//! it over the edge-table generator: every table the check accepts is
//! within the bound at random inputs of its envelope.
//!
//! Every function is `#[inline]`: compiled only into the crates that call
//! it. As ordinary functions they were compiled into model-core's object
//! whether used or not, and under the images' fat LTO that changed how
//! the bench image's `eval_f32` compiled (`poly_deg5_f32` 793 → 1159
//! instructions, over its cost estimate) without the image calling any.
//!
//! Nothing here panics for any parsed table (the board runs it): holds are
//! `max`/`min`, not `clamp`, whose panic message would also pull f64
//! formatting into the board's image.
#![allow(clippy::needless_range_loop)] // per-output loops mirror [ex, ey, ez]
#![allow(clippy::manual_clamp)] // see above

use crate::eval::{Inputs, ModelCap, MAX_TEMPS};
use crate::table::{Table, TermKind, TermView};

/// The most the board's evaluations (fixed point and f32) may differ from
/// the table's definition at any checked input, nm.
pub const DEFINITION_BOUND_NM: u32 = 100;

/// Inputs the evaluations are compared on.
pub const DEFINITION_POINTS: u32 = 256;

/// Which evaluation departs from the definition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EvalPath {
    /// The integer evaluation the board's correction loop runs.
    Fixed,
    /// The f32 evaluation.
    F32,
}

impl EvalPath {
    /// "fixed-point" or "f32".
    #[inline]
    pub fn name(self) -> &'static str {
        match self {
            EvalPath::Fixed => "fixed-point",
            EvalPath::F32 => "f32",
        }
    }
}

/// How far an evaluation departs from the definition, and where.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Departure {
    /// The evaluation.
    pub path: EvalPath,
    /// The output (0 = ex).
    pub output: u8,
    /// |evaluation − definition|, nm, rounded up (saturating).
    pub error_nm: u32,
    /// The input, or `None` for the static bound (no single point).
    pub at: Option<Inputs>,
    /// For the static bound: the term (index in the table, kind) whose
    /// rounding adds the most.
    pub term: Option<(u8, TermKind)>,
}

/// The f64 value of `table`'s terms at `inp` as given (no envelope: no
/// input held, no output clamped), the definition of `TableSpec::eval_f64`
/// read from the bytes: u = (p − centre) / half-span, polynomials Σ c·u^m,
/// periodic Σ a_k sin + b_k cos of 2πk·(p mod period)/period, thermal
/// (T − T_ref)·poly with T in °C, reversal amplitude × state (Q30 / 2^30),
/// Abbe arm × poly, the MLP's tanh layers with min–max scaling, the grid's
/// multilinear interpolation held at its edges. Absent outputs are 0.
#[inline]
pub fn eval_f64(table: &Table<'_>, inp: &Inputs) -> [f64; 3] {
    let sc = table.scaling();
    let pos = inp.pos_nm.map(f64::from);
    let u: [f64; 3] = core::array::from_fn(|a| {
        (pos[a] - f64::from(sc.centre_nm[a])) / f64::from(sc.half_span_nm[a])
    });
    let temp_c = |ch: usize| f64::from(inp.temp_mc[ch % MAX_TEMPS]) / 1000.0;
    let mut out = [0.0f64; 3];
    for term in table.terms() {
        match term.view() {
            TermView::Poly { output, coefs } => out[output % 3] += poly(&u, coefs),
            v @ TermView::Periodic {
                output,
                axis,
                period_nm,
                harmonics,
                ..
            } => {
                let period = f64::from(period_nm);
                let mut r = libm::fmod(pos[axis % 3], period);
                if r < 0.0 {
                    r += period;
                }
                let mut s = 0.0;
                for k in 1..=harmonics {
                    let (a, b) = v.harmonic(k);
                    let ph = 2.0 * core::f64::consts::PI * k as f64 * r / period;
                    s += a * libm::sin(ph) + b * libm::cos(ph);
                }
                out[output % 3] += s;
            }
            TermView::Thermal {
                output,
                channel,
                t_ref_mc,
                coefs,
            } => {
                let dt_k = temp_c(channel) - f64::from(t_ref_mc) / 1000.0;
                out[output % 3] += dt_k * poly(&u, coefs);
            }
            TermView::Reversal {
                output,
                axis,
                amplitude_nm,
                ..
            } => {
                let rev = f64::from(inp.rev_q30[axis % 3]) / (1u64 << 30) as f64;
                out[output % 3] += amplitude_nm * rev;
            }
            TermView::Abbe { output, coefs } => {
                out[output % 3] += f64::from(inp.tool_nm) * poly(&u, coefs)
            }
            TermView::Mlp { outputs, net } => {
                const W: usize = crate::limits::MAX_HIDDEN_UNITS;
                let n_in = net.n_inputs();
                let mut x = [0.0f64; W];
                for (i, xi) in x.iter_mut().enumerate().take(n_in) {
                    let r = net.input(i);
                    let v = if r.source < 3 {
                        pos[r.source as usize]
                    } else {
                        temp_c(r.source as usize - 3) * 1000.0
                    };
                    *xi = 2.0 * (v - r.min) / (r.max - r.min) - 1.0;
                }
                // Parameters in the table's order: per layer W (row-major,
                // units × inputs) then b; the hidden layers, then the output.
                let mut k = 0;
                let mut prev = n_in;
                for &units in net.hidden() {
                    let mut h = [0.0f64; W];
                    dense(&net, &mut k, &x[..prev], &mut h[..units]);
                    for v in h.iter_mut().take(units) {
                        *v = libm::tanh(*v);
                    }
                    x = h;
                    prev = units;
                }
                let mut y = [0.0f64; 3];
                let n_out = net.n_outputs();
                dense(&net, &mut k, &x[..prev], &mut y[..n_out]);
                let mut j = 0;
                for (o, v) in out.iter_mut().enumerate() {
                    if outputs & (1 << o) != 0 && j < n_out {
                        let (lo, hi) = net.output_range(j);
                        *v += (y[j] + 1.0) * (hi - lo) / 2.0 + lo;
                        j += 1;
                    }
                }
            }
            TermView::Grid { output, grid } => out[output % 3] += grid_value(&grid, &pos),
        }
    }
    for (o, v) in out.iter_mut().enumerate() {
        if !table.has_output(o) {
            *v = 0.0;
        }
    }
    out
}

/// The definition at `inp` as the board applies it: the inputs held to
/// the envelope (positions to the travel, the channels the table declares
/// to their ranges, the tool arm to its range), each output clamped to its
/// max |correction|.
#[inline]
pub fn definition_nm(table: &Table<'_>, inp: &Inputs) -> [f64; 3] {
    let env = table.envelope();
    let mut held = *inp;
    for a in 0..3 {
        held.pos_nm[a] = inp.pos_nm[a]
            .max(env.travel_min_nm[a])
            .min(env.travel_max_nm[a]);
    }
    for ch in 0..table.channel_count().min(MAX_TEMPS) {
        held.temp_mc[ch] = inp.temp_mc[ch]
            .max(env.temp_min_mc[ch])
            .min(env.temp_max_mc[ch]);
    }
    held.tool_nm = inp.tool_nm.max(env.tool_min_nm).min(env.tool_max_nm);
    let v = eval_f64(table, &held);
    core::array::from_fn(|o| {
        let max = f64::from(env.max_corr_nm[o]);
        // A non-finite definition is no definition: it departs from any
        // evaluation (the check refuses the table).
        if v[o].is_finite() {
            v[o].max(-max).min(max)
        } else {
            f64::INFINITY
        }
    })
}

/// y = W·x + b for the next layer of `net`'s parameters (from `k` on).
#[inline]
fn dense(net: &crate::table::MlpView<'_>, k: &mut usize, x: &[f64], y: &mut [f64]) {
    let n = x.len();
    for (j, yj) in y.iter_mut().enumerate() {
        let mut s = 0.0;
        for (i, xi) in x.iter().enumerate() {
            s += net.param(*k + j * n + i) * xi;
        }
        *yj = s;
    }
    *k += y.len() * n;
    for yj in y.iter_mut() {
        *yj += net.param(*k);
        *k += 1;
    }
}

#[inline]
fn poly(u: &[f64; 3], coefs: crate::table::PolyCoefs<'_>) -> f64 {
    coefs
        .iter()
        .map(|(m, c)| {
            let mut v = c;
            for a in 0..3 {
                for _ in 0..m[a] {
                    v *= u[a];
                }
            }
            v
        })
        .sum()
}

#[inline]
fn grid_value(g: &crate::table::GridView<'_>, pos: &[f64; 3]) -> f64 {
    let mut idx = [0usize; 3];
    let mut t = [0.0f64; 3];
    let axes = [g.axis(0), g.axis(1), g.axis(2)];
    for a in 0..3 {
        let ax = axes[a];
        if ax.nodes < 2 {
            continue;
        }
        let span = f64::from(ax.nodes - 1) * f64::from(ax.step_nm);
        let d = (pos[a] - f64::from(ax.origin_nm)).max(0.0).min(span);
        let f = d / f64::from(ax.step_nm);
        let i = (libm::floor(f) as usize).min(usize::from(ax.nodes) - 2);
        idx[a] = i;
        t[a] = f - i as f64;
    }
    let nx = usize::from(axes[0].nodes);
    let nxy = nx * usize::from(axes[1].nodes);
    let mut v = 0.0;
    for corner in 0..8 {
        let mut wgt = 1.0;
        let mut off = 0;
        for a in 0..3 {
            let hi = corner >> a & 1 == 1;
            if axes[a].nodes < 2 {
                if hi {
                    wgt = 0.0;
                }
                continue;
            }
            wgt *= if hi { t[a] } else { 1.0 - t[a] };
            off += (idx[a] + usize::from(hi)) * [1, nx, nxy][a];
        }
        if wgt != 0.0 {
            v += wgt * g.value(off);
        }
    }
    v
}

/// The largest |factor| a thermal (ΔT, m°C) or Abbe (arm, nm) term sees
/// inside the envelope.
#[inline]
fn max_factor(table: &Table<'_>, view: &TermView<'_>) -> f64 {
    let env = table.envelope();
    match *view {
        TermView::Thermal {
            channel, t_ref_mc, ..
        } => {
            let ch = channel % MAX_TEMPS;
            let lo = (i64::from(env.temp_min_mc[ch]) - i64::from(t_ref_mc)).abs();
            let hi = (i64::from(env.temp_max_mc[ch]) - i64::from(t_ref_mc)).abs();
            lo.max(hi) as f64
        }
        TermView::Abbe { .. } => {
            let lo = i64::from(env.tool_min_nm).abs();
            let hi = i64::from(env.tool_max_nm).abs();
            lo.max(hi) as f64
        }
        _ => 0.0,
    }
}

/// The largest |value| `view` can add to an output inside the envelope,
/// nm, per output (a network's output j can exceed its range: its output
/// layer is linear, |y| ≤ Σ|w| + |b| with |tanh| ≤ 1).
#[inline]
fn max_term_nm(table: &Table<'_>, view: &TermView<'_>) -> [f64; 3] {
    let mut m = [0.0f64; 3];
    let sum = |c: crate::table::PolyCoefs<'_>| c.iter().map(|(_, c)| c.abs()).sum::<f64>();
    match *view {
        TermView::Poly { output, coefs } => m[output % 3] = sum(coefs),
        TermView::Thermal { output, coefs, .. } => {
            m[output % 3] = sum(coefs) * max_factor(table, view) / 1000.0
        }
        TermView::Abbe { output, coefs } => m[output % 3] = sum(coefs) * max_factor(table, view),
        TermView::Reversal {
            output,
            amplitude_nm,
            ..
        } => m[output % 3] = amplitude_nm.abs(),
        TermView::Periodic {
            output, harmonics, ..
        } => {
            m[output % 3] = (1..=harmonics)
                .map(|k| {
                    let (a, b) = view.harmonic(k);
                    a.abs() + b.abs()
                })
                .sum()
        }
        TermView::Grid { output, grid } => {
            m[output % 3] = (0..grid.len())
                .map(|i| grid.value(i).abs())
                .fold(0.0, f64::max)
        }
        TermView::Mlp { outputs, net } => {
            let prev = net.hidden().last().copied().unwrap_or(net.n_inputs());
            // The output layer's parameters are the last (prev + 1)·n_out.
            let n_params: usize = {
                let mut n = 0;
                let mut p = net.n_inputs();
                for &u in net.hidden() {
                    n += u * p + u;
                    p = u;
                }
                n
            };
            let n_out = net.n_outputs();
            let mut j = 0;
            for (o, mo) in m.iter_mut().enumerate() {
                if outputs & (1 << o) == 0 || j >= n_out {
                    continue;
                }
                let w: f64 = (0..prev)
                    .map(|i| net.param(n_params + j * prev + i).abs())
                    .sum();
                let b = net.param(n_params + n_out * prev + j).abs();
                let (lo, hi) = net.output_range(j);
                *mo = (w + b + 1.0) * (hi - lo).abs() / 2.0 + lo.abs();
                j += 1;
            }
        }
    }
    m
}

/// The most an MLP term's evaluations can depart from its definition, per
/// output, nm: (fixed point, f32). The errors of each layer's inputs are
/// carried through the layer — tanh is 1-Lipschitz — and each layer adds
/// its own: fixed point, the weights' rounding to the layer's binary scale
/// (½ unit each, times the inputs' magnitude), the inputs' Q28 rounding
/// and the pre-activation's to Q26, and tanh_q30's 5·10^-9; f32, 2^-24 of
/// every product and sum, and tanh_f32's 5·10^-7. `f64::INFINITY` for a
/// layer the loader would refuse.
#[inline]
fn mlp_bound_nm(table: &Table<'_>, outputs: u8, net: &crate::table::MlpView<'_>) -> [[f64; 3]; 2] {
    const W: usize = crate::limits::MAX_HIDDEN_UNITS;
    let env = table.envelope();
    let eps = libm::exp2(-24.0);
    let n_in = net.n_inputs();
    let hidden = net.hidden();
    let n_out = net.n_outputs();
    // The scaled inputs' largest magnitude over the envelope (what the
    // loader checks to be ≤ 7) and their mid-point residuals, which the
    // loader folds into the first layer's biases.
    let mut x_max = [0.0f64; crate::limits::MAX_MLP_INPUTS];
    let mut resid = [0.0f64; crate::limits::MAX_MLP_INPUTS];
    for i in 0..n_in.min(crate::limits::MAX_MLP_INPUTS) {
        let r = net.input(i);
        let mid_true = (r.min + r.max) / 2.0;
        let mid = libm::round(mid_true)
            .max(i32::MIN as f64)
            .min(i32::MAX as f64);
        let k = 2.0 / (r.max - r.min);
        resid[i] = (mid - mid_true) * k;
        let (lo, hi) = match r.source {
            s @ 0..=2 => (env.travel_min_nm[s as usize], env.travel_max_nm[s as usize]),
            s => {
                let ch = (s as usize - 3) % MAX_TEMPS;
                (env.temp_min_mc[ch], env.temp_max_mc[ch])
            }
        };
        x_max[i] = ((f64::from(lo) - mid) * k)
            .abs()
            .max(((f64::from(hi) - mid) * k).abs());
    }
    // Errors of the current layer's inputs (per unit, the worst), and
    // their magnitude: (fixed, f32).
    let mut e = [libm::exp2(-28.0), 0.0];
    let mut mag = x_max[..n_in].iter().copied().fold(0.0, f64::max);
    let (mut k, mut prev) = (0usize, n_in);
    for (layer, &units) in hidden.iter().enumerate() {
        let mut worst = 0.0f64;
        // Fixed point: the inputs' errors through the weights (absolute),
        // and the weights' and bias's rounding (units of 2^-q, q known
        // once every row is seen). f32: both absolute.
        let (mut carried, mut e32) = (0.0f64, 0.0f64);
        for j in 0..units.min(W) {
            let row = |i: usize| net.param(k + j * prev + i);
            let mut b = net.param(k + units * prev + j);
            if layer == 0 {
                for (i, r) in resid.iter().enumerate().take(prev) {
                    b += row(i) * r;
                }
            }
            let w_sum: f64 = (0..prev).map(|i| row(i).abs()).sum();
            worst = worst.max(w_sum + b.abs());
            carried = carried.max(w_sum * e[0]);
            e32 = e32.max(w_sum * e[1] + (prev as f64 + 3.0) * eps * (w_sum * mag + b.abs()));
        }
        let Some(q) = crate::eval::mlp_layer_q(worst) else {
            return [[f64::INFINITY; 3]; 2];
        };
        let units_2q = (prev as f64 * mag + 1.0) * 0.5;
        // Then the pre-activation's rounding to Q26 and tanh's own error.
        e[0] = carried
            + units_2q * libm::exp2(-f64::from(q))
            + libm::exp2(-27.0)
            + 5e-9
            + libm::exp2(-30.0);
        e[1] = e32 + 5e-7;
        k += units * prev + units;
        prev = units;
        mag = 1.0;
    }
    // The output layer, its weights and biases in nm (the output range
    // folded in, as the loader does).
    let mut out = [[0.0f64; 3]; 2];
    let mut worst = 0.0f64;
    let mut rows = [[0.0f64; 2]; 3];
    for j in 0..n_out.min(3) {
        let (lo, hi) = net.output_range(j);
        let s = (hi - lo) / 2.0;
        let w_sum: f64 = (0..prev)
            .map(|i| (net.param(k + j * prev + i) * s).abs())
            .sum();
        let b = (net.param(k + n_out * prev + j) * s + (hi + lo) / 2.0).abs();
        worst = worst.max(w_sum + b);
        rows[j] = [w_sum, b];
    }
    let q = match crate::eval::mlp_layer_q(worst) {
        Some(q) => q,
        None => return [[f64::INFINITY; 3]; 2],
    };
    let mut j = 0;
    for o in 0..3 {
        if outputs & (1 << o) == 0 || j >= n_out.min(3) {
            continue;
        }
        let [w_sum, b] = rows[j];
        let n = prev as f64;
        out[0][o] = w_sum * e[0] + (n + 1.0) * 0.5 * libm::exp2(-f64::from(q)) + 1.0;
        out[1][o] = w_sum * e[1] + (n + 3.0) * eps * (w_sum + b) + 1.0;
        j += 1;
    }
    out
}

/// The static part of the check (module doc): per evaluation path and
/// output, what rounding can add anywhere in the envelope, nm, and the
/// term that adds the most.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StaticBound {
    /// Per path ([`EvalPath::Fixed`], [`EvalPath::F32`]) and output, nm
    /// (`f64::INFINITY` for a scale the loader would refuse).
    pub nm: [[f64; 3]; 2],
    /// Per path and output: the term (index, kind) that adds the most.
    pub worst_term: [[Option<(u8, TermKind)>; 3]; 2],
}

impl StaticBound {
    #[inline]
    fn add(
        &mut self,
        path: usize,
        output: usize,
        term: (usize, TermKind),
        v: f64,
        best: &mut [[f64; 3]; 2],
    ) {
        self.nm[path][output] += v;
        if beyond(v, best[path][output]) {
            best[path][output] = v;
            self.worst_term[path][output] = u8::try_from(term.0).ok().map(|i| (i, term.1));
        }
    }
}

/// The static bound of `table` ([`StaticBound`]): for the fixed-point
/// path, what a thermal or Abbe term's rounding can add (its polynomial
/// rounded to the loader's binary scale q before the factor multiplies it,
/// by the monomial vector or by the separable path's rows)
/// and an MLP's ([`mlp_bound_nm`]); for the f32 path, the rounding of every
/// term linear in its coefficients (polynomial, thermal, Abbe, reversal),
/// an MLP's, and that of the sum of all terms of the output — each f32
/// operation rounds to 2^-24 of its magnitude, and a term's magnitude is
/// bounded by its coefficients ([`max_term_nm`]). The other terms' own
/// evaluation errors (sine, interpolation) are what the sampled points
/// measure.
#[inline]
pub fn static_bound_nm(table: &Table<'_>) -> StaticBound {
    const FIXED: usize = 0;
    const F32: usize = 1;
    let eps = libm::exp2(-24.0);
    let mut sb = StaticBound::default();
    let mut best = [[0.0f64; 3]; 2];
    let mut total = [0.0f64; 3];
    let mut terms = [0.0f64; 3];
    let horner = crate::eval::horner_plan(table);
    let mut fac = 0;
    for (i, term) in table.terms().enumerate() {
        let view = term.view();
        let i = (i, term.kind);
        let m = max_term_nm(table, &view);
        for o in 0..3 {
            total[o] += m[o];
            terms[o] += f64::from(u8::from(m[o] > 0.0));
        }
        if let TermView::Mlp { outputs, net } = view {
            let bound = mlp_bound_nm(table, outputs, &net);
            for path in [FIXED, F32] {
                for o in 0..3 {
                    sb.add(path, o, i, bound[path][o], &mut best);
                }
            }
            continue;
        }
        let (output, coefs) = match view {
            TermView::Poly { output, coefs }
            | TermView::Thermal { output, coefs, .. }
            | TermView::Abbe { output, coefs } => (output % 3, Some(coefs)),
            TermView::Reversal { output, .. } => (output % 3, None),
            _ => continue,
        };
        let (n, deg) = coefs.map_or((1.0, 0.0), |c| {
            let deg = c
                .iter()
                .map(|(m, _)| u32::from(m[0]) + u32::from(m[1]) + u32::from(m[2]))
                .max()
                .unwrap_or(0);
            (c.len() as f64, f64::from(deg))
        });
        // f32: the coefficients, each monomial's factors (converted and
        // scaled: two roundings each), the products and the sum, the
        // factor's conversion and the product with it.
        let v = (n + 2.0 * deg + 5.0) * eps * m[output];
        sb.add(F32, output, i, v, &mut best);
        let (Some(coefs), true) = (
            coefs,
            matches!(view, TermView::Thermal { .. } | TermView::Abbe { .. }),
        ) else {
            continue;
        };
        // Fixed point, as the loader scales them: thermal coefficients
        // per m°C, q the term's scale. In units of 2^-q before the factor:
        // each coefficient's rounding (½ per monomial, |m| ≤ 1), the Q30
        // monomials' (≤ 2·(d + 1) units of 2^-30 each, times Σ|c_q| <
        // 2^31), the sum's rounding to 2^-q (½); then the factor, the
        // shift to Q16 and the rounding to nm (1 nm).
        let per_mc = matches!(view, TermView::Thermal { .. });
        let sum: f64 = coefs
            .iter()
            .map(|(_, c)| if per_mc { c / 1000.0 } else { c }.abs())
            .sum();
        // On the separable path (Horner rows, `eval::horner_plan`) the
        // term's scale is the plan's and each monomial's row adds at most
        // 4 truncated steps and 2 units from its weight's product.
        let (units, q) = match &horner {
            Some(p) => {
                fac += 1;
                (0.5 * n + 6.0 * n + 0.5, Some(p.factored_q(fac - 1)))
            }
            None => (
                0.5 * n + 4.0 * (deg + 1.0) + 0.5,
                crate::eval::factored_q(sum),
            ),
        };
        let v = match q {
            Some(q) => units * libm::exp2(-f64::from(q)) * max_factor(table, &view) + 1.0,
            None => f64::INFINITY,
        };
        sb.add(FIXED, output, i, v, &mut best);
    }
    for o in 0..3 {
        // The f32 sum of the output's terms, and its rounding to nm.
        sb.nm[F32][o] += (terms[o] + 1.0) * eps * total[o] + 1.0;
    }
    sb
}

/// Input `k` (0 ≤ k < [`DEFINITION_POINTS`]) of the check, inside `table`'s
/// envelope: the first half combines the levels of each input (travel ends,
/// scaling centre and 1 nm beside it, range ends and middles, reversal ±1
/// and 0) by a fixed pseudo-random sequence — the eight travel corners
/// first —, the second half draws each input uniformly from its range.
#[inline]
pub fn check_point(table: &Table<'_>, k: u32) -> Inputs {
    let env = table.envelope();
    let sc = table.scaling();
    // SplitMix64 of (k, input index): the same sequence on every target.
    let draw = |i: u32| -> u64 {
        let mut z = (u64::from(k) << 8 | u64::from(i)).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let uniform = |i: u32, lo: i32, hi: i32| -> i32 {
        let span = (i64::from(hi) - i64::from(lo)) as u64 + 1;
        (i64::from(lo) + (draw(i) % span) as i64) as i32
    };
    let structured = k < DEFINITION_POINTS / 2;
    let level = |i: u32, lo: i32, hi: i32, extra: [i64; 4]| -> i32 {
        if !structured {
            return uniform(i, lo, hi);
        }
        let mid = ((i64::from(lo) + i64::from(hi)) / 2) as i32;
        let v = match draw(i) % 8 {
            0 | 1 => lo,
            2 | 3 => hi,
            4 => mid,
            r => extra[r as usize - 4]
                .max(i64::from(lo))
                .min(i64::from(hi))
                .try_into()
                .unwrap_or(mid),
        };
        v.max(lo).min(hi)
    };
    let pos_nm = core::array::from_fn(|a| {
        let (lo, hi) = (env.travel_min_nm[a], env.travel_max_nm[a]);
        if k < 8 {
            return if k >> a & 1 == 0 { lo } else { hi };
        }
        let c = i64::from(sc.centre_nm[a]);
        level(a as u32, lo, hi, [c, c + 1, c - 1, c])
    });
    let rev_q30 = core::array::from_fn(|a| {
        let one = 1i32 << 30;
        match (structured, draw(3 + a as u32) % 4) {
            (false, _) => uniform(3 + a as u32, -one, one),
            (true, 0) => -one,
            (true, 1) => one,
            (true, 2) => 0,
            (true, _) => one / 2,
        }
    });
    let channels = table.channel_count().min(MAX_TEMPS);
    let temp_mc = core::array::from_fn(|ch| {
        if ch >= channels {
            return 0;
        }
        let (lo, hi) = (env.temp_min_mc[ch], env.temp_max_mc[ch]);
        level(6 + ch as u32, lo, hi, [20_000, 20_001, 19_999, 25_000])
    });
    let tool_nm = level(
        10,
        env.tool_min_nm,
        env.tool_max_nm,
        [0, 1, -1, 100_000_000],
    );
    Inputs {
        pos_nm,
        rev_q30,
        temp_mc,
        tool_nm,
    }
}

/// The worst departure of `model`'s evaluations (fixed point and f32) from
/// `table`'s definition — `model` must be `table` loaded — over the static
/// bound and the [`DEFINITION_POINTS`] inputs of [`check_point`], or
/// `None` when both stay within [`DEFINITION_BOUND_NM`] everywhere. Stops
/// at the first input beyond the bound.
#[inline]
pub fn check_definition<const P: usize, const G: usize>(
    table: &Table<'_>,
    model: &ModelCap<P, G>,
) -> Option<Departure> {
    let bound = f64::from(DEFINITION_BOUND_NM);
    let sb = static_bound_nm(table);
    for (p, path) in [EvalPath::Fixed, EvalPath::F32].into_iter().enumerate() {
        for o in 0..3 {
            let e = sb.nm[p][o];
            if beyond(e, bound) {
                return Some(Departure {
                    path,
                    output: o as u8,
                    error_nm: ceil_nm(e),
                    at: None,
                    term: sb.worst_term[p][o],
                });
            }
        }
    }
    for k in 0..DEFINITION_POINTS {
        let inp = check_point(table, k);
        let def = definition_nm(table, &inp);
        for (path, got) in [
            (EvalPath::Fixed, model.eval_fixed(&inp).corr_nm),
            (EvalPath::F32, model.eval_f32(&inp).corr_nm),
        ] {
            for o in 0..3 {
                let e = (f64::from(got[o]) - def[o]).abs();
                // NaN (a non-finite definition) departs too.
                if beyond(e, bound) {
                    return Some(Departure {
                        path,
                        output: o as u8,
                        error_nm: ceil_nm(e),
                        at: Some(inp),
                        term: None,
                    });
                }
            }
        }
    }
    None
}

/// `e` > `bound`, or NaN (a non-finite definition or bound departs).
#[inline]
fn beyond(e: f64, bound: f64) -> bool {
    e > bound || e.is_nan()
}

#[inline]
fn ceil_nm(e: f64) -> u32 {
    if e.is_nan() || e >= u32::MAX as f64 {
        u32::MAX
    } else {
        libm::ceil(e) as u32
    }
}
