//! Zero-copy views of a validated table's terms: the term iterator, and per
//! kind the polynomial coefficients, the MLP's layers and inputs and the
//! grid's axes and node values, read in place from the bytes.

use super::bytes::*;
use super::validate::mlp_shape;
use super::*;

/// Iterator over the terms of a table.
#[derive(Clone, Debug)]
pub struct Terms<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) off: usize,
    pub(super) left: usize,
}

impl<'a> Iterator for Terms<'a> {
    type Item = TermRef<'a>;
    fn next(&mut self) -> Option<TermRef<'a>> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        let off = self.off;
        let body_len = rd_u32(self.bytes, off + 4) as usize;
        let end = (off + TERM_HEADER_LEN).checked_add(body_len)?;
        let body = self.bytes.get(off + TERM_HEADER_LEN..end)?;
        self.off = end;
        Some(TermRef {
            kind: TermKind::from_u8(rd_u8(self.bytes, off))?,
            outputs: rd_u8(self.bytes, off + 1),
            aux: rd_u8(self.bytes, off + 2),
            offset: off,
            body,
        })
    }
}

/// One term of a validated table.
#[derive(Clone, Copy, Debug)]
pub struct TermRef<'a> {
    /// What kind of term.
    pub kind: TermKind,
    /// Output mask (bit 0 ex …); exactly one bit except for MLPs.
    pub outputs: u8,
    /// Kind-specific: axis (periodic, reversal), channel (thermal), 0 otherwise.
    pub aux: u8,
    /// Byte offset of the term header in the table.
    pub offset: usize,
    pub(super) body: &'a [u8],
}

/// Coefficients of a polynomial: (monomial, coefficient) pairs.
#[derive(Clone, Copy, Debug)]
pub struct PolyCoefs<'a> {
    pub(super) entries: &'a [u8],
}

impl<'a> PolyCoefs<'a> {
    /// Number of monomials.
    pub fn len(&self) -> usize {
        self.entries.len() / 12
    }
    /// Whether there are none (never for a parsed table).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The i-th (monomial, coefficient).
    pub fn get(&self, i: usize) -> (Monomial, f64) {
        let e = 12 * i;
        (
            [
                rd_u8(self.entries, e),
                rd_u8(self.entries, e + 1),
                rd_u8(self.entries, e + 2),
            ],
            rd_f64(self.entries, e + 4),
        )
    }
    /// Iterate over (monomial, coefficient).
    pub fn iter(&self) -> impl Iterator<Item = (Monomial, f64)> + 'a {
        let c = *self;
        (0..c.len()).map(move |i| c.get(i))
    }
}

pub(super) fn poly_at(body: &[u8], off: usize) -> PolyCoefs<'_> {
    PolyCoefs {
        entries: body.get(off + 4..).unwrap_or(&[]),
    }
}

/// An input of an MLP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MlpInputRef {
    /// 0..=2: position x/y/z (nm); 3 + ch: temperature channel ch (m°C).
    pub source: u8,
    /// Training minimum (maps to −1).
    pub min: f64,
    /// Training maximum (maps to +1).
    pub max: f64,
}

/// A view of an MLP term.
#[derive(Clone, Copy, Debug)]
pub struct MlpView<'a> {
    pub(super) shape: MlpShape,
    pub(super) body: &'a [u8],
}

impl<'a> MlpView<'a> {
    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.shape.n_in
    }
    /// Widths of the hidden layers.
    pub fn hidden(&self) -> &[usize] {
        &self.shape.hidden[..self.shape.n_layers]
    }
    /// Number of outputs (= bits in the term's output mask, assigned in ascending order).
    pub fn n_outputs(&self) -> usize {
        self.shape.n_out
    }
    /// Input i.
    pub fn input(&self, i: usize) -> MlpInputRef {
        let o = 4 + 20 * i;
        MlpInputRef {
            source: rd_u8(self.body, o),
            min: rd_f64(self.body, o + 4),
            max: rd_f64(self.body, o + 12),
        }
    }
    /// Output scaling (min, max) of net output j, nm.
    pub fn output_range(&self, j: usize) -> (f64, f64) {
        let o = 4 + 20 * self.shape.n_in + 16 * j;
        (rd_f64(self.body, o), rd_f64(self.body, o + 8))
    }
    /// The k-th parameter in the order L1 W (row-major, rows = units), L1 b, [L2 W, L2 b], out W, out b.
    pub fn param(&self, k: usize) -> f64 {
        rd_f64(
            self.body,
            4 + 20 * self.shape.n_in + 16 * self.shape.n_out + 8 * k,
        )
    }
    pub(crate) fn shape(&self) -> MlpShape {
        self.shape
    }
}

/// One axis of a grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridAxisRef {
    /// Number of nodes (1 = the grid does not vary along this axis).
    pub nodes: u16,
    /// Position of node 0, nm.
    pub origin_nm: i32,
    /// Node spacing, nm.
    pub step_nm: i32,
}

/// A view of a grid term.
#[derive(Clone, Copy, Debug)]
pub struct GridView<'a> {
    pub(super) body: &'a [u8],
}

impl<'a> GridView<'a> {
    /// Axis a (0 = x).
    pub fn axis(&self, a: usize) -> GridAxisRef {
        let e = 12 * a;
        GridAxisRef {
            nodes: rd_u16(self.body, e),
            origin_nm: rd_i32(self.body, e + 4),
            step_nm: rd_i32(self.body, e + 8),
        }
    }
    /// Number of values.
    pub fn len(&self) -> usize {
        self.body.len().saturating_sub(36) / 8
    }
    /// Whether there are none (never for a parsed table).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Value i (x fastest, then y, then z), nm.
    pub fn value(&self, i: usize) -> f64 {
        rd_f64(self.body, 36 + 8 * i)
    }
}

/// A decoded term.
#[derive(Clone, Copy, Debug)]
pub enum TermView<'a> {
    /// Polynomial in normalised positions.
    Poly { output: usize, coefs: PolyCoefs<'a> },
    /// Periodic along an axis; `coefs[k-1] = (a_k sin, b_k cos)`, nm.
    Periodic {
        output: usize,
        axis: usize,
        period_nm: i32,
        harmonics: usize,
        body: &'a [u8],
    },
    /// (T − T_ref) × polynomial, coefficients in nm/K.
    Thermal {
        output: usize,
        channel: usize,
        t_ref_mc: i32,
        coefs: PolyCoefs<'a>,
    },
    /// amplitude × reversal state.
    Reversal {
        output: usize,
        axis: usize,
        transition_nm: i32,
        amplitude_nm: f64,
    },
    /// tool arm × polynomial (coefficients in nm per nm of arm).
    Abbe { output: usize, coefs: PolyCoefs<'a> },
    /// MLP with outputs in the mask.
    Mlp { outputs: u8, net: MlpView<'a> },
    /// Grid table.
    Grid { output: usize, grid: GridView<'a> },
}

impl<'a> TermView<'a> {
    /// Harmonic k (1-based) of a periodic term: (sin amplitude, cos amplitude) in nm.
    /// (0, 0) for k = 0, for k beyond the term's harmonics and for other
    /// kinds: a public accessor must not panic for any argument.
    pub fn harmonic(&self, k: usize) -> (f64, f64) {
        match self {
            // k ≤ harmonics ≤ MAX_HARMONICS (validated), so the offsets are small.
            TermView::Periodic {
                body, harmonics, ..
            } if (1..=*harmonics).contains(&k) => (rd_f64(body, 16 * k - 8), rd_f64(body, 16 * k)),
            _ => (0.0, 0.0),
        }
    }
}

impl<'a> TermRef<'a> {
    /// Decode the body.
    pub fn view(&self) -> TermView<'a> {
        let output = self.outputs.trailing_zeros() as usize;
        let b = self.body;
        match self.kind {
            TermKind::Poly => TermView::Poly {
                output,
                coefs: poly_at(b, 0),
            },
            TermKind::Abbe => TermView::Abbe {
                output,
                coefs: poly_at(b, 0),
            },
            TermKind::Thermal => TermView::Thermal {
                output,
                channel: self.aux as usize,
                t_ref_mc: rd_i32(b, 0),
                coefs: poly_at(b, 8),
            },
            TermKind::Periodic => TermView::Periodic {
                output,
                axis: self.aux as usize,
                period_nm: rd_i32(b, 0),
                harmonics: rd_u8(b, 4) as usize,
                body: b,
            },
            TermKind::Reversal => TermView::Reversal {
                output,
                axis: self.aux as usize,
                transition_nm: rd_i32(b, 0),
                amplitude_nm: rd_f64(b, 8),
            },
            TermKind::Mlp => TermView::Mlp {
                outputs: self.outputs,
                net: MlpView {
                    shape: mlp_shape(b, 0, self.outputs.count_ones() as usize),
                    body: b,
                },
            },
            TermKind::Grid => TermView::Grid {
                output,
                grid: GridView { body: b },
            },
        }
    }
}
