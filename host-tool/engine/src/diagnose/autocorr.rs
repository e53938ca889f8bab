//! Effective sample size of a residual in time order: readings a minute
//! apart on a slowly wandering error are not independent, and intervals
//! computed as if they were are far too narrow. With the residual's lag-1
//! autocorrelation ρ (an AR(1) reading of the series), n readings count as
//! about n_eff = n·(1−ρ)/(1+ρ) independent ones for ρ > 0 (n otherwise),
//! and a standard error grows by √(n/n_eff).

use super::target::TargetData;

/// The lag-1 autocorrelation of `x` (in order): Σ(xᵢ−x̄)(xᵢ₊₁−x̄)/Σ(xᵢ−x̄)².
/// None with fewer than 3 values or no variation.
pub fn lag1_autocorrelation(x: &[f64]) -> Option<f64> {
    if x.len() < 3 {
        return None;
    }
    let m = x.iter().sum::<f64>() / x.len() as f64;
    let den: f64 = x.iter().map(|v| (v - m) * (v - m)).sum();
    if den <= 0.0 || !den.is_finite() {
        return None;
    }
    let num: f64 = x.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    Some((num / den).clamp(-1.0, 1.0))
}

/// n·(1−ρ)/(1+ρ) for ρ > 0, n otherwise (never below 1).
pub fn effective_n(n: usize, rho: f64) -> f64 {
    let n = n as f64;
    if rho > 0.0 {
        (n * (1.0 - rho) / (1.0 + rho)).max(1.0)
    } else {
        n
    }
}

/// The positions (indices into `td.rows`) in time order (session, then
/// `t_s`), made once per target; None without a `t_s` column.
pub(super) fn time_positions<'a>(td: &'a TargetData) -> Option<&'a [usize]> {
    td.time_order
        .get_or_init(|| {
            let data = td.data;
            data.t_s.as_ref()?;
            let mut idx: Vec<usize> = (0..td.rows.len()).collect();
            idx.sort_by(|&a, &b| {
                let (ka, kb) = (
                    crate::holdout::time_key(data, td.rows[a]),
                    crate::holdout::time_key(data, td.rows[b]),
                );
                ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
            });
            Some(idx)
        })
        .as_deref()
}

/// The lag-1 autocorrelation of a target's residual `resid` (one value per
/// row of `td.rows`) in time order, and its effective sample size. None
/// without a `t_s` column or when ρ cannot be computed.
pub(super) fn in_time(td: &TargetData, resid: &[f64]) -> Option<(f64, f64)> {
    let order = time_positions(td)?;
    let ordered: Vec<f64> = order.iter().map(|&i| resid[i]).collect();
    let rho = lag1_autocorrelation(&ordered)?;
    Some((rho, effective_n(resid.len(), rho)))
}

/// [`in_time`] of the residual `resid − Σ partialledₖ·βₖ` (the model plus a
/// candidate, its columns partialled); None without `t_s` (nothing
/// computed then).
pub(super) fn in_time_after(
    td: &TargetData,
    resid: &[f64],
    partialled: &[Vec<f64>],
    beta: &[f64],
) -> Option<(f64, f64)> {
    time_positions(td)?;
    let after: Vec<f64> = (0..resid.len())
        .map(|i| {
            let fit: f64 = partialled.iter().zip(beta).map(|(c, b)| c[i] * b).sum();
            resid[i] - fit
        })
        .collect();
    in_time(td, &after)
}

/// The factor √(n/n_eff) by which an interval computed as if the readings
/// were independent is widened.
pub fn widening(n: usize, n_eff: f64) -> f64 {
    if n_eff > 0.0 && (n as f64) > n_eff {
        (n as f64 / n_eff).sqrt()
    } else {
        1.0
    }
}

/// A ΔBIC of `n` readings, n·ln(RSS₁/RSS₀) + k·ln n with `k` parameters
/// charged, recomputed as if the data held `n_eff` independent ones:
/// n_eff·ln(RSS₁/RSS₀) + k·ln n_eff.
pub fn effective_dbic(dbic: f64, n: usize, n_eff: f64, k: f64) -> f64 {
    let nf = n as f64;
    let per_reading = (dbic - k * nf.ln()) / nf;
    n_eff * per_reading + k * n_eff.max(1.0).ln()
}

/// Whether n_eff enters the path's decision for `td`: a time series at one
/// position (a `t_s` column, no axis moving). There every reading's
/// neighbour in time is the same point read again, and a residual
/// correlated from one reading to the next is the error wandering in
/// time. In a scan the neighbour in time is the next point in space, and
/// the lag-1 correlation is mostly the seed's smooth misfit along the path
/// — judged by the spatial hold-out and the smooth rule instead (the
/// intervals are widened either way).
pub(super) fn decides(td: &TargetData) -> bool {
    td.data.t_s.is_some() && td.data.varying_axes().is_empty()
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_test_support::SplitMix64;

    fn ar1(n: usize, rho: f64, seed: u64) -> Vec<f64> {
        let mut rng = SplitMix64(seed);
        let mut x = 0.0;
        (0..n)
            .map(|_| {
                x = rho * x + rng.normal();
                x
            })
            .collect()
    }

    #[test]
    fn ar1_rho_is_estimated() {
        for &rho in &[0.5, 0.93] {
            let x = ar1(5000, rho, 7);
            let r = lag1_autocorrelation(&x).unwrap();
            assert!((r - rho).abs() < 0.03, "rho {rho}: estimated {r}");
        }
        // 0.93 over 4683 readings: about 170 effective samples.
        let ne = effective_n(4683, 0.93);
        assert!((ne - 170.0).abs() < 2.0, "{ne}");
    }

    #[test]
    fn white_noise_keeps_n() {
        let x = ar1(5000, 0.0, 11);
        let r = lag1_autocorrelation(&x).unwrap();
        let ne = effective_n(x.len(), r);
        assert!(ne > 0.95 * x.len() as f64, "rho {r}, n_eff {ne}");
        assert_eq!(effective_n(100, -0.3), 100.0);
        assert_eq!(widening(100, 100.0), 1.0);
        assert!(lag1_autocorrelation(&[1.0, 1.0, 1.0]).is_none());
    }

    #[test]
    fn effective_dbic_counts_n_eff_readings() {
        // n = 1000, RSS halved, 2 parameters charged.
        let (n, k) = (1000usize, 2.0);
        let dbic = n as f64 * 0.5f64.ln() + k * (n as f64).ln();
        assert!((effective_dbic(dbic, n, n as f64, k) - dbic).abs() < 1e-9);
        let e = effective_dbic(dbic, n, 10.0, k);
        assert!(
            (e - (10.0 * 0.5f64.ln() + k * 10f64.ln())).abs() < 1e-9,
            "{e}"
        );
    }
}
