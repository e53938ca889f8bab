//! Small, bit-exact numeric kernels for the evaluators: sin/cos of an
//! integer phase (in turns) and tanh, in fixed point (Q30) and a fast f32
//! tanh. No libm in the hot path: the MCU budget for a whole 3-16-3 network
//! is ~1000 instructions, so each kernel is a table look-up plus a short
//! polynomial (fixed) or a short rational function (f32).
//!
//! Stated error bounds (all tested in `tests` below against f64 over dense
//! sweeps):
//! - [`sincos_q30`]: |error| ≤ 4e-9 (≈ 4 LSB of Q30) for sin and cos.
//! - [`sincos_f32`]: |error| ≤ 2e-7.
//! - [`tanh_q30`]: |error| ≤ 5e-9 over the whole Q26 input range (the
//!   saturation at |z| = 10 costs 1 − tanh 10 = 4.1e-9).
//! - [`tanh_f32`]: |error| ≤ 5e-7 over all finite inputs (the rational
//!   function itself is good to 1.1e-8; the rest is f32 rounding, about
//!   3.2e-7 at worst).
//!
//! The tables are generated once (the generator is the `tables_match_f64`
//! test, which recomputes them with std's f64 `sin`/`tanh` and requires each
//! entry to be within 1 LSB) and checked in as integers, so the host and
//! thumbv7em read the very same numbers and the fixed-point kernels are
//! bit-exact between the two.

/// 1.0 in Q30.
pub const ONE_Q30: i32 = 1 << 30;
/// π in Q30 (rounded), as i64 because it exceeds i32.
const PI_Q30: i64 = 3_373_259_426;

/// Rounding shift right by 30 of an i64 product.
#[inline(always)]
fn rshr30(x: i64) -> i64 {
    (x + (1 << 29)) >> 30
}

/// sin and cos of `turn` (a full turn is 2^32), both in Q30.
///
/// Table of sin at 256 points per turn plus the angle-addition formula with a
/// short Taylor series for the remaining angle δ < 2π/256 (δ⁵/120 < 8e-11).
#[inline]
pub fn sincos_q30(turn: u32) -> (i32, i32) {
    let i = (turn >> 24) as usize;
    let d = (turn & 0x00FF_FFFF) as i64;
    // δ in Q30 rad = d · 2π / 2^24 · 2^30 / 2^8 … = d · π / 2 (d < 2^24).
    let delta = (d * PI_Q30 + (1 << 30)) >> 31;
    let d2 = rshr30(delta * delta);
    let d3 = rshr30(d2 * delta);
    let d4 = rshr30(d2 * d2);
    // All of d2, d3, d4 are < 2^20 here, so the divisions by constants are
    // on small values (the compiler turns them into multiplies).
    let sd = delta - (d3 as i32 / 6) as i64;
    let cd = ONE_Q30 as i64 - (d2 as i32 / 2) as i64 + (d4 as i32 / 24) as i64;
    let sa = SIN_Q30.get(i).copied().unwrap_or(0) as i64;
    let ca = SIN_Q30.get(i + 64).copied().unwrap_or(0) as i64;
    let s = rshr30(sa * cd + ca * sd);
    let c = rshr30(ca * cd - sa * sd);
    (s as i32, c as i32)
}

/// sin and cos of `turn` (a full turn is 2^32) in f32, for the f32
/// evaluator: the same 256-point table and angle addition as
/// [`sincos_q30`], in f32 arithmetic (about 15 instructions).
/// |error| ≤ 2e-7 (tested).
#[inline]
pub fn sincos_f32(turn: u32) -> (f32, f32) {
    let i = (turn >> 24) as usize;
    // δ < 2π/256; (d as f32) is exact (d < 2^24).
    let d = (turn & 0x00FF_FFFF) as f32 * (core::f32::consts::TAU / 4_294_967_296.0);
    let d2 = d * d;
    let sd = d - d * d2 * (1.0 / 6.0);
    let cd = 1.0 - d2 * 0.5; // δ⁴/24 < 1.6e-8 left out
    let sa = SIN_F32.get(i).copied().unwrap_or(0.0);
    let ca = SIN_F32.get(i + 64).copied().unwrap_or(0.0);
    (sa * cd + ca * sd, ca * cd - sa * sd)
}

/// Fractional bits of the fixed-point tanh input.
pub const TANH_IN_FRAC: u32 = 26;
/// |z| at and beyond which tanh is returned as exactly ±1 (Q26 value of 10).
const TANH_SAT_Q26: u32 = 10 << TANH_IN_FRAC;

/// tanh of `z_q26` (Q26, so |z| < 32), result in Q30.
///
/// Cubic Hermite interpolation between table nodes every 1/64 with the
/// derivatives 1 − tanh² taken from the nodes themselves (interpolation
/// error ≤ h⁴/384·max|tanh⁗| ≈ 1e-9); beyond |z| = 10 the result is ±1
/// (1 − tanh 10 = 4.1e-9).
#[inline]
pub fn tanh_q30(z_q26: i32) -> i32 {
    let a = z_q26.unsigned_abs();
    let y = if a >= TANH_SAT_Q26 {
        ONE_Q30 as i64
    } else {
        let i = (a >> 20) as usize;
        let t = ((a & 0xF_FFFF) as i64) << 10; // Q30 in [0, 1)
        let y0 = TANH_Q30.get(i).copied().unwrap_or(ONE_Q30) as i64;
        let y1 = TANH_Q30.get(i + 1).copied().unwrap_or(ONE_Q30) as i64;
        // Derivatives scaled by the node spacing h = 1/64.
        let m0 = (ONE_Q30 as i64 - rshr30(y0 * y0)) >> 6;
        let m1 = (ONE_Q30 as i64 - rshr30(y1 * y1)) >> 6;
        let t2 = rshr30(t * t);
        let t3 = rshr30(t2 * t);
        let h01 = 3 * t2 - 2 * t3;
        let h10 = t3 - 2 * t2 + t;
        let h11 = t3 - t2;
        y0 + rshr30(h01 * (y1 - y0) + h10 * m0 + h11 * m1)
    };
    let y = y as i32;
    if z_q26 < 0 {
        -y
    } else {
        y
    }
}

/// x² beyond which [`tanh_f32`] returns ±1 (|x| > 8.5: 1 − tanh 8.5 = 8.3e-8).
const TANH_F32_SAT2: f32 = 8.5 * 8.5;

/// Fast tanh in f32: a (9, 8) odd/even rational minimax approximation on
/// |x| ≤ 8.5 (fitted for this crate: approximation error 1.1e-8, the rest of
/// the bound is f32 rounding), x·P(x²)/Q(x²) with a monic Q, about 20
/// instructions with one division; beyond |x| = 8.5 (tested on x², so NaN
/// takes the same branch) an out-of-line path returns ±1 (NaN stays NaN).
/// |error| ≤ 5e-7 against f64 tanh (tested; about 3.2e-7 in practice).
#[inline(always)]
pub fn tanh_f32(x: f32) -> f32 {
    const P0: f32 = 1_238_603.0;
    const P1: f32 = 166_049.66;
    const P2: f32 = 4_367.089;
    const P3: f32 = 26.161_222;
    const P4: f32 = 0.017_463_349;
    const Q0: f32 = 1_238_603.0;
    const Q1: f32 = 578_917.06;
    const Q2: f32 = 32_192.693;
    const Q3: f32 = 413.159_4;
    let x2 = x * x;
    // One compare on x² (NaN fails it too and takes the rare branch).
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(x2 <= TANH_F32_SAT2) {
        return tanh_f32_saturated(x);
    }
    let mut p = P4;
    p = p * x2 + P3;
    p = p * x2 + P2;
    p = p * x2 + P1;
    p = p * x2 + P0;
    p *= x;
    let mut q = x2 + Q3;
    q = q * x2 + Q2;
    q = q * x2 + Q1;
    q = q * x2 + Q0;
    p / q
}

/// The leading coefficient of [`tanh_f32`]'s numerator: [`tanh_over_lead_f32`]
/// returns tanh(x) / `TANH_F32_LEAD`, so a caller that multiplies the result
/// by a weight stores the weight × `TANH_F32_LEAD` instead (the MLP's output
/// weights, scaled at load).
pub const TANH_F32_LEAD: f32 = 0.017_463_349;

/// [`tanh_f32`] divided by [`TANH_F32_LEAD`]: the same rational function with
/// both P and Q monic, so its first Horner step is one addition (one
/// instruction fewer per neuron); beyond |x| = 8.5 ±1 / `TANH_F32_LEAD`.
/// |error · `TANH_F32_LEAD`| ≤ 5e-7 against f64 tanh (tested).
#[inline(always)]
pub fn tanh_over_lead_f32(x: f32) -> f32 {
    let x2 = x * x;
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(x2 <= TANH_F32_SAT2) {
        return tanh_over_lead_saturated(x);
    }
    tanh_over_lead_f32_bounded(x)
}

/// [`tanh_over_lead_f32`]'s numerator P / `TANH_F32_LEAD` (monic, P₄ = 1).
const TANH_LEAD_P: [f32; 4] = [70_925_856.0, 9_508_466.0, 250_071.67, 1_498.064_5];
/// [`tanh_f32`]'s denominator Q (monic, Q₄ = 1).
const TANH_Q: [f32; 4] = [1_238_603.0, 578_917.06, 32_192.693, 413.159_4];

/// [`tanh_over_lead_f32`] for |x| ≤ 8.5 known beforehand (no saturation
/// test; the caller proves the bound): the same operations, the same result.
#[inline(always)]
pub fn tanh_over_lead_f32_bounded(x: f32) -> f32 {
    let x2 = x * x;
    let mut p = x2 + TANH_LEAD_P[3];
    p = p * x2 + TANH_LEAD_P[2];
    p = p * x2 + TANH_LEAD_P[1];
    p = p * x2 + TANH_LEAD_P[0];
    p *= x;
    let mut q = x2 + TANH_Q[3];
    q = q * x2 + TANH_Q[2];
    q = q * x2 + TANH_Q[1];
    q = q * x2 + TANH_Q[0];
    p / q
}

/// The rare branch of [`tanh_over_lead_f32`]: ±1 / `TANH_F32_LEAD`, NaN kept.
#[cold]
#[inline(never)]
fn tanh_over_lead_saturated(x: f32) -> f32 {
    if x.is_nan() {
        x
    } else {
        (1.0 / TANH_F32_LEAD).copysign(x)
    }
}

/// The rare branch of [`tanh_f32`]: ±1 beyond the fitted range, NaN kept.
#[cold]
#[inline(never)]
fn tanh_f32_saturated(x: f32) -> f32 {
    if x.is_nan() {
        x
    } else {
        1.0f32.copysign(x)
    }
}

/// sin(2πi/256) for the first quarter turn, i = 0..=64, Q30 (in the
/// source as integers; the rest of the turn is its mirror images, and
/// `SIN_Q30` and `SIN_F32` are built from it).
const SIN_QUARTER_Q30: [i32; 65] = [
    0, 26350943, 52686014, 78989349, 105245103, 131437462, 157550647, 183568930, 209476638,
    235258165, 260897982, 286380643, 311690799, 336813204, 361732726, 386434353, 410903207,
    435124548, 459083786, 482766489, 506158392, 529245404, 552013618, 574449320, 596538995,
    618269338, 639627258, 660599890, 681174602, 701339000, 721080937, 740388522, 759250125,
    777654384, 795590213, 813046808, 830013654, 846480531, 862437520, 877875009, 892783698,
    907154608, 920979082, 934248793, 946955747, 959092290, 970651112, 981625251, 992008094,
    1001793390, 1010975242, 1019548121, 1027506862, 1034846671, 1041563127, 1047652185, 1053110176,
    1057933813, 1062120190, 1065666786, 1068571464, 1070832474, 1072448455, 1073418433, 1073741824,
];

/// The sin table over a turn and a quarter, from [`SIN_QUARTER_Q30`] by
/// sin(π − x) = sin x and sin(π + x) = −sin x.
const SIN_Q30_TABLE: [i32; 320] = {
    let mut t = [0i32; 320];
    let mut i = 0;
    while i < 320 {
        let k = i % 128;
        let v = SIN_QUARTER_Q30[if k <= 64 { k } else { 128 - k }];
        t[i] = if i % 256 < 128 { v } else { -v };
        i += 1;
    }
    t
};

/// sin(2πi/256), Q30, i = 0..320 (a quarter turn extra so cos = sin[i + 64]).
pub(crate) static SIN_Q30: [i32; 320] = SIN_Q30_TABLE;

/// The same table as f32 (converted at compile time).
static SIN_F32: [f32; 320] = {
    let mut t = [0.0f32; 320];
    let mut i = 0;
    while i < 320 {
        t[i] = SIN_Q30_TABLE[i] as f32 * (1.0 / ONE_Q30 as f32);
        i += 1;
    }
    t
};

/// tanh(i/64), Q30, i = 0..=640.
pub(crate) static TANH_Q30: [i32; 641] = [
    0, 16775851, 33543514, 50294816, 67021619, 83715829, 100369417, 116974433, 133523019,
    150007427, 166420030, 182753337, 199000008, 215152863, 231204897, 247149288, 262979411,
    278688847, 294271390, 309721058, 325032097, 340198992, 355216470, 370079506, 384783327,
    399323414, 413695509, 427895611, 441919982, 455765145, 469427884, 482905241, 496194519,
    509293276, 522199322, 534910717, 547425766, 559743014, 571861244, 583779466, 595496917,
    607013051, 618327534, 629440237, 640351229, 651060770, 661569304, 671877449, 681985995,
    691895889, 701608235, 711124280, 720445410, 729573140, 738509109, 747255071, 755812887,
    764184519, 772372023, 780377540, 788203292, 795851574, 803324746, 810625229, 817755498,
    824718078, 831515533, 838150469, 844625518, 850943344, 857106631, 863118081, 868980407,
    874696335, 880268593, 885699910, 890993016, 896150633, 901175474, 906070241, 910837623,
    915480290, 920000894, 924402065, 928686409, 932856508, 936914916, 940864156, 944706725,
    948445085, 952081667, 955618867, 959059047, 962404532, 965657614, 968820543, 971895537,
    974884771, 977790386, 980614480, 983359117, 986026317, 988618065, 991136306, 993582944,
    995959846, 998268841, 1000511717, 1002690226, 1004806081, 1006860957, 1008856492, 1010794288,
    1012675908, 1014502881, 1016276701, 1017998824, 1019670673, 1021293637, 1022869072, 1024398298,
    1025882605, 1027323250, 1028721460, 1030078428, 1031395319, 1032673268, 1033913380, 1035116732,
    1036284373, 1037417324, 1038516580, 1039583108, 1040617851, 1041621725, 1042595624, 1043540415,
    1044456943, 1045346031, 1046208476, 1047045057, 1047856530, 1048643629, 1049407069, 1050147544,
    1050865731, 1051562285, 1052237845, 1052893030, 1053528442, 1054144667, 1054742274, 1055321814,
    1055883826, 1056428829, 1056957331, 1057469822, 1057966782, 1058448672, 1058915945, 1059369036,
    1059808371, 1060234362, 1060647409, 1061047900, 1061436213, 1061812714, 1062177758, 1062531689,
    1062874844, 1063207545, 1063530110, 1063842843, 1064146042, 1064439994, 1064724980, 1065001270,
    1065269127, 1065528808, 1065780559, 1066024621, 1066261228, 1066490604, 1066712970, 1066928539,
    1067137518, 1067340105, 1067536496, 1067726879, 1067911437, 1068090347, 1068263781, 1068431906,
    1068594884, 1068752870, 1068906019, 1069054476, 1069198386, 1069337886, 1069473111, 1069604193,
    1069731257, 1069854425, 1069973818, 1070089550, 1070201734, 1070310477, 1070415885, 1070518060,
    1070617100, 1070713102, 1070806159, 1070896360, 1070983793, 1071068543, 1071150692, 1071230320,
    1071307503, 1071382317, 1071454834, 1071525125, 1071593257, 1071659298, 1071723310, 1071785356,
    1071845497, 1071903791, 1071960295, 1072015063, 1072068148, 1072119603, 1072169477, 1072217818,
    1072264675, 1072310092, 1072354113, 1072396782, 1072438139, 1072478226, 1072517080, 1072554741,
    1072591244, 1072626625, 1072660919, 1072694159, 1072726377, 1072757605, 1072787872, 1072817210,
    1072845645, 1072873207, 1072899921, 1072925813, 1072950910, 1072975235, 1072998813, 1073021665,
    1073043815, 1073065284, 1073086092, 1073106261, 1073125810, 1073144757, 1073163122, 1073180922,
    1073198175, 1073214897, 1073231105, 1073246815, 1073262041, 1073276799, 1073291104, 1073304968,
    1073318406, 1073331431, 1073344055, 1073356291, 1073368150, 1073379645, 1073390786, 1073401585,
    1073412051, 1073422196, 1073432028, 1073441558, 1073450795, 1073459748, 1073468426, 1073476836,
    1073484988, 1073492889, 1073500547, 1073507970, 1073515164, 1073522137, 1073528895, 1073535446,
    1073541795, 1073547948, 1073553913, 1073559694, 1073565297, 1073570728, 1073575991, 1073581093,
    1073586038, 1073590830, 1073595476, 1073599978, 1073604342, 1073608572, 1073612671, 1073616644,
    1073620496, 1073624228, 1073627846, 1073631353, 1073634751, 1073638045, 1073641238, 1073644333,
    1073647332, 1073650239, 1073653057, 1073655788, 1073658435, 1073661000, 1073663487, 1073665897,
    1073668233, 1073670497, 1073672691, 1073674818, 1073676880, 1073678878, 1073680815, 1073682692,
    1073684511, 1073686274, 1073687983, 1073689640, 1073691245, 1073692801, 1073694309, 1073695771,
    1073697188, 1073698561, 1073699892, 1073701183, 1073702433, 1073703645, 1073704819, 1073705958,
    1073707061, 1073708131, 1073709168, 1073710172, 1073711146, 1073712090, 1073713005, 1073713891,
    1073714751, 1073715584, 1073716391, 1073717174, 1073717932, 1073718667, 1073719379, 1073720070,
    1073720739, 1073721388, 1073722017, 1073722626, 1073723217, 1073723789, 1073724344, 1073724882,
    1073725403, 1073725908, 1073726398, 1073726873, 1073727333, 1073727779, 1073728211, 1073728629,
    1073729035, 1073729429, 1073729810, 1073730180, 1073730538, 1073730885, 1073731222, 1073731548,
    1073731864, 1073732171, 1073732468, 1073732756, 1073733035, 1073733305, 1073733567, 1073733821,
    1073734067, 1073734306, 1073734537, 1073734761, 1073734979, 1073735189, 1073735393, 1073735591,
    1073735783, 1073735969, 1073736149, 1073736324, 1073736493, 1073736657, 1073736816, 1073736970,
    1073737119, 1073737264, 1073737404, 1073737540, 1073737672, 1073737800, 1073737924, 1073738044,
    1073738160, 1073738273, 1073738382, 1073738488, 1073738591, 1073738690, 1073738786, 1073738880,
    1073738970, 1073739058, 1073739143, 1073739226, 1073739306, 1073739383, 1073739458, 1073739531,
    1073739602, 1073739670, 1073739736, 1073739801, 1073739863, 1073739923, 1073739982, 1073740038,
    1073740093, 1073740146, 1073740198, 1073740248, 1073740297, 1073740344, 1073740389, 1073740433,
    1073740476, 1073740518, 1073740558, 1073740597, 1073740634, 1073740671, 1073740707, 1073740741,
    1073740774, 1073740807, 1073740838, 1073740868, 1073740898, 1073740926, 1073740954, 1073740980,
    1073741006, 1073741032, 1073741056, 1073741080, 1073741103, 1073741125, 1073741146, 1073741167,
    1073741187, 1073741207, 1073741226, 1073741244, 1073741262, 1073741279, 1073741296, 1073741312,
    1073741328, 1073741343, 1073741358, 1073741373, 1073741386, 1073741400, 1073741413, 1073741426,
    1073741438, 1073741450, 1073741461, 1073741472, 1073741483, 1073741494, 1073741504, 1073741514,
    1073741523, 1073741532, 1073741541, 1073741550, 1073741559, 1073741567, 1073741575, 1073741582,
    1073741590, 1073741597, 1073741604, 1073741611, 1073741617, 1073741624, 1073741630, 1073741636,
    1073741642, 1073741647, 1073741653, 1073741658, 1073741663, 1073741668, 1073741673, 1073741677,
    1073741682, 1073741686, 1073741691, 1073741695, 1073741699, 1073741702, 1073741706, 1073741710,
    1073741713, 1073741717, 1073741720, 1073741723, 1073741726, 1073741729, 1073741732, 1073741735,
    1073741738, 1073741740, 1073741743, 1073741746, 1073741748, 1073741750, 1073741753, 1073741755,
    1073741757, 1073741759, 1073741761, 1073741763, 1073741765, 1073741767, 1073741768, 1073741770,
    1073741772, 1073741773, 1073741775, 1073741776, 1073741778, 1073741779, 1073741781, 1073741782,
    1073741783, 1073741785, 1073741786, 1073741787, 1073741788, 1073741789, 1073741790, 1073741791,
    1073741792, 1073741793, 1073741794, 1073741795, 1073741796, 1073741797, 1073741798, 1073741799,
    1073741799, 1073741800, 1073741801, 1073741802, 1073741802, 1073741803, 1073741804, 1073741804,
    1073741805, 1073741805, 1073741806, 1073741806, 1073741807, 1073741808, 1073741808, 1073741809,
    1073741809, 1073741809, 1073741810, 1073741810, 1073741811, 1073741811, 1073741812, 1073741812,
    1073741812, 1073741813, 1073741813, 1073741813, 1073741814, 1073741814, 1073741814, 1073741815,
    1073741815, 1073741815, 1073741815, 1073741816, 1073741816, 1073741816, 1073741816, 1073741817,
    1073741817, 1073741817, 1073741817, 1073741818, 1073741818, 1073741818, 1073741818, 1073741818,
    1073741818, 1073741819, 1073741819, 1073741819, 1073741819, 1073741819, 1073741819, 1073741820,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_match_f64() {
        for (i, &v) in SIN_Q30.iter().enumerate() {
            let exact =
                (2.0 * core::f64::consts::PI * i as f64 / 256.0).sin() * (1u64 << 30) as f64;
            assert!((v as f64 - exact).abs() <= 1.0, "sin entry {i}");
        }
        for (i, &v) in TANH_Q30.iter().enumerate() {
            let exact = (i as f64 / 64.0).tanh() * (1u64 << 30) as f64;
            assert!((v as f64 - exact).abs() <= 1.0, "tanh entry {i}");
        }
    }

    /// The worst error of a sin/cos `f` (values as f64) over 2 million
    /// turns from `start`, a dense sweep with a stride co-prime to the
    /// table spacing.
    fn worst_sincos_error(start: u32, f: impl Fn(u32) -> (f64, f64)) -> f64 {
        let mut worst = 0.0f64;
        let mut turn = start;
        for _ in 0..2_000_000 {
            let (s, c) = f(turn);
            let a = turn as f64 / 4_294_967_296.0 * 2.0 * core::f64::consts::PI;
            worst = worst.max((s - a.sin()).abs()).max((c - a.cos()).abs());
            turn = turn.wrapping_add(2_147_483_647 / 1_000_000 * 2 + 1);
        }
        worst
    }

    #[test]
    fn sincos_error_bound() {
        let q = (1u64 << 30) as f64;
        let worst = worst_sincos_error(0, |turn| {
            let (s, c) = sincos_q30(turn);
            (s as f64 / q, c as f64 / q)
        });
        assert!(worst <= 4e-9, "sincos worst error {worst:e}");
    }

    #[test]
    fn sincos_f32_error_bound() {
        let worst = worst_sincos_error(12345, |turn| {
            let (s, c) = sincos_f32(turn);
            (s as f64, c as f64)
        });
        assert!(worst <= 2e-7, "sincos_f32 worst error {worst:e}");
    }

    #[test]
    fn tanh_q30_error_bound() {
        let mut worst = 0.0f64;
        let mut z: i64 = -(12i64 << 26);
        while z <= 12i64 << 26 {
            let y = tanh_q30(z as i32) as f64 / (1u64 << 30) as f64;
            let x = z as f64 / (1u64 << 26) as f64;
            worst = worst.max((y - x.tanh()).abs());
            z += 1_234_567; // not a multiple of the node spacing
        }
        for z in [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX] {
            let y = tanh_q30(z) as f64 / (1u64 << 30) as f64;
            let x = z as f64 / (1u64 << 26) as f64;
            worst = worst.max((y - x.tanh()).abs());
        }
        assert!(worst <= 5e-9, "tanh_q30 worst error {worst:e}");
    }

    /// The worst |f(x) − tanh x| of an f32 tanh `f` over a dense sweep of
    /// ±12 and the extremes (±max, ±∞, ±0, a denormal-sized input).
    fn worst_f32_tanh_error(f: impl Fn(f32) -> f64) -> f64 {
        let mut worst = 0.0f64;
        let mut x = -12.0f64;
        while x <= 12.0 {
            worst = worst.max((f(x as f32) - (x as f32 as f64).tanh()).abs());
            x += 1.37e-4;
        }
        for x in [
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            1e-30,
        ] {
            worst = worst.max((f(x) - (x as f64).tanh()).abs());
        }
        worst
    }

    #[test]
    fn tanh_f32_error_bound() {
        let worst = worst_f32_tanh_error(|x| tanh_f32(x) as f64);
        assert!(worst <= 5e-7, "tanh_f32 worst error {worst:e}");
        assert!(tanh_f32(f32::NAN).is_nan());
    }

    #[test]
    fn tanh_over_lead_f32_error_bound() {
        let lead = TANH_F32_LEAD as f64;
        let worst = worst_f32_tanh_error(|x| tanh_over_lead_f32(x) as f64 * lead);
        assert!(worst <= 5e-7, "tanh_over_lead_f32 worst error {worst:e}");
        assert!(tanh_over_lead_f32(f32::NAN).is_nan());
    }
}
