//! One-dimensional minimisation on a bracket: Brent's method, for the
//! nonlinear parameter of a candidate effect (a thermal lag) whose residual
//! sum is smooth between two grid points.

/// Minimum of `f` on [lo, hi] to `tol` by Brent's method (parabolic
/// interpolation through the three best points, a golden-section step
/// where the parabola is not safe; the bounded form of scipy's
/// `fminbound`): (x, f(x)). Assumes one minimum in the bracket (the grid
/// point and its neighbours). On the smooth residual sum of a lag, 6–9
/// evaluations where golden section alone needs 11–14 — each evaluation is
/// a projection of an n-long column on the model.
pub fn brent_min(f: impl Fn(f64) -> f64, lo: f64, hi: f64, tol: f64) -> (f64, f64) {
    const GOLD: f64 = 0.381_966_011_250_105_1; // (3 − √5)/2
    let sqrt_eps = f64::EPSILON.sqrt();
    let (mut a, mut b) = (lo, hi);
    // x: best so far, w: second best, v: the previous w.
    let mut x = a + GOLD * (b - a);
    let mut fx = f(x);
    let (mut w, mut fw, mut v, mut fv) = (x, fx, x, fx);
    let (mut step, mut prev) = (0.0f64, 0.0f64);
    for _ in 0..100 {
        let m = 0.5 * (a + b);
        let tol1 = sqrt_eps * x.abs() + tol / 3.0;
        let tol2 = 2.0 * tol1;
        if (x - m).abs() <= tol2 - 0.5 * (b - a) {
            break;
        }
        let mut golden = true;
        if prev.abs() > tol1 {
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            let mut q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            let older = prev;
            prev = step;
            if p.abs() < (0.5 * q * older).abs() && p > q * (a - x) && p < q * (b - x) {
                golden = false;
                step = p / q;
                let u = x + step;
                if u - a < tol2 || b - u < tol2 {
                    step = if m >= x { tol1 } else { -tol1 };
                }
            }
        }
        if golden {
            prev = if x >= m { a - x } else { b - x };
            step = GOLD * prev;
        }
        let u = x + if step >= 0.0 {
            step.max(tol1)
        } else {
            step.min(-tol1)
        };
        let fu = f(u);
        if fu <= fx {
            if u >= x {
                a = x;
            } else {
                b = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, fx)
}

#[cfg(test)]
mod tests {
    use super::brent_min;
    use std::cell::Cell;

    #[test]
    fn brent_finds_the_minimum_to_the_tolerance_in_few_evaluations() {
        // A lag-like residual sum: smooth, asymmetric, minimum at 913.4 s
        // inside the grid bracket 600…1200 s.
        let calls = Cell::new(0);
        let f = |x: f64| {
            calls.set(calls.get() + 1);
            let d = (x - 913.4) / 300.0;
            1.0 + d * d + 0.3 * d * d * d
        };
        let (x, fx) = brent_min(f, 600.0, 1200.0, 1.0);
        assert!((x - 913.4).abs() <= 1.0, "{x}");
        assert!((1.0..1.0 + 1e-4).contains(&fx), "{fx}");
        // Golden section alone needs ⌈ln(600/1)/ln(1.618)⌉ + 1 = 15.
        assert!(calls.get() <= 10, "{} evaluations", calls.get());
    }

    #[test]
    fn brent_on_a_monotone_bracket_ends_at_its_low_edge_and_on_a_flat_one_stays_inside() {
        let (x, _) = brent_min(|x| x, 120.0, 300.0, 1.0);
        assert!((120.0..=121.5).contains(&x), "{x}");
        let (x, _) = brent_min(|x| -x, 120.0, 300.0, 1.0);
        assert!((298.5..=300.0).contains(&x), "{x}");
        // A flat sum (the lag not identified): any point, but in the bracket
        // and a finite number of evaluations.
        let (x, fx) = brent_min(|_| 2.0, 0.0, 120.0, 1.0);
        assert!((0.0..=120.0).contains(&x) && fx == 2.0);
    }
}
