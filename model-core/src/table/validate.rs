//! The checks `parse` runs before a [`Table`] exists: the fixed part
//! (reserved bytes, envelope, scaling, channels), every term header and
//! body (polynomial blocks, periodic, factored, grid and MLP terms) within
//! the table's length — so no accessor ever meets malformed bytes.

use super::bytes::*;
use super::*;

pub(super) fn check_reserved(b: &[u8], off: usize, n: usize) -> Result<(), TableError> {
    for i in off..off + n {
        if rd_u8(b, i) != 0 {
            return Err(TableError::ReservedNonZero { offset: i as u32 });
        }
    }
    Ok(())
}

pub(super) fn finite(b: &[u8], off: usize) -> Result<f64, TableError> {
    let v = rd_f64(b, off);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(TableError::NotFinite { offset: off as u32 })
    }
}

pub(super) fn validate_structure(b: &[u8]) -> Result<(), TableError> {
    use layout as l;
    check_reserved(b, l::RESERVED0, 2)?;
    let units = rd_u8(b, l::UNITS);
    if units != UNITS_NM_MC {
        return Err(TableError::UnsupportedUnits { code: units });
    }
    let nch = rd_u8(b, l::CHANNEL_COUNT);
    if nch as usize > MAX_TEMPS {
        return Err(TableError::BadChannelCount { count: nch });
    }
    for ch in 0..MAX_TEMPS {
        let off = l::CHANNEL_NAMES + ch * CHANNEL_NAME_LEN;
        let raw = &b[off..off + CHANNEL_NAME_LEN];
        let bad = TableError::BadChannelName { channel: ch as u8 };
        if ch < nch as usize {
            let n = raw.iter().position(|&c| c == 0).unwrap_or(CHANNEL_NAME_LEN);
            if n == 0
                || raw[n..].iter().any(|&c| c != 0)
                || core::str::from_utf8(&raw[..n]).is_err()
            {
                return Err(bad);
            }
        } else if raw.iter().any(|&c| c != 0) {
            return Err(bad);
        }
    }
    // Envelope.
    let env = envelope_at(b);
    for a in 0..3 {
        if env.travel_min_nm[a] > env.travel_max_nm[a] {
            return Err(TableError::BadEnvelope {
                offset: (l::TRAVEL_MIN + 4 * a) as u32,
            });
        }
        if !(0..=MAX_CORR_LIMIT_NM).contains(&env.max_corr_nm[a]) {
            return Err(TableError::BadEnvelope {
                offset: (l::MAX_CORR + 4 * a) as u32,
            });
        }
    }
    if !(1..=MAX_SLEW_LIMIT_NM_PER_MS).contains(&env.max_slew_nm_per_ms) {
        return Err(TableError::BadEnvelope {
            offset: l::MAX_SLEW as u32,
        });
    }
    for ch in 0..MAX_TEMPS {
        let (lo, hi) = (env.temp_min_mc[ch], env.temp_max_mc[ch]);
        let ok = if ch < nch as usize {
            lo <= hi && lo >= -MAX_TREF_MC && hi <= MAX_TREF_MC
        } else {
            lo == 0 && hi == 0
        };
        if !ok {
            return Err(TableError::BadEnvelope {
                offset: (l::TEMP_MIN + 4 * ch) as u32,
            });
        }
    }
    if env.tool_min_nm > env.tool_max_nm {
        return Err(TableError::BadEnvelope {
            offset: l::TOOL_MIN as u32,
        });
    }
    // Scaling: the travel must map into |u| ≤ 1 so that every monomial stays
    // within ±1 (the fixed-point evaluator's range analysis relies on it).
    let sc = scaling_at(b);
    for a in 0..3 {
        let h = sc.half_span_nm[a];
        if h <= 0 {
            return Err(TableError::BadScaling { axis: a as u8 });
        }
        let c = sc.centre_nm[a] as i64;
        if (env.travel_min_nm[a] as i64) < c - h as i64
            || (env.travel_max_nm[a] as i64) > c + h as i64
        {
            return Err(TableError::TravelOutsideScaling { axis: a as u8 });
        }
    }
    let outputs = rd_u8(b, l::OUTPUTS);
    if outputs & !0b111 != 0 {
        return Err(TableError::BadOutputs {
            offset: l::OUTPUTS as u32,
        });
    }
    check_reserved(b, l::RESERVED1, 3)?;
    // Terms.
    let count = rd_u16(b, l::TERM_COUNT);
    let mut off = l::TERMS;
    // Reversal terms of one axis must share one transition length. The
    // evaluator reads one reversal state per axis (`Inputs::rev_q30`), which
    // the firmware's single `DirTracker` per axis produces with one
    // transition length (`Model::reversal_transition_nm`); a second term
    // with another length would run on the first one's ramp, its own length
    // silently ignored. Refusing the table is the safe choice: one state per
    // axis is what the inputs, the link and the firmware carry, trackers
    // per term would change all three for a table no exporter writes (the
    // host exports one length for every reversal term). 0 = no term yet
    // (a valid length is > 0).
    let mut transition_nm = [0i32; 3];
    for _ in 0..count {
        let hdr_end = off + TERM_HEADER_LEN;
        if hdr_end > b.len() {
            return Err(TableError::TermTruncated { offset: off as u32 });
        }
        let body_len = rd_u32(b, off + 4) as usize;
        let end = match hdr_end.checked_add(body_len) {
            Some(e) if e <= b.len() => e,
            _ => return Err(TableError::TermTruncated { offset: off as u32 }),
        };
        validate_term(b, off, end, outputs, nch)?;
        if rd_u8(b, off) == TermKind::Reversal as u8 {
            // Validated: the axis is < 3, the length > 0.
            let axis = rd_u8(b, off + 2) as usize % 3;
            let t = rd_i32(b, off + TERM_HEADER_LEN);
            if transition_nm[axis] == 0 {
                transition_nm[axis] = t;
            } else if transition_nm[axis] != t {
                return Err(TableError::ReversalTransitionMismatch {
                    offset: (off + TERM_HEADER_LEN) as u32,
                });
            }
        }
        off = end;
    }
    if off != b.len() {
        return Err(TableError::TrailingBytes { offset: off as u32 });
    }
    Ok(())
}

pub(super) fn envelope_at(b: &[u8]) -> Envelope {
    use layout as l;
    Envelope {
        travel_min_nm: i32x3(b, l::TRAVEL_MIN),
        travel_max_nm: i32x3(b, l::TRAVEL_MAX),
        max_corr_nm: i32x3(b, l::MAX_CORR),
        max_slew_nm_per_ms: rd_i32(b, l::MAX_SLEW),
        temp_min_mc: i32x4(b, l::TEMP_MIN),
        temp_max_mc: i32x4(b, l::TEMP_MAX),
        tool_min_nm: rd_i32(b, l::TOOL_MIN),
        tool_max_nm: rd_i32(b, l::TOOL_MAX),
    }
}

pub(super) fn scaling_at(b: &[u8]) -> InputScaling {
    InputScaling {
        centre_nm: i32x3(b, layout::CENTRE),
        half_span_nm: i32x3(b, layout::HALF_SPAN),
    }
}

/// Validate a polynomial body (count, entries) starting at `off`, ending exactly at `end`.
pub(super) fn validate_poly(b: &[u8], off: usize, end: usize) -> Result<(), TableError> {
    if off + 4 > end {
        return Err(TableError::TermLengthMismatch { offset: off as u32 });
    }
    let n = rd_u16(b, off) as usize;
    check_reserved(b, off + 2, 2)?;
    if n == 0 || n > MAX_MONOMIALS {
        return Err(TableError::BadTermField { offset: off as u32 });
    }
    if off + 4 + 12 * n != end {
        return Err(TableError::TermLengthMismatch { offset: off as u32 });
    }
    for i in 0..n {
        let e = off + 4 + 12 * i;
        let m = [rd_u8(b, e), rd_u8(b, e + 1), rd_u8(b, e + 2)];
        check_reserved(b, e + 3, 1)?;
        if m.iter().map(|&v| v as u32).sum::<u32>() > MAX_DEGREE as u32 {
            return Err(TableError::BadTermField { offset: e as u32 });
        }
        for j in 0..i {
            let e2 = off + 4 + 12 * j;
            if [rd_u8(b, e2), rd_u8(b, e2 + 1), rd_u8(b, e2 + 2)] == m {
                return Err(TableError::DuplicateMonomial { offset: e as u32 });
            }
        }
        finite(b, e + 4)?;
    }
    Ok(())
}

pub(super) fn validate_term(
    b: &[u8],
    off: usize,
    end: usize,
    present: u8,
    nch: u8,
) -> Result<(), TableError> {
    let kind_raw = rd_u8(b, off);
    let kind = TermKind::from_u8(kind_raw).ok_or(TableError::UnknownTermKind {
        offset: off as u32,
        kind: kind_raw,
    })?;
    let outs = rd_u8(b, off + 1);
    let aux = rd_u8(b, off + 2);
    check_reserved(b, off + 3, 1)?;
    let bad_outs = TableError::BadTermOutputs {
        offset: (off + 1) as u32,
    };
    if outs == 0 || outs & !present != 0 {
        return Err(bad_outs);
    }
    if kind != TermKind::Mlp && outs.count_ones() != 1 {
        return Err(bad_outs);
    }
    let bad_aux = TableError::BadTermField {
        offset: (off + 2) as u32,
    };
    let body = off + TERM_HEADER_LEN;
    let mismatch = TableError::TermLengthMismatch { offset: off as u32 };
    match kind {
        TermKind::Poly => {
            if aux != 0 {
                return Err(bad_aux);
            }
            validate_poly(b, body, end)
        }
        TermKind::Abbe => {
            // aux: the arm input; 0 = the tool arm (the only one in v1).
            if aux != 0 {
                return Err(bad_aux);
            }
            validate_poly(b, body, end)
        }
        TermKind::Thermal => {
            if aux >= nch {
                return Err(bad_aux);
            }
            if body + 8 > end {
                return Err(mismatch);
            }
            let tref = rd_i32(b, body);
            if !(-MAX_TREF_MC..=MAX_TREF_MC).contains(&tref) {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            check_reserved(b, body + 4, 4)?;
            validate_poly(b, body + 8, end)
        }
        TermKind::Periodic => {
            if aux >= 3 {
                return Err(bad_aux);
            }
            if body + 8 > end {
                return Err(mismatch);
            }
            if rd_i32(b, body) <= 0 {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            let h = rd_u8(b, body + 4) as usize;
            if h == 0 || h > MAX_HARMONICS {
                return Err(TableError::BadTermField {
                    offset: (body + 4) as u32,
                });
            }
            check_reserved(b, body + 5, 3)?;
            if body + 8 + 16 * h != end {
                return Err(mismatch);
            }
            for i in 0..2 * h {
                finite(b, body + 8 + 8 * i)?;
            }
            Ok(())
        }
        TermKind::Reversal => {
            if aux >= 3 {
                return Err(bad_aux);
            }
            if body + 16 != end {
                return Err(mismatch);
            }
            if rd_i32(b, body) <= 0 {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            check_reserved(b, body + 4, 4)?;
            finite(b, body + 8).map(|_| ())
        }
        TermKind::Mlp => {
            if aux != 0 {
                return Err(bad_aux);
            }
            validate_mlp(b, body, end, outs.count_ones() as usize, nch)
        }
        TermKind::Grid => {
            if aux != 0 {
                return Err(bad_aux);
            }
            if body + 36 > end {
                return Err(mismatch);
            }
            let mut total: usize = 1;
            let mut used = 0;
            for a in 0..3 {
                let e = body + 12 * a;
                let nodes = rd_u16(b, e);
                check_reserved(b, e + 2, 2)?;
                if nodes == 0 || nodes > MAX_GRID_NODES_PER_AXIS {
                    return Err(TableError::BadTermField { offset: e as u32 });
                }
                if rd_i32(b, e + 8) <= 0 {
                    return Err(TableError::BadTermField {
                        offset: (e + 8) as u32,
                    });
                }
                // The last node must stay representable in i32 nm.
                let last = rd_i32(b, e + 4) as i64 + (nodes as i64 - 1) * rd_i32(b, e + 8) as i64;
                if last > i32::MAX as i64 {
                    return Err(TableError::BadTermField {
                        offset: (e + 8) as u32,
                    });
                }
                if nodes >= 2 {
                    used += 1;
                }
                total *= nodes as usize;
            }
            if used == 0 {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            match total.checked_mul(8).and_then(|v| v.checked_add(body + 36)) {
                Some(e) if e == end => {}
                _ => return Err(mismatch),
            }
            for i in 0..total {
                finite(b, body + 36 + 8 * i)?;
            }
            Ok(())
        }
    }
}

/// Byte sizes of an MLP body's parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct MlpShape {
    pub n_in: usize,
    pub hidden: [usize; MAX_HIDDEN_LAYERS],
    pub n_layers: usize,
    pub n_out: usize,
}

impl MlpShape {
    /// Number of f64 weights and biases.
    pub fn n_params(&self) -> usize {
        let mut prev = self.n_in;
        let mut n = 0;
        for &h in &self.hidden[..self.n_layers] {
            n += h * prev + h;
            prev = h;
        }
        n + self.n_out * prev + self.n_out
    }
    /// Body length in bytes.
    pub fn body_len(&self) -> usize {
        4 + 20 * self.n_in + 16 * self.n_out + 8 * self.n_params()
    }
}

pub(super) fn mlp_shape(b: &[u8], body: usize, n_out: usize) -> MlpShape {
    MlpShape {
        n_in: rd_u8(b, body) as usize,
        n_layers: rd_u8(b, body + 1) as usize,
        hidden: [rd_u8(b, body + 2) as usize, rd_u8(b, body + 3) as usize],
        n_out,
    }
}

pub(super) fn validate_mlp(
    b: &[u8],
    body: usize,
    end: usize,
    n_out: usize,
    nch: u8,
) -> Result<(), TableError> {
    if body + 4 > end {
        return Err(TableError::TermLengthMismatch {
            offset: body as u32,
        });
    }
    let s = mlp_shape(b, body, n_out);
    if s.n_in == 0 || s.n_in > MAX_MLP_INPUTS {
        return Err(TableError::BadTermField {
            offset: body as u32,
        });
    }
    if s.n_layers == 0 || s.n_layers > MAX_HIDDEN_LAYERS {
        return Err(TableError::BadTermField {
            offset: (body + 1) as u32,
        });
    }
    for i in 0..MAX_HIDDEN_LAYERS {
        let h = s.hidden[i];
        let ok = if i < s.n_layers {
            (1..=MAX_HIDDEN_UNITS).contains(&h)
        } else {
            h == 0
        };
        if !ok {
            return Err(TableError::BadTermField {
                offset: (body + 2 + i) as u32,
            });
        }
    }
    if body + s.body_len() != end {
        return Err(TableError::TermLengthMismatch {
            offset: body as u32,
        });
    }
    let mut off = body + 4;
    for _ in 0..s.n_in {
        let src = rd_u8(b, off);
        if src as usize >= 3 + nch as usize {
            return Err(TableError::BadTermField { offset: off as u32 });
        }
        check_reserved(b, off + 1, 3)?;
        let lo = finite(b, off + 4)?;
        let hi = finite(b, off + 12)?;
        if lo >= hi || hi - lo < 1e-3 || lo.abs() > 1e10 || hi.abs() > 1e10 {
            return Err(TableError::BadTermField {
                offset: (off + 4) as u32,
            });
        }
        off += 20;
    }
    for _ in 0..s.n_out {
        let lo = finite(b, off)?;
        let hi = finite(b, off + 8)?;
        if lo > hi {
            return Err(TableError::BadTermField { offset: off as u32 });
        }
        off += 16;
    }
    for _ in 0..s.n_params() {
        finite(b, off)?;
        off += 8;
    }
    Ok(())
}
