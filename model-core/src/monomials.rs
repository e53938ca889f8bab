//! Named monomial sets for polynomial terms (exponents `[a, b, c]` of
//! x^a y^b z^c in normalised positions). These are the seed models the host
//! tool fits (`--model cubic19`, `--model kinematic`); they live here so the
//! host and the docs name the same lists.

use crate::table::Monomial;

/// The seed's 19 terms per error axis: 1, x, x², x³, y, y², y³, z, z², z³,
/// xy, xz, yz, xy², xz², yz², yx², zx², zy² (no xyz).
pub const CUBIC19: [Monomial; 19] = [
    [0, 0, 0],
    [1, 0, 0],
    [2, 0, 0],
    [3, 0, 0],
    [0, 1, 0],
    [0, 2, 0],
    [0, 3, 0],
    [0, 0, 1],
    [0, 0, 2],
    [0, 0, 3],
    [1, 1, 0],
    [1, 0, 1],
    [0, 1, 1],
    [1, 2, 0],
    [1, 0, 2],
    [0, 1, 2],
    [2, 1, 0],
    [2, 0, 1],
    [0, 2, 1],
];

/// `kinematic` for ex: the own axis' cubic (1, x, x², x³) plus the
/// quadratic and cubic straightness along the other axes (y², y³, z², z³).
/// No linear terms in the other axes (those are squareness, a separate
/// diagnosis effect) and no cross products.
pub const KINEMATIC_X: [Monomial; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [2, 0, 0],
    [3, 0, 0],
    [0, 2, 0],
    [0, 3, 0],
    [0, 0, 2],
    [0, 0, 3],
];
/// `kinematic` for ey: 1, y, y², y³, x², x³, z², z³.
pub const KINEMATIC_Y: [Monomial; 8] = [
    [0, 0, 0],
    [0, 1, 0],
    [0, 2, 0],
    [0, 3, 0],
    [2, 0, 0],
    [3, 0, 0],
    [0, 0, 2],
    [0, 0, 3],
];
/// `kinematic` for ez: 1, z, z², z³, x², x³, y², y³.
pub const KINEMATIC_Z: [Monomial; 8] = [
    [0, 0, 0],
    [0, 0, 1],
    [0, 0, 2],
    [0, 0, 3],
    [2, 0, 0],
    [3, 0, 0],
    [0, 2, 0],
    [0, 3, 0],
];

/// The `kinematic` set of `output` (0 = ex, 1 = ey, 2 = ez).
pub fn kinematic(output: usize) -> &'static [Monomial] {
    match output {
        0 => &KINEMATIC_X,
        1 => &KINEMATIC_Y,
        _ => &KINEMATIC_Z,
    }
}

/// Every monomial of total degree ≤ `degree` (≤ 5), in graded order.
pub fn up_to_degree(degree: u8) -> &'static [Monomial] {
    let n = match degree {
        0 => 1,
        1 => 4,
        2 => 10,
        3 => 20,
        4 => 35,
        _ => 56,
    };
    &crate::eval::MONO_EXPS[..n]
}
