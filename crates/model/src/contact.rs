//! Wheel–rail contact mechanics: Hertz, Kalker, Polach
//! (docs/spec/contact.md, the contract for everything in this module).
//!
//! The product model needs two things from the contact of a wheel on a rail:
//!
//! - the mean Hertzian pressure `pm`, which scales product consumption through
//!   `fp` (model.md, eq. 2), and
//! - the coefficient of adhesion T/N, which is what the friction coefficient
//!   `mu` of eq. (4) becomes in a rolling, creeping contact.
//!
//! The chain is the usual one of railway vehicle dynamics:
//!
//! 1. [`hertz`]: the elliptical Hertz contact (Hertz 1882; Johnson, *Contact
//!    Mechanics*, 1985, §4.2) with the complete elliptic integrals evaluated
//!    exactly rather than read from the usual tables of Hertz coefficients
//!    (good to a percent or so): `pm` enters `fp` directly, and an
//!    independent implementation must agree with it to 1e-6
//!    (tests/reference/contact_golden.csv, copied from the independent implementation).
//! 2. [`kalker`]: Kalker's creepage coefficients c11, c22, c23 (Kalker 1990,
//!    Table E3), interpolated as contact.md prescribes.
//! 3. [`polach`]: Polach's creep force model (Polach 1999, Vehicle System
//!    Dynamics Suppl. 33, with the spin extension; Polach 2005, Wear 258, for
//!    the reduction factors kA, kS and the slip-velocity dependent friction).
//!
//! Everything here is a pure function of numbers: no I/O, no allocation, no
//! panics. Preconditions (positive load, positive curvature sums, positive
//! semi-axes, `mu0 > 0`) are the caller's to keep; outside them the functions
//! return non-physical numbers (possibly NaN or infinity) rather than panic.
//!
//! Axes (contact.md, "Hertz"): x is the rolling direction, y lateral. `a` is
//! always the semi-axis along x and `b` the one along y.
//!
//! The engine solves the ellipse's shape once per wheel diameter
//! ([`HertzShape`]: it does not depend on the load), scales it to each
//! wheel's load ([`HertzContact`]) with Kalker's coefficients ([`kalker`]),
//! and asks [`polach`] for the adhesion at each contact.

use std::f64::consts::PI;

/// Linear-elastic material of wheel and rail (both the same steel).
///
/// contact.md, "Hertz": `E = 210 GPa`, `nu = 0.3` unless configured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steel {
    /// Young's modulus E [Pa].
    pub e_pa: f64,
    /// Poisson's ratio nu [-].
    pub nu: f64,
}

impl Steel {
    /// The spec's steel: E = 210 GPa, nu = 0.3 (contact.md, "Hertz").
    pub const DEFAULT: Steel = Steel {
        e_pa: 210e9,
        nu: 0.3,
    };

    /// Shear modulus `G = E / (2 (1 + nu))` [Pa] (contact.md, "Hertz"); the
    /// stiffness Polach's creep force model scales the creepages with.
    pub fn g_pa(&self) -> f64 {
        self.e_pa / (2.0 * (1.0 + self.nu))
    }

    /// Contact modulus `E* = E / (2 (1 - nu^2))` [Pa] of two bodies of this
    /// steel (contact.md, "Hertz"): `1/E* = (1 - nu^2)/E + (1 - nu^2)/E`.
    pub(crate) fn e_star_pa(&self) -> f64 {
        self.e_pa / (2.0 * (1.0 - self.nu * self.nu))
    }
}

impl Default for Steel {
    fn default() -> Self {
        Steel::DEFAULT
    }
}

/// The Hertzian contact ellipse of one wheel on one rail (contact.md, "Hertz").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HertzContact {
    /// Semi-axis along x, the rolling direction [m].
    pub a_m: f64,
    /// Semi-axis along y, lateral [m].
    pub b_m: f64,
    /// Maximum pressure `p0 = 3Q / (2 pi a b)` [Pa].
    pub p0_pa: f64,
    /// Mean pressure `pm = Q / (pi a b)` [Pa]; the `pm` of model.md eq. (2).
    pub pm_pa: f64,
}

/// Complete elliptic integrals of the first and second kind, K(e) and E(e),
/// by the arithmetic–geometric mean (contact.md, "Hertz"):
///
/// ```text
/// a0 = 1, b0 = sqrt(1 - e^2), c0^2 = e^2
/// c_{n+1} = (a_n - b_n)/2, a_{n+1} = (a_n + b_n)/2, b_{n+1} = sqrt(a_n b_n)
/// K = pi / (2 a_inf), E = K (1 - S), S = sum_{n>=0} 2^(n-1) c_n^2
/// ```
///
/// Two choices keep every digit without changing the mathematics:
///
/// - The argument is the *complementary* modulus `k = sqrt(1 - e^2)`, which is
///   the Hertz aspect ratio itself, passed straight in as `b0`; computing
///   `sqrt(1 - e^2)` would cancel for slender ellipses.
/// - The sum S is kept as its n = 0 term `e^2/2` and the rest, so that
///   `K - E = K S` and `e^2 - S = e^2/2 - rest` never subtract two nearly
///   equal numbers, even for a nearly circular contact (e -> 0) where Hertz
///   divides them by `e^2`.
#[derive(Debug, Clone, Copy)]
struct EllipticIntegrals {
    /// `e^2 = 1 - k^2`.
    e_sq: f64,
    /// K(e).
    k_int: f64,
    /// `sum_{n>=1} 2^(n-1) c_n^2`, the AGM sum without its n = 0 term.
    sum_rest: f64,
}

impl EllipticIntegrals {
    fn new(k: f64) -> Self {
        // AGM converges quadratically; 64 steps are far more than any finite
        // argument needs and only bound the loop for NaN.
        const MAX_STEPS: usize = 64;
        let (mut a, mut b) = (1.0_f64, k);
        let mut weight = 0.5; // 2^(n-1)
        let mut sum_rest = 0.0;
        for _ in 0..MAX_STEPS {
            let c = 0.5 * (a - b);
            (a, b) = (0.5 * (a + b), (a * b).sqrt());
            weight *= 2.0;
            sum_rest += weight * c * c;
            // Once c is a rounding error of a, the next term is of order c^4
            // and a, b only trade the last ulp: the sum is complete.
            if c.abs() <= f64::EPSILON * a {
                break;
            }
        }
        EllipticIntegrals {
            e_sq: (1.0 - k) * (1.0 + k),
            k_int: PI / (2.0 * a),
            sum_rest,
        }
    }

    /// The whole AGM sum `S = e^2/2 + sum_rest`.
    fn sum(&self) -> f64 {
        0.5 * self.e_sq + self.sum_rest
    }

    /// K(e) - E(e) = K S.
    fn k_minus_e(&self) -> f64 {
        self.k_int * self.sum()
    }
}

/// The Hertz contact of a wheel on a rail (contact.md, "Hertz").
///
/// - `q_n`: normal load Q [N] (`wheel_load_kN * 1e3`).
/// - `r_wx_m`: wheel rolling radius R_wx [m] (half the wheel diameter).
/// - `r_wy_m`: wheel transverse profile radius R_wy [m]; `f64::INFINITY` for a
///   flat (cylindrical) tread, negative for a concave profile.
/// - `r_ry_m`: rail head transverse radius R_ry [m].
///
/// With the curvature half-sums `Ax = 1/(2 R_wx)` and
/// `By = (1/R_wy + 1/R_ry)/2`, the long semi-axis lies along the smaller
/// curvature. The aspect ratio `k` (short/long), `e^2 = 1 - k^2`, solves
///
/// ```text
/// ((1/k^2) E(e) - K(e)) / (K(e) - E(e)) = C_max / C_min
/// ```
///
/// by bisection on k in (0, 1) until the midpoint equals an end of the
/// interval, i.e. to full double precision (the left side falls monotonically
/// from infinity at k -> 0 to 1 at k = 1). Then
/// `a_long^3 = 3 Q (K - E) / (2 pi E* C_min e^2)` and `a_short = k a_long`.
/// A circular contact (`Ax = By`) is `a = b = (3 Q / (4 E* (Ax + By)))^(1/3)`.
///
/// Precondition: `q_n > 0`, `Ax > 0`, `By > 0` (a convex contact), all finite
/// except `r_wy_m`. Outside it the result is meaningless (NaN or infinite),
/// but the function returns.
pub fn hertz(q_n: f64, r_wx_m: f64, r_wy_m: f64, r_ry_m: f64, steel: &Steel) -> HertzContact {
    HertzShape::new(r_wx_m, r_wy_m, r_ry_m, steel).contact(q_n)
}

/// The part of the Hertz solution that does not depend on the load: the
/// semi-axis ratio `k` and the elliptic integrals. A wheel of one diameter on
/// one rail has one shape whatever its load, so the engine solves the
/// bisection once per diameter and scales it with `Q^(1/3)`
/// ([`HertzShape::contact`]); [`hertz`] is exactly `new(..).contact(q)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HertzShape {
    e_star_pa: f64,
    ax_per_m: f64,
    by_per_m: f64,
    /// `None` for a circular contact (`Ax = By`).
    ellipse: Option<Ellipse>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Ellipse {
    c_min: f64,
    k: f64,
    k_minus_e: f64,
    e_sq: f64,
}

impl HertzShape {
    /// Solves the shape for the curvatures of a wheel of radius `r_wx_m` with
    /// transverse profile radius `r_wy_m` on a rail head of radius `r_ry_m`.
    pub fn new(r_wx_m: f64, r_wy_m: f64, r_ry_m: f64, steel: &Steel) -> Self {
        let ax_per_m = 1.0 / (2.0 * r_wx_m);
        let by_per_m = 0.5 * (1.0 / r_wy_m + 1.0 / r_ry_m);
        let e_star_pa = steel.e_star_pa();
        let ellipse = (ax_per_m != by_per_m).then(|| {
            let (c_min, c_max) = if ax_per_m < by_per_m {
                (ax_per_m, by_per_m)
            } else {
                (by_per_m, ax_per_m)
            };
            let ratio = c_max / c_min;

            // Bisection: a midpoint whose left side exceeds the curvature ratio is
            // too slender, so k lies above it. Terminates for any input (also NaN):
            // the interval halves until it holds no double between its ends.
            let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
            let k = loop {
                let mid = 0.5 * (lo + hi);
                if mid <= lo || mid >= hi {
                    break mid;
                }
                // ((1/k^2) E - K) / (K - E) with E = K (1 - S) is
                // (e^2 - S) / (k^2 S): the same number, without the cancellation
                // of E/k^2 - K that would cost ~8 digits of k near the circle.
                let integrals = EllipticIntegrals::new(mid);
                let lhs =
                    (0.5 * integrals.e_sq - integrals.sum_rest) / (mid * mid * integrals.sum());
                if lhs > ratio {
                    lo = mid;
                } else {
                    hi = mid;
                }
            };
            let integrals = EllipticIntegrals::new(k);
            Ellipse {
                c_min,
                k,
                k_minus_e: integrals.k_minus_e(),
                e_sq: integrals.e_sq,
            }
        });
        Self {
            e_star_pa,
            ax_per_m,
            by_per_m,
            ellipse,
        }
    }

    /// The contact under wheel load `q_n`.
    pub fn contact(&self, q_n: f64) -> HertzContact {
        let (a_m, b_m) = match &self.ellipse {
            None => {
                let r =
                    (3.0 * q_n / (4.0 * self.e_star_pa * (self.ax_per_m + self.by_per_m))).cbrt();
                (r, r)
            }
            Some(el) => {
                let a_long = (3.0 * q_n * el.k_minus_e
                    / (2.0 * PI * self.e_star_pa * el.c_min * el.e_sq))
                    .cbrt();
                let a_short = el.k * a_long;
                // The long axis lies along the direction of smaller curvature.
                if self.ax_per_m < self.by_per_m {
                    (a_long, a_short)
                } else {
                    (a_short, a_long)
                }
            }
        };
        HertzContact {
            a_m,
            b_m,
            p0_pa: 3.0 * q_n / (2.0 * PI * a_m * b_m),
            pm_pa: q_n / (PI * a_m * b_m),
        }
    }
}

/// Kalker's creepage coefficients (Kalker 1990, Table E3): the dimensionless
/// slopes of the linear (no-slip) creep law, longitudinal `c11`, lateral
/// `c22` and lateral-spin `c23`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalkerCoefficients {
    /// Longitudinal creepage coefficient c11 [-].
    pub c11: f64,
    /// Lateral creepage coefficient c22 [-].
    pub c22: f64,
    /// Lateral force from spin, c23 [-].
    pub c23: f64,
}

/// Number of columns in Kalker's Table E3: a/b = 0.1 … 1.0, then b/a = 0.9 … 0.1.
const KALKER_COLUMNS: usize = 19;

/// One coefficient of Kalker's Table E3: rows nu = 0, 0.25, 0.5.
type KalkerTable = [[f64; KALKER_COLUMNS]; 3];

/// c11 of Kalker's Table E3 (contact.md, "Kalker coefficients").
#[rustfmt::skip]
const KALKER_C11: KalkerTable = [
    [2.51, 2.59, 2.68, 2.78, 2.88, 2.98, 3.09, 3.19, 3.29, 3.40, 3.51, 3.65, 3.82, 4.06, 4.37, 4.84, 5.57, 6.96, 10.7],
    [3.31, 3.37, 3.44, 3.53, 3.62, 3.72, 3.81, 3.91, 4.01, 4.12, 4.22, 4.36, 4.54, 4.78, 5.10, 5.57, 6.34, 7.78, 11.7],
    [4.85, 4.81, 4.80, 4.82, 4.83, 4.91, 4.97, 5.05, 5.12, 5.20, 5.30, 5.42, 5.58, 5.80, 6.11, 6.57, 7.34, 8.82, 12.9],
];

/// c22 of Kalker's Table E3 (contact.md, "Kalker coefficients").
// The table's 3.14 entries are Kalker's numbers, not an approximation of pi.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
const KALKER_C22: KalkerTable = [
    [2.51, 2.59, 2.68, 2.78, 2.88, 2.98, 3.09, 3.19, 3.29, 3.40, 3.51, 3.65, 3.82, 4.06, 4.37, 4.84, 5.57, 6.96, 10.7],
    [2.52, 2.63, 2.75, 2.88, 3.01, 3.14, 3.28, 3.41, 3.54, 3.67, 3.81, 3.99, 4.21, 4.50, 4.90, 5.48, 6.40, 8.14, 12.8],
    [2.53, 2.66, 2.81, 2.98, 3.14, 3.31, 3.48, 3.65, 3.82, 3.98, 4.16, 4.39, 4.67, 5.04, 5.56, 6.31, 7.51, 9.79, 16.0],
];

/// c23 of Kalker's Table E3 (contact.md, "Kalker coefficients").
#[rustfmt::skip]
const KALKER_C23: KalkerTable = [
    [0.334, 0.483, 0.607, 0.720, 0.827, 0.930, 1.03, 1.13, 1.23, 1.33, 1.44, 1.58, 1.76, 2.01, 2.35, 2.88, 3.79, 5.72, 12.2],
    [0.473, 0.603, 0.715, 0.823, 0.929, 1.03, 1.14, 1.25, 1.36, 1.47, 1.59, 1.75, 1.95, 2.23, 2.62, 3.24, 4.32, 6.63, 14.6],
    [0.731, 0.809, 0.889, 0.977, 1.07, 1.18, 1.29, 1.40, 1.51, 1.63, 1.77, 1.94, 2.18, 2.50, 2.96, 3.70, 5.01, 7.89, 18.0],
];

/// Kalker's coefficients for Poisson's ratio `nu` and semi-axes `a_m` (along
/// x) and `b_m` (along y) (contact.md, "Kalker coefficients c11, c22, c23").
///
/// Column by column, the table is interpolated quadratically (Lagrange) in nu
/// through its rows nu = 0, 0.25, 0.5; the result is then interpolated
/// linearly in a/b when `a <= b` (columns a/b = 0.1 … 1.0) and in b/a when
/// `a > b` (columns b/a = 1.0 … 0.1, the a/b = 1.0 column joining both
/// halves). Outside the table the nearest edge is used: a/b or b/a below 0.1
/// is clamped to 0.1, and nu to [0, 0.5].
///
/// Precondition: `a_m > 0`, `b_m > 0`, finite.
pub fn kalker(nu: f64, a_m: f64, b_m: f64) -> KalkerCoefficients {
    // Position along the 19 columns, 0.0 ..= 18.0 (a/b = 0.1 is 0, a = b is 9,
    // b/a = 0.1 is 18). Columns are 0.1 apart in either ratio.
    let position = if a_m <= b_m {
        let a_over_b = (a_m / b_m).clamp(0.1, 1.0);
        (a_over_b - 0.1) / 0.1
    } else {
        let b_over_a = (b_m / a_m).clamp(0.1, 1.0);
        9.0 + (1.0 - b_over_a) / 0.1
    };
    // `as usize` saturates (NaN -> 0) and `min` keeps `column + 1` in the
    // table, so no input can index out of bounds.
    let column = (position.floor() as usize).min(KALKER_COLUMNS - 2);
    let t = position - column as f64;

    // Lagrange basis through nu = 0, 0.25, 0.5.
    let nu = nu.clamp(0.0, 0.5);
    let l0 = (nu - 0.25) * (nu - 0.5) / ((0.0 - 0.25) * (0.0 - 0.5));
    let l1 = (nu - 0.0) * (nu - 0.5) / ((0.25 - 0.0) * (0.25 - 0.5));
    let l2 = (nu - 0.0) * (nu - 0.25) / ((0.5 - 0.0) * (0.5 - 0.25));

    let interpolate = |table: &KalkerTable| {
        let at_nu = |j: usize| l0 * table[0][j] + l1 * table[1][j] + l2 * table[2][j];
        let (left, right) = (at_nu(column), at_nu(column + 1));
        left + t * (right - left)
    };

    KalkerCoefficients {
        c11: interpolate(&KALKER_C11),
        c22: interpolate(&KALKER_C22),
        c23: interpolate(&KALKER_C23),
    }
}

/// Polach's model parameters (Polach 2005; contact.md, "Polach").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolachParams {
    /// `A` in Polach 2005: the ratio of the friction coefficient at infinite
    /// slip velocity to `mu0` [-].
    pub p_a: f64,
    /// `B` in Polach 2005: the exponential rate of friction decrease with
    /// slip velocity [s/m].
    pub p_b_s_per_m: f64,
    /// Reduction factor kA in the area of adhesion [-].
    pub k_a: f64,
    /// Reduction factor kS in the area of slip [-].
    pub k_s: f64,
}

impl PolachParams {
    /// Polach's dry set, the default (contact.md, "fixed here"):
    /// A = 0.40, B = 0.60 s/m, kA = 1.00, kS = 0.40.
    pub(crate) const DRY: PolachParams = PolachParams {
        p_a: 0.40,
        p_b_s_per_m: 0.60,
        k_a: 1.00,
        k_s: 0.40,
    };
}

impl Default for PolachParams {
    fn default() -> Self {
        PolachParams::DRY
    }
}

/// The state of one rolling contact, as Polach's model takes it
/// (contact.md, "Polach", Inputs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolachInput {
    /// Normal load Q [N].
    pub q_n: f64,
    /// Contact semi-axis along x [m].
    pub a_m: f64,
    /// Contact semi-axis along y [m].
    pub b_m: f64,
    /// Shear modulus G [Pa].
    pub g_pa: f64,
    /// Kalker's coefficients for this contact ellipse.
    pub kalker: KalkerCoefficients,
    /// Longitudinal creepage sx [-], used exactly as recorded.
    pub sx: f64,
    /// Lateral creepage sy [-], used exactly as recorded.
    pub sy: f64,
    /// Spin creepage psi [1/m], used exactly as recorded.
    pub psi_per_m: f64,
    /// Rolling speed V [m/s] (the train's speed).
    pub speed_mps: f64,
    /// Maximum friction coefficient mu0 [-]: the product model's `mu`
    /// (model.md eq. 4).
    pub mu0: f64,
}

/// What Polach's model gives for one contact (contact.md, "Polach").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolachForces {
    /// `mu_w`: the friction coefficient at this slip velocity [-] (step 2).
    pub mu_slip: f64,
    /// Gradient of tangential stress in the area of adhesion, ε [-] (step 3).
    pub eps: f64,
    /// The same for spin, ε_M [-] (step 5).
    pub eps_m: f64,
    /// Longitudinal creep force Fx [N] (step 4).
    pub fx_n: f64,
    /// Total lateral creep force Fy, including the spin term F_yS [N] (step 5).
    pub fy_n: f64,
    /// Coefficient of adhesion `T/N = hypot(Fx, Fy) / Q` [-] (step 6).
    pub t_over_q: f64,
}

/// Polach's creep forces of one contact (Polach 1999 with the spin
/// extension, Polach 2005 reduction factors; contact.md, "Polach", steps 1–6).
///
/// 1. The creepage that slides is `s_C = hypot(sx, s_yC)`, where spin adds to
///    the lateral creepage only when it increases it:
///    `s_yC = sy + psi a` if `|sy + psi a| > |sy|`, else `sy`. At `s_C = 0`
///    nothing slides and there is no force (`mu_slip = mu0`, `eps = eps_M = 0`).
/// 2. Friction falls with the slip velocity `w = V s_C`:
///    `mu_w = mu0 ((1 - A) exp(-B w) + A)`.
/// 3. The stress gradient in the adhesion area:
///    `eps = G pi a b c_jj s_C / (4 Q mu_w)` with
///    `c_jj = hypot(c11 sx/s, c22 sy/s)`, `s = hypot(sx, sy)` (0 when s = 0).
/// 4. The creep force, reduced by kA in adhesion and kS in slip (Polach 2005):
///    `F = 2 Q mu_w / pi (kA eps / (1 + (kA eps)^2) + atan(kS eps))`, split
///    along the creepages: `Fx = F sx / s_C`, `Fy = F sy / s_C`.
/// 5. Spin adds a lateral force: `k_spin = 1 + 6.3 (1 - exp(-a/b))`,
///    `eps_M = (8/3) G b sqrt(a b) c23 |s_yC| / (Q mu_w k_spin)`,
///    `delta = (eps_M^2 - 1)/(eps_M^2 + 1)`,
///    `K_M = |eps_M| (delta^3/3 - delta^2/2 + 1/6) - sqrt((1 - delta^2)^3)/3`,
///    `F_yS = -(9/16) a Q mu_w K_M k_spin psi / s_C`; `Fy_total = Fy + F_yS`.
/// 6. `T/N = hypot(Fx, Fy_total) / Q`. Signs come only from the creepages as
///    recorded, for either direction of travel.
///
/// Precondition: `q_n > 0`, `a_m > 0`, `b_m > 0`, `g_pa > 0`, `mu0 > 0`, all
/// finite. A contact without friction (`mu_w = 0`) transmits no force and is
/// returned as such instead of dividing by zero.
pub fn polach(input: &PolachInput, params: &PolachParams) -> PolachForces {
    PolachContact::new(input, params).forces(input.mu0)
}

/// [`polach`] for one contact whose `mu0` varies: what does not depend on
/// `mu0` computed once (the engine takes a wheel's adhesion at every grid
/// point of a snapshot, each point with its own mu). [`PolachContact::forces`]
/// runs the same operations in the same order as the steps above, so the
/// forces are those of [`polach`] bit for bit ([`polach`] is this).
#[derive(Debug, Clone, Copy)]
pub struct PolachContact {
    q_n: f64,
    sx: f64,
    sy: f64,
    psi_per_m: f64,
    s_c: f64,
    /// Step 2: `(1 - pA) exp(-pB w) + pA`, mu_w over mu0.
    slip_factor: f64,
    /// Step 3: `G pi a b c_jj s_C` and `4 Q`.
    eps_numerator: f64,
    four_q: f64,
    /// Step 4: `2 Q`, kA and kS.
    two_q: f64,
    k_a: f64,
    k_s: f64,
    /// Step 5: `k_spin`, `(8/3) G b sqrt(a b) c23 |s_yC|` and `-(9/16) a Q`.
    k_spin: f64,
    eps_m_numerator: f64,
    spin_force_factor: f64,
}

impl PolachContact {
    /// Steps 1 to 5 as far as they do not need `mu0` (`input.mu0` unused).
    pub fn new(input: &PolachInput, params: &PolachParams) -> Self {
        let PolachInput {
            q_n,
            a_m,
            b_m,
            g_pa,
            kalker,
            sx,
            sy,
            psi_per_m,
            speed_mps,
            mu0: _,
        } = *input;

        // Step 1: the sliding creepage, with spin where it adds to sy.
        let s = sx.hypot(sy);
        let sy_spin = sy + psi_per_m * a_m;
        let s_yc = if sy_spin.abs() > sy.abs() {
            sy_spin
        } else {
            sy
        };
        let s_c = sx.hypot(s_yc);

        // Step 2: friction at the slip velocity, over mu0.
        let w_mps = speed_mps * s_c;
        let slip_factor = (1.0 - params.p_a) * (-params.p_b_s_per_m * w_mps).exp() + params.p_a;

        // Step 3: the gradient of tangential stress in the area of adhesion.
        let c_jj = if s == 0.0 {
            0.0
        } else {
            (kalker.c11 * sx / s).hypot(kalker.c22 * sy / s)
        };

        Self {
            q_n,
            sx,
            sy,
            psi_per_m,
            s_c,
            slip_factor,
            eps_numerator: g_pa * PI * a_m * b_m * c_jj * s_c,
            four_q: 4.0 * q_n,
            two_q: 2.0 * q_n,
            k_a: params.k_a,
            k_s: params.k_s,
            k_spin: 1.0 + 6.3 * (1.0 - (-a_m / b_m).exp()),
            eps_m_numerator: 8.0 / 3.0 * g_pa * b_m * (a_m * b_m).sqrt() * kalker.c23 * s_yc.abs(),
            spin_force_factor: -9.0 / 16.0 * a_m * q_n,
        }
    }

    /// The forces at `mu0`: steps 2 to 6.
    pub fn forces(&self, mu0: f64) -> PolachForces {
        let Self {
            q_n,
            sx,
            sy,
            psi_per_m,
            s_c,
            slip_factor,
            eps_numerator,
            four_q,
            two_q,
            k_a,
            k_s,
            k_spin,
            eps_m_numerator,
            spin_force_factor,
        } = *self;

        // Step 2.
        let mu_slip = mu0 * slip_factor;

        if s_c == 0.0 || mu_slip == 0.0 {
            return PolachForces {
                mu_slip,
                eps: 0.0,
                eps_m: 0.0,
                fx_n: 0.0,
                fy_n: 0.0,
                t_over_q: 0.0,
            };
        }

        // Step 3.
        let eps = eps_numerator / (four_q * mu_slip);

        // Step 4: the creep force of longitudinal and lateral creepage.
        let ka_eps = k_a * eps;
        let f_n = two_q * mu_slip / PI * (ka_eps / (1.0 + ka_eps * ka_eps) + (k_s * eps).atan());
        let fx_n = f_n * sx / s_c;
        let fy_n = f_n * sy / s_c;

        // Step 5: the lateral force of spin.
        let eps_m = eps_m_numerator / (q_n * mu_slip * k_spin);
        // delta = (eps_M^2 - 1)/(eps_M^2 + 1) enters K_M only through 1 - delta
        // and 1 + delta, and the cubic factors as
        //   delta^3/3 - delta^2/2 + 1/6 = (1 - delta)^2 (1 + 2 delta) / 6,
        // so K_M is evaluated in that form: identical to step 5, but it keeps
        // its precision as delta -> 1 (large spin) instead of cancelling, and
        // eps_M^2 overflowing to infinity gives the limit K_M = 0, not NaN.
        let one_minus_delta = 2.0 / (eps_m * eps_m + 1.0);
        let one_plus_delta = 2.0 - one_minus_delta;
        let one_plus_two_delta = 3.0 - 2.0 * one_minus_delta;
        let k_m = eps_m.abs() * one_minus_delta * one_minus_delta * one_plus_two_delta / 6.0
            - (one_minus_delta * one_plus_delta).powi(3).sqrt() / 3.0;
        let fy_spin_n = spin_force_factor * mu_slip * k_m * k_spin * psi_per_m / s_c;
        let fy_total_n = fy_n + fy_spin_n;

        // Step 6: the coefficient of adhesion.
        PolachForces {
            mu_slip,
            eps,
            eps_m,
            fx_n,
            fy_n: fy_total_n,
            t_over_q: fx_n.hypot(fy_total_n) / q_n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Polach's input for the worked contact of contact.md (a 0.92 m wheel,
    /// 100 kN on a rail head of R_ry = 0.30 m, the default steel) at 20 m/s.
    fn worked(cx: f64, cy: f64, spin_per_m: f64, mu0: f64) -> PolachInput {
        let steel = Steel::DEFAULT;
        let h = hertz(100e3, 0.46, f64::INFINITY, 0.30, &steel);
        PolachInput {
            q_n: 100e3,
            a_m: h.a_m,
            b_m: h.b_m,
            g_pa: steel.g_pa(),
            kalker: kalker(steel.nu, h.a_m, h.b_m),
            sx: cx,
            sy: cy,
            psi_per_m: spin_per_m,
            speed_mps: 20.0,
            mu0,
        }
    }

    /// `got` rounds to `printed`, which the spec prints with `decimals`
    /// decimals (contact.md: "rounded to 6 digits").
    fn assert_rounds_to(what: &str, got: f64, printed: f64, decimals: i32) {
        let half_unit = 0.5 * 10f64.powi(-decimals);
        assert!(
            (got - printed).abs() <= half_unit * (1.0 + 1e-9),
            "{what}: got {got}, the spec prints {printed}"
        );
    }

    /// contact.md, "Hertz", worked example: Q = 100 kN, R_wx = 0.46 m,
    /// R_ry = 0.30 m, flat wheel profile.
    #[test]
    fn hertz_worked_example() {
        let h = hertz(100e3, 0.46, f64::INFINITY, 0.30, &Steel::DEFAULT);
        assert_rounds_to("a [mm]", h.a_m * 1e3, 7.16168, 5);
        assert_rounds_to("b [mm]", h.b_m * 1e3, 5.38717, 5);
        assert_rounds_to("p0 [MPa]", h.p0_pa * 1e-6, 1237.56, 2);
        assert_rounds_to("pm [MPa]", h.pm_pa * 1e-6, 825.04, 2);
    }

    /// contact.md, "Kalker", worked example: nu = 0.3 on the worked ellipse.
    #[test]
    fn kalker_worked_example() {
        let h = hertz(100e3, 0.46, f64::INFINITY, 0.30, &Steel::DEFAULT);
        let k = kalker(0.3, h.a_m, h.b_m);
        assert_rounds_to("c11", k.c11, 4.62924, 5);
        assert_rounds_to("c22", k.c22, 4.17566, 5);
        assert_rounds_to("c23", k.c23, 1.88501, 5);
    }

    /// contact.md, "Polach", golden values: T/Q at six longitudinal creepages.
    #[test]
    fn polach_worked_example() {
        let cases = [
            (0.001, 0.097936),
            (0.002, 0.179978),
            (0.005, 0.304936),
            (0.01, 0.358854),
            (0.02, 0.392848),
            (0.05, 0.374360),
        ];
        for (cx, t_over_q) in cases {
            let got = polach(&worked(cx, 0.0, 0.0, 0.55), &PolachParams::DRY).t_over_q;
            assert_rounds_to(&format!("T/Q at cx = {cx}"), got, t_over_q, 6);
        }
    }

    /// K(m) and E(m) at m = e^2 = 1/2 (Abramowitz & Stegun, Table 17.1).
    #[test]
    fn elliptic_integrals_at_half() {
        let half = EllipticIntegrals::new(0.5_f64.sqrt());
        assert!((half.k_int - 1.854_074_677_301_372).abs() < 1e-15);
        let e_int = half.k_int * (1.0 - half.sum());
        assert!((e_int - 1.350_643_881_047_675).abs() < 1e-15);
        assert!((half.k_minus_e() - (half.k_int - e_int)).abs() < 1e-15);
        // The circle: K = E = pi/2.
        let circle = EllipticIntegrals::new(1.0);
        assert_eq!((circle.k_int, circle.k_minus_e()), (PI / 2.0, 0.0));
    }

    /// Swapping the curvatures turns the ellipse by 90 degrees, and the
    /// elliptical solution meets the circular one as the curvatures meet.
    #[test]
    fn hertz_symmetry_and_circular_limit() {
        let steel = Steel::DEFAULT;
        // Ax = 1/(2*0.46), By = 1/(2*0.30) and the reverse.
        let h = hertz(100e3, 0.46, f64::INFINITY, 0.30, &steel);
        let turned = hertz(100e3, 0.30, f64::INFINITY, 0.46, &steel);
        assert!((h.a_m - turned.b_m).abs() <= 1e-15 && (h.b_m - turned.a_m).abs() <= 1e-15);

        let circle = hertz(100e3, 0.46, f64::INFINITY, 0.46, &steel);
        assert_eq!(circle.a_m, circle.b_m);
        // A relative change d of one radius moves the semi-axes by O(d); the
        // bisection must resolve that even at d = 1e-12 (E/k^2 - K taken
        // literally would lose ~8 digits here).
        for d in [1e-6, 1e-9, 1e-12] {
            for r_ry_m in [0.46 * (1.0 + d), 0.46 * (1.0 - d)] {
                let near = hertz(100e3, 0.46, f64::INFINITY, r_ry_m, &steel);
                assert!((near.a_m / circle.a_m - 1.0).abs() < d, "{d}: {near:?}");
                assert!((near.b_m / circle.b_m - 1.0).abs() < d, "{d}: {near:?}");
            }
        }
    }

    /// Nothing slides, nothing is transmitted (contact.md, Polach step 1).
    #[test]
    fn no_creepage_no_force() {
        let f = polach(&worked(0.0, 0.0, 0.0, 0.55), &PolachParams::DRY);
        assert_eq!(
            (f.fx_n, f.fy_n, f.t_over_q, f.eps, f.eps_m),
            (0.0, 0.0, 0.0, 0.0, 0.0)
        );
        assert_eq!(f.mu_slip, 0.55);
    }

    /// Extreme but finite inputs return without panicking and without NaN
    /// where the physics has a limit.
    #[test]
    fn extreme_inputs_stay_finite() {
        let steel = Steel::DEFAULT;
        let slender = hertz(100e3, 0.46, f64::INFINITY, 1e-6, &steel);
        assert!(slender.a_m.is_finite() && slender.b_m > 0.0 && slender.a_m > slender.b_m);
        let k = kalker(0.3, slender.a_m, slender.b_m);
        assert_eq!(k, kalker(0.3, 1.0, 0.1 * 0.999));

        for (cx, cy, spin) in [(1e3, -1e3, 1e6), (0.0, 0.0, 1e300), (-1e-300, 0.0, 0.0)] {
            let t = polach(&worked(cx, cy, spin, 0.4), &PolachParams::DRY).t_over_q;
            assert!(t.is_finite() && t >= 0.0, "{cx} {cy} {spin}: {t}");
        }
        assert_eq!(
            polach(&worked(0.01, 0.0, 0.0, 0.0), &PolachParams::DRY).t_over_q,
            0.0
        );
    }
}
