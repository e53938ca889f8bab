//! The accuracy sweep (the **Accuracy check** of the module docs): the
//! points at which the table is compared with the host's model and on
//! which the envelope's max |correction| and slew are measured — an
//! 11-point grid on the used axes at every state (approach direction, low
//! and high temperature, low and high tool arm, where the model has such
//! terms) and dense lines along each axis at the first and the last state.

use super::envelope::Ranges;
use super::mapping::shortest_period_mm;
use crate::export::Point;
use crate::model::FittedModel;

/// The sweep's points inside `ranges`: states over both directions when
/// the model has a reversal term (`has_rev`), low and high temperature
/// when it reads a channel, low and high tool arm when it has an Abbe term
/// (`has_abbe`). Positions, temperatures and arms are whole nm and m°C.
pub(super) fn points(
    model: &FittedModel,
    ranges: &Ranges,
    has_abbe: bool,
    has_rev: bool,
) -> Vec<Point> {
    // The sweep: an 11-point grid on the used axes at every state, and
    // dense lines at the first and last state (both directions, low and
    // high temperature and tool arm together).
    let used: Vec<usize> = (0..3).filter(|&a| ranges.travel[a].is_some()).collect();
    let at = |a: usize, k: usize, n: usize| -> f64 {
        let (lo, hi) = ranges.travel[a].unwrap_or((0, 0));
        let v = lo as f64 + (hi as f64 - lo as f64) * k as f64 / (n - 1).max(1) as f64;
        v.round() * 1e-6
    };
    let n_grid: usize = 11;
    let mut grid_pos: Vec<[f64; 3]> = Vec::new();
    for k in 0..n_grid.pow(used.len() as u32) {
        let mut p = [0.0; 3];
        let mut r = k;
        for &a in &used {
            p[a] = at(a, r % n_grid, n_grid);
            r /= n_grid;
        }
        grid_pos.push(p);
    }
    let mut line_pos: Vec<[f64; 3]> = Vec::new();
    for &a in &used {
        let (lo, hi) = ranges.travel[a].unwrap_or((0, 0));
        let span_mm = (hi as f64 - lo as f64) * 1e-6;
        let step = match shortest_period_mm(model, a) {
            Some(p) => (p / 16.0).min(span_mm / 2000.0),
            None => span_mm / 2000.0,
        };
        let n_line = ((span_mm / step.max(1e-6)).ceil() as usize + 1).clamp(2, 4000);
        // The other axes at their low, middle and high position together.
        for k in 0..3 {
            let mut base = [0.0; 3];
            for &b in used.iter().filter(|&&b| b != a) {
                base[b] = at(b, k, 3);
            }
            for i in 0..n_line {
                let mut p = base;
                p[a] = at(a, i, n_line);
                line_pos.push(p);
            }
        }
    }
    let dirs: Vec<i8> = if has_rev { vec![1, -1] } else { vec![1] };
    // 0 = every channel at its low end, 1 = at its high end.
    let temps: Vec<usize> = if ranges.temps_c.is_empty() {
        vec![0]
    } else {
        vec![0, 1]
    };
    let (tool_lo, tool_hi) = ranges.tool_mm;
    let tools: Vec<f64> = if has_abbe {
        vec![tool_lo, tool_hi]
    } else {
        vec![tool_lo]
    };
    let mut states: Vec<(i8, usize, f64)> = Vec::new();
    for &d in &dirs {
        for &t in &temps {
            for &tool in &tools {
                states.push((d, t, tool));
            }
        }
    }
    let first_last = [states[0], states[states.len() - 1]];
    let mut points = Vec::with_capacity(grid_pos.len() * states.len() + 2 * line_pos.len());
    let mut push = |p: &[f64; 3], (d, t, tool): (i8, usize, f64)| {
        points.push(Point {
            pos_mm: *p,
            dir: [d; 3],
            temp_c: ranges
                .temps_c
                .iter()
                .map(|r| ((if t == 0 { r.0 } else { r.1 }) * 1000.0).round() / 1000.0)
                .collect(),
            tool_mm: (tool * 1e6).round() * 1e-6,
        });
    };
    for &st in &states {
        for p in &grid_pos {
            push(p, st);
        }
    }
    for (k, &st) in first_last.iter().enumerate() {
        if k == 1 && states.len() == 1 {
            break;
        }
        for p in &line_pos {
            push(p, st);
        }
    }
    points
}
