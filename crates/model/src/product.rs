//! Product transport on the wheel and rail surfaces: consumption, friction
//! and transfer, after Trummer, Lee, Lewis and Six, "Modelling of Frictional
//! Conditions in the Wheel–Rail Interface Due to Application of Top-of-Rail
//! Products", Lubricants 2021, 9, 100. Equation numbers are the paper's; the
//! choices the paper leaves open are fixed by docs/spec/model.md.
//!
//! Masses are in kg. Everything here is a pure function of its arguments:
//! the engine decides which contact happens when, this module says what a
//! contact does.

use serde::{Deserialize, Serialize};

/// The reference mean contact pressure of eq. (2): 1178 MPa.
pub(crate) const PM_REF_PA: f64 = 1178e6;
/// The reference creepage of eq. (3): 1 %.
pub(crate) const CREEPAGE_REF: f64 = 0.01;
/// The largest transfer fraction: equal shares (model.md).
pub(crate) const TRANSFER_FRACTION_MAX: f64 = 0.5;

/// The product model's parameters: Table 2 of the paper plus the cap.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProductParams {
    /// k0, eq. (1): consumption per contact that does not depend on the mass.
    pub k0_kg: f64,
    /// km1, eq. (1): consumption per contact when product is abundant.
    pub km1_kg: f64,
    /// km2, eq. (1): the mass (in units of m0) below which consumption slows.
    pub km2: f64,
    /// m0, eq. (1): the product mass applied at the application site, a
    /// constant of the product and the site (model.md; not in Table 2). It
    /// does not follow the recorded pulses. 0 makes the saturation term 1.
    pub m0_kg: f64,
    /// kp, eq. (2).
    pub kp: f64,
    /// kc, eq. (3).
    pub kc: f64,
    /// muD, eq. (4): dry and clean.
    pub mu_d: f64,
    /// muC, eq. (4): surplus product.
    pub mu_c: f64,
    /// km, eq. (4).
    pub km_kg: f64,
    /// kt, eq. (6): pick-up efficiency.
    pub kt: f64,
    /// cm, eq. (6).
    pub cm_kg: f64,
    /// cN, eq. (6).
    pub cn: f64,
    /// m_max: what one surface holds at one grid point; the excess is
    /// squeezed out (model.md).
    pub m_max_kg: f64,
}

/// One constant of [`ProductParams`] by name: the `[product]` keys of the
/// configuration, the constants a site calibration examines
/// (docs/spec/interfaces.md, "Site constants").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ProductKey {
    MuD,
    MuC,
    KmKg,
    Kc,
    Kt,
    Cn,
    K0Kg,
    Km1Kg,
    M0Kg,
    Km2,
    Kp,
    CmKg,
    MMaxKg,
}

impl ProductKey {
    /// Every constant: the friction levels first, then pick-up and
    /// transfer, consumption, and the cap (the order reports list them in).
    pub const ALL: [ProductKey; 13] = [
        ProductKey::MuD,
        ProductKey::MuC,
        ProductKey::KmKg,
        ProductKey::Kc,
        ProductKey::Kt,
        ProductKey::Cn,
        ProductKey::K0Kg,
        ProductKey::Km1Kg,
        ProductKey::M0Kg,
        ProductKey::Km2,
        ProductKey::Kp,
        ProductKey::CmKg,
        ProductKey::MMaxKg,
    ];

    /// The key under `[product]`, e.g. `mu_d`.
    pub fn name(self) -> &'static str {
        match self {
            ProductKey::MuD => "mu_d",
            ProductKey::MuC => "mu_c",
            ProductKey::KmKg => "km_kg",
            ProductKey::Kc => "kc",
            ProductKey::Kt => "kt",
            ProductKey::Cn => "cn",
            ProductKey::K0Kg => "k0_kg",
            ProductKey::Km1Kg => "km1_kg",
            ProductKey::M0Kg => "m0_kg",
            ProductKey::Km2 => "km2",
            ProductKey::Kp => "kp",
            ProductKey::CmKg => "cm_kg",
            ProductKey::MMaxKg => "m_max_kg",
        }
    }

    /// What it sets, for people.
    pub fn what(self) -> &'static str {
        match self {
            ProductKey::MuD => "friction of dry, clean rail (eq. 4)",
            ProductKey::MuC => "friction with surplus product (eq. 4)",
            ProductKey::KmKg => "mass scale of the friction decay (eq. 4)",
            ProductKey::Kc => "creepage sensitivity of consumption (eq. 3)",
            ProductKey::Kt => "pick-up efficiency of the transfer (eq. 6)",
            ProductKey::Cn => "wheel revolutions scale of the transfer (eq. 6)",
            ProductKey::K0Kg => "consumption per contact at no product (eq. 1)",
            ProductKey::Km1Kg => "mass-dependent consumption per contact (eq. 1)",
            ProductKey::M0Kg => "product mass applied at the site, m0 (eq. 1)",
            ProductKey::Km2 => "mass scale of consumption in units of m0 (eq. 1)",
            ProductKey::Kp => "pressure sensitivity of consumption (eq. 2)",
            ProductKey::CmKg => "mass scale of the transfer (eq. 6)",
            ProductKey::MMaxKg => "what one surface holds at one grid point (the cap)",
        }
    }

    /// Its value in `params`.
    pub fn get(self, p: &ProductParams) -> f64 {
        *self.slot(&mut p.clone())
    }

    /// Sets its value in `params`.
    pub fn set(self, p: &mut ProductParams, value: f64) {
        *self.slot(p) = value;
    }

    fn slot(self, p: &mut ProductParams) -> &mut f64 {
        match self {
            ProductKey::MuD => &mut p.mu_d,
            ProductKey::MuC => &mut p.mu_c,
            ProductKey::KmKg => &mut p.km_kg,
            ProductKey::Kc => &mut p.kc,
            ProductKey::Kt => &mut p.kt,
            ProductKey::Cn => &mut p.cn,
            ProductKey::K0Kg => &mut p.k0_kg,
            ProductKey::Km1Kg => &mut p.km1_kg,
            ProductKey::M0Kg => &mut p.m0_kg,
            ProductKey::Km2 => &mut p.km2,
            ProductKey::Kp => &mut p.kp,
            ProductKey::CmKg => &mut p.cm_kg,
            ProductKey::MMaxKg => &mut p.m_max_kg,
        }
    }
}

/// Eq. (2): the influence of the mean Hertz pressure on consumption,
/// `fp = max(0, 1 + kp (pm / 1178 MPa - 1))`. The clamp at 0 is fixed by
/// model.md: below about 537 MPa the paper's linear law would turn negative
/// and make consumption create product.
#[inline]
pub fn pressure_factor(params: &ProductParams, pm_pa: f64) -> f64 {
    (1.0 + params.kp * (pm_pa / PM_REF_PA - 1.0)).max(0.0)
}

/// Eq. (3): the influence of the creepage on consumption,
/// `fc = max(0, 1 + kc (sqrt(cx² + cy²) / 0.01 - 1))`. Spin does not enter.
#[inline]
pub fn creepage_factor(params: &ProductParams, cx: f64, cy: f64) -> f64 {
    (1.0 + params.kc * ((cx * cx + cy * cy).sqrt() / CREEPAGE_REF - 1.0)).max(0.0)
}

/// Eq. (1): the mass consumed by one contact,
/// `c = k0 + km1 (1 - exp(-m / (m0 km2))) fp fc`, never more than `m`.
///
/// - `m_kg`: the total mass in the contact, wheel plus rail (model.md).
/// - `m0` is `params.m0_kg`, the same for every contact; with `m0 = 0` the
///   saturation term is 1.
/// - `fp_fc`: eq. (2) times eq. (3) for this wheel on this rail.
/// - `factor`: an effect's multiplier of the whole `c` (1 without one),
///   applied before the limit `c <= m` (effects.md, temperature_consumption).
#[inline]
pub fn consumption(params: &ProductParams, m_kg: f64, fp_fc: f64, factor: f64) -> f64 {
    consumption_given(params, m_kg, fp_fc, factor, |arg| arg.exp())
}

/// The argument of eq. (1)'s exponential, `-m / (m0 km2)`. Multiplying by
/// the reciprocal keeps the division off the wheel mass's dependency chain
/// in the stepping loop (it depends only on the constants m0 and km2, so
/// the compiler hoists it); the result differs from the literal quotient
/// by at most an ulp.
#[inline(always)]
fn saturation_arg(params: &ProductParams, m_kg: f64) -> f64 {
    -m_kg * (1.0 / (params.m0_kg * params.km2))
}

/// [`consumption`] with its exponential taken by `exp` (of
/// [`saturation_arg`], asked only when `m0 > 0`).
#[inline(always)]
fn consumption_given(
    params: &ProductParams,
    m_kg: f64,
    fp_fc: f64,
    factor: f64,
    exp: impl FnOnce(f64) -> f64,
) -> f64 {
    let saturation = if params.m0_kg > 0.0 {
        1.0 - exp(saturation_arg(params, m_kg))
    } else {
        1.0
    };
    // Grouped so that only one multiply and one add wait for the mass:
    // `(k0 + km1 s fp fc) factor = k0 factor + (km1 fp fc factor) s`.
    (params.k0_kg * factor + (params.km1_kg * fp_fc * factor) * saturation).min(m_kg)
}

/// Eq. (4): the friction coefficient of a contact holding `m_kg` of product,
/// `mu = muC + (muD - muC) exp(-m / km)`.
#[inline]
pub fn friction(params: &ProductParams, m_kg: f64) -> f64 {
    params.mu_c + (params.mu_d - params.mu_c) * (-m_kg / params.km_kg).exp()
}

/// The part of eq. (6) that depends only on the wheel's distance from its
/// applicator: `exp(-(N - 1) / cN)`, with `N = |i - i_app| + 1` (model.md).
/// The engine tabulates it once per grid distance.
#[inline]
pub fn revolution_factor(params: &ProductParams, n: u32) -> f64 {
    (-(f64::from(n) - 1.0) / params.cn).exp()
}

/// Eq. (6): the transfer fraction for a donor holding `m1_kg`,
/// `t = kt (1 - exp(-m1 / cm)) exp(-(N - 1) / cN)`, times an effect's
/// `factor` (1 without one), clamped to at most 0.5 (equal shares; model.md).
/// `revolution` is [`revolution_factor`] for this N.
#[inline]
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) fn transfer_fraction(
    params: &ProductParams,
    m1_kg: f64,
    revolution: f64,
    factor: f64,
) -> f64 {
    transfer_fraction_given(
        params,
        transfer_arg(params, m1_kg).exp(),
        revolution,
        factor,
    )
}

/// The argument of eq. (6)'s exponential, `-m1 / cm` (`1 / cm` is a
/// constant the compiler hoists out of the stepping loop).
#[inline(always)]
fn transfer_arg(params: &ProductParams, m1_kg: f64) -> f64 {
    -m1_kg * (1.0 / params.cm_kg)
}

/// [`transfer_fraction`] with `e = exp(-m1 / cm)` given.
#[inline(always)]
fn transfer_fraction_given(params: &ProductParams, e: f64, revolution: f64, factor: f64) -> f64 {
    let t = params.kt * (1.0 - e) * revolution;
    (t * factor).min(TRANSFER_FRACTION_MAX)
}

/// Eq. (5): the surface with more product (the donor, `m1`) gives
/// `t (m1 - m2)` to the other; equal masses exchange nothing. Returns the
/// new `(wheel, rail)` masses. `fraction_of` gives `t` for the donor's mass.
pub(crate) fn transfer(
    wheel_kg: f64,
    rail_kg: f64,
    fraction_of: impl FnOnce(f64) -> f64,
) -> (f64, f64) {
    if wheel_kg > rail_kg {
        let moved = fraction_of(wheel_kg) * (wheel_kg - rail_kg);
        (wheel_kg - moved, rail_kg + moved)
    } else if rail_kg > wheel_kg {
        let moved = fraction_of(rail_kg) * (rail_kg - wheel_kg);
        (wheel_kg + moved, rail_kg - moved)
    } else {
        (wheel_kg, rail_kg)
    }
}

/// What one contact needs to know besides the two masses: everything here
/// depends on the wheel, its applicator and the grid point, not on the masses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactConditions {
    /// fp · fc of eq. (2) and (3).
    pub fp_fc: f64,
    /// `exp(-(N - 1) / cN)` times any effect factor of the transfer, or
    /// `None` before the wheel has passed an applicator (no transfer).
    pub transfer_revolution: Option<f64>,
    /// Multiplier of the consumption (temperature_consumption), else 1.
    pub consumption_factor: f64,
}

/// Where the mass of one contact went, in kg (for the mass balance).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactLosses {
    pub consumed_kg: f64,
    pub capped_kg: f64,
}

/// Steps 3 to 5 of "one contact" (model.md) on the wheel and rail masses:
/// transfer (eq. 5, 6), consumption (eq. 1) with the total mass `m` from
/// before the transfer, both surfaces scaled by `(m - c) / m`, then the cap
/// at `m_max` on each surface. Steps 1, 2 and 6 belong to the engine (time
/// and wheel effects, and what is observed).
#[inline]
pub fn roll(
    params: &ProductParams,
    wheel_kg: &mut f64,
    rail_kg: &mut f64,
    conditions: &ContactConditions,
) -> ContactLosses {
    roll_core(
        params,
        wheel_kg,
        rail_kg,
        conditions,
        |arg| arg.exp(),
        |arg| arg.exp(),
    )
}

/// The arguments of the two exponentials [`roll`] may take, from the masses
/// before the contact: eq. (6)'s `-m1 / cm` (m1 the larger mass, the donor)
/// and eq. (1)'s `-m / (m0 km2)`. For a caller that takes the exponentials
/// of several contacts at once and hands them to [`roll_given`].
#[inline(always)]
pub fn roll_exp_args(params: &ProductParams, wheel_kg: f64, rail_kg: f64) -> [f64; 2] {
    [
        transfer_arg(params, wheel_kg.max(rail_kg)),
        saturation_arg(params, wheel_kg + rail_kg),
    ]
}

/// [`roll`] with its exponentials given: `exps` is `exp` of
/// [`roll_exp_args`] for the same masses. The same operations in the same
/// order, so the same bits as [`roll`] wherever `exp` is the same.
#[inline(always)]
pub fn roll_given(
    params: &ProductParams,
    wheel_kg: &mut f64,
    rail_kg: &mut f64,
    conditions: &ContactConditions,
    exps: [f64; 2],
) -> ContactLosses {
    roll_core(
        params,
        wheel_kg,
        rail_kg,
        conditions,
        |_| exps[0],
        |_| exps[1],
    )
}

/// Steps 3 to 5, the exponentials of eq. (6) and eq. (1) taken by
/// `transfer_exp` and `consumption_exp` (each given its argument).
#[inline(always)]
fn roll_core(
    params: &ProductParams,
    wheel_kg: &mut f64,
    rail_kg: &mut f64,
    conditions: &ContactConditions,
    transfer_exp: impl FnOnce(f64) -> f64,
    consumption_exp: impl FnOnce(f64) -> f64,
) -> ContactLosses {
    let m = *wheel_kg + *rail_kg;
    let mut losses = ContactLosses::default();
    if m > 0.0 {
        // Computed while the exponentials run, instead of dividing at the end.
        let per_m = 1.0 / m;
        if let Some(revolution) = conditions.transfer_revolution {
            (*wheel_kg, *rail_kg) = transfer(*wheel_kg, *rail_kg, |m1| {
                transfer_fraction_given(
                    params,
                    transfer_exp(transfer_arg(params, m1)),
                    revolution,
                    1.0,
                )
            });
        }
        let c = consumption_given(
            params,
            m,
            conditions.fp_fc,
            conditions.consumption_factor,
            consumption_exp,
        );
        // A subnormal m (below 2.2e-308 kg, left by ageing over years) has
        // no finite reciprocal: divide instead (0 * inf would be NaN).
        let f = if per_m.is_finite() {
            (m - c) * per_m
        } else {
            (m - c) / m
        };
        let before = *wheel_kg + *rail_kg;
        *wheel_kg *= f;
        *rail_kg *= f;
        // The consumed mass is what the scaling removed, so that the mass
        // balance closes to rounding.
        losses.consumed_kg = before - (*wheel_kg + *rail_kg);
    }
    losses.capped_kg = cap(params, wheel_kg) + cap(params, rail_kg);
    losses
}

/// [`roll_given`] for four contacts at once (four wheels' lanes of the
/// stepping kernel, each with its own masses, conditions and
/// exponentials): returns the new wheel and rail masses and each lane's
/// losses. Lane by lane here; [`roll_given4_avx`] computes the same bits in
/// vector registers.
#[inline(always)]
fn roll_given4(
    params: &ProductParams,
    masses: ([f64; 4], [f64; 4]),
    conditions: &[ContactConditions; 4],
    exps: ([f64; 4], [f64; 4]),
) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
    let (mut wheel, mut rail) = masses;
    let losses = std::array::from_fn(|j| {
        roll_given(
            params,
            &mut wheel[j],
            &mut rail[j],
            &conditions[j],
            [exps.0[j], exps.1[j]],
        )
    });
    (wheel, rail, losses)
}

/// [`roll_given4`] in AVX registers: every lane's operations are
/// [`roll_core`]'s, in its order and without fused multiply-adds (so the
/// same correctly rounded results); its branches (a positive total mass,
/// a transfer, which surface gives, the cap, a subnormal total) become
/// lane masks that choose between results computed for both sides. No
/// branch depends on the masses, so none is mispredicted where the donor
/// changes from point to point.
///
/// To be inlined into a caller compiled for AVX
/// (`#[target_feature(enable = "avx")]`), as [`crate::exp::exp4_inline`].
///
/// # Safety
/// The CPU must have AVX.
#[cfg(all(target_arch = "x86_64", test))]
#[inline(always)]
unsafe fn roll_given4_avx(
    params: &ProductParams,
    masses: ([f64; 4], [f64; 4]),
    conditions: &[ContactConditions; 4],
    exps: ([f64; 4], [f64; 4]),
) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
    use std::arch::x86_64::_mm256_loadu_pd;
    let conditions = Conditions4::of(conditions);
    let rolled = roll_given4_register(
        params,
        (
            _mm256_loadu_pd(masses.0.as_ptr()),
            _mm256_loadu_pd(masses.1.as_ptr()),
        ),
        &conditions,
        (
            _mm256_loadu_pd(exps.0.as_ptr()),
            _mm256_loadu_pd(exps.1.as_ptr()),
        ),
    );
    rolled.arrays()
}

/// Four lanes' [`ContactConditions`] in AVX registers.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub struct Conditions4 {
    /// All bits set in a lane whose `transfer_revolution` is `Some`, else 0.
    pub transfers: std::arch::x86_64::__m256d,
    /// `transfer_revolution`, 0 where `None`.
    pub revolution: std::arch::x86_64::__m256d,
    /// `consumption_factor`.
    pub factor: std::arch::x86_64::__m256d,
    /// `fp_fc`.
    pub fp_fc: std::arch::x86_64::__m256d,
}

#[cfg(target_arch = "x86_64")]
impl Conditions4 {
    /// The four lanes' conditions gathered into registers.
    ///
    /// # Safety
    /// The CPU must have AVX.
    #[inline(always)]
    pub unsafe fn of(conditions: &[ContactConditions; 4]) -> Self {
        use std::arch::x86_64::*;
        macro_rules! lanes {
            (|$c:ident| $e:expr) => {{
                let [c0, c1, c2, c3] = conditions;
                _mm256_setr_pd(
                    {
                        let $c = c0;
                        $e
                    },
                    {
                        let $c = c1;
                        $e
                    },
                    {
                        let $c = c2;
                        $e
                    },
                    {
                        let $c = c3;
                        $e
                    },
                )
            }};
        }
        Self {
            transfers: lanes!(|c| if c.transfer_revolution.is_some() {
                f64::from_bits(u64::MAX)
            } else {
                0.0
            }),
            revolution: lanes!(|c| c.transfer_revolution.unwrap_or(0.0)),
            factor: lanes!(|c| c.consumption_factor),
            fp_fc: lanes!(|c| c.fp_fc),
        }
    }
}

/// What [`roll_given4_register`] leaves: the four lanes' new wheel and rail
/// masses and their losses, in AVX registers.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub struct Rolled4 {
    pub wheel: std::arch::x86_64::__m256d,
    pub rail: std::arch::x86_64::__m256d,
    pub consumed: std::arch::x86_64::__m256d,
    pub capped: std::arch::x86_64::__m256d,
}

#[cfg(target_arch = "x86_64")]
impl Rolled4 {
    /// The registers as arrays, the losses per lane.
    ///
    /// # Safety
    /// The CPU must have AVX.
    #[inline(always)]
    unsafe fn arrays(self) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
        use std::arch::x86_64::*;
        // Macros, not closures: a closure is not compiled for AVX and may be
        // left out of line (see the engine's `touches4`).
        macro_rules! store {
            ($v:expr) => {{
                let mut a = [0.0; 4];
                _mm256_storeu_pd(a.as_mut_ptr(), $v);
                a
            }};
        }
        let (consumed, capped) = (store!(self.consumed), store!(self.capped));
        macro_rules! losses {
            ($j:literal) => {
                ContactLosses {
                    consumed_kg: consumed[$j],
                    capped_kg: capped[$j],
                }
            };
        }
        let losses = [losses!(0), losses!(1), losses!(2), losses!(3)];
        (store!(self.wheel), store!(self.rail), losses)
    }
}

/// [`roll_given4_avx`] on registers: the masses `(w0, r0)`, the conditions
/// and the exponentials given in registers, the results left in them.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn roll_given4_register(
    params: &ProductParams,
    (w0, r0): (std::arch::x86_64::__m256d, std::arch::x86_64::__m256d),
    conditions: &Conditions4,
    exps: (std::arch::x86_64::__m256d, std::arch::x86_64::__m256d),
) -> Rolled4 {
    use std::arch::x86_64::*;
    // Macros, not closures: a closure is not compiled for AVX and may be
    // left out of line (see the engine's `touches4`).
    macro_rules! splat {
        ($x:expr) => {
            _mm256_set1_pd($x)
        };
    }
    // $a where $mask, else $b.
    macro_rules! pick {
        ($mask:expr, $a:expr, $b:expr $(,)?) => {
            _mm256_blendv_pd($b, $a, $mask)
        };
    }
    let m = _mm256_add_pd(w0, r0);
    let positive = _mm256_cmp_pd::<_CMP_GT_OQ>(m, _mm256_setzero_pd());
    let per_m = _mm256_div_pd(splat!(1.0), m);
    // Transfer (eq. 5, 6) where the wheel has passed an applicator.
    let Conditions4 {
        transfers,
        revolution,
        factor,
        fp_fc,
    } = *conditions;
    let t = _mm256_mul_pd(
        _mm256_mul_pd(splat!(params.kt), _mm256_sub_pd(splat!(1.0), exps.0)),
        revolution,
    );
    // (t * 1.0).min(0.5): min_pd gives its second operand where t is NaN,
    // as f64::min does.
    let fraction = _mm256_min_pd(_mm256_mul_pd(t, splat!(1.0)), splat!(TRANSFER_FRACTION_MAX));
    // [`transfer`]'s three cases in one: where the rail gives, its
    // `fraction (r - w)` is exactly `-(fraction (w - r))` (negation commutes
    // with rounding), so `w + moved` there is `w - fraction (w - r)`, bit for
    // bit; where the masses are equal, `fraction (w - r)` is zero (fraction is
    // finite: `min` never returns NaN) and leaves both as they are. Lanes
    // with a NaN mass have `positive` unset and keep their masses below.
    let moved = _mm256_mul_pd(fraction, _mm256_sub_pd(w0, r0));
    let w_t = _mm256_sub_pd(w0, moved);
    let r_t = _mm256_add_pd(r0, moved);
    let transferred = _mm256_and_pd(transfers, positive);
    let w1 = pick!(transferred, w_t, w0);
    let r1 = pick!(transferred, r_t, r0);
    // Consumption (eq. 1) of the total before the transfer.
    let saturation = if params.m0_kg > 0.0 {
        _mm256_sub_pd(splat!(1.0), exps.1)
    } else {
        splat!(1.0)
    };
    let c = _mm256_min_pd(
        _mm256_add_pd(
            _mm256_mul_pd(splat!(params.k0_kg), factor),
            _mm256_mul_pd(
                _mm256_mul_pd(_mm256_mul_pd(splat!(params.km1_kg), fp_fc), factor),
                saturation,
            ),
        ),
        m,
    );
    let finite =
        _mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_andnot_pd(splat!(-0.0), per_m), splat!(f64::INFINITY));
    let left = _mm256_sub_pd(m, c);
    let f = _mm256_mul_pd(left, per_m);
    // The division only where a lane needs it (a subnormal m; a lane
    // without mass keeps its masses whatever f is): off the chain of
    // dependent steps that every contact waits for (measured 2026-12-02).
    let f = if _mm256_movemask_pd(_mm256_andnot_pd(finite, positive)) == 0 {
        f
    } else {
        pick!(finite, f, _mm256_div_pd(left, m))
    };
    let before = _mm256_add_pd(w1, r1);
    let w2 = _mm256_mul_pd(w1, f);
    let r2 = _mm256_mul_pd(r1, f);
    let consumed = _mm256_sub_pd(before, _mm256_add_pd(w2, r2));
    let w2 = pick!(positive, w2, w0);
    let r2 = pick!(positive, r2, r0);
    let consumed = _mm256_and_pd(positive, consumed);
    // The cap on each surface.
    let m_max = splat!(params.m_max_kg);
    let over_w = _mm256_cmp_pd::<_CMP_GT_OQ>(w2, m_max);
    let over_r = _mm256_cmp_pd::<_CMP_GT_OQ>(r2, m_max);
    let excess_w = _mm256_and_pd(over_w, _mm256_sub_pd(w2, m_max));
    let excess_r = _mm256_and_pd(over_r, _mm256_sub_pd(r2, m_max));
    let capped = _mm256_add_pd(excess_w, excess_r);
    Rolled4 {
        wheel: pick!(over_w, m_max, w2),
        rail: pick!(over_r, m_max, r2),
        consumed,
        capped,
    }
}

/// [`roll`] for four contacts at once: each lane's [`roll_exp_args`], their
/// exponentials by `f64::exp`, then [`roll_given4`]. [`roll4_fma`] computes
/// the same in vector registers (the same bits where `f64::exp` is glibc's,
/// as [`crate::exp::exp4`]).
#[inline(always)]
pub fn roll4(
    params: &ProductParams,
    masses: ([f64; 4], [f64; 4]),
    conditions: &[ContactConditions; 4],
) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
    let args: [[f64; 2]; 4] =
        std::array::from_fn(|j| roll_exp_args(params, masses.0[j], masses.1[j]));
    let exps = (args.map(|a| a[0].exp()), args.map(|a| a[1].exp()));
    roll_given4(params, masses, conditions, exps)
}

/// [`roll4`] in AVX registers: [`roll_exp_args`] four at once (`max`, a
/// sign flip and a product, as there), [`crate::exp::exp4_inline`], then
/// [`roll_given4_avx`].
///
/// To be inlined into a caller compiled for AVX2 and FMA
/// (`#[target_feature(enable = "avx2,fma")]`), as
/// [`crate::exp::exp4_inline`].
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn roll4_fma(
    params: &ProductParams,
    masses: ([f64; 4], [f64; 4]),
    conditions: &[ContactConditions; 4],
) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
    use std::arch::x86_64::*;
    let wheel = _mm256_loadu_pd(masses.0.as_ptr());
    let rail = _mm256_loadu_pd(masses.1.as_ptr());
    roll4_register(params, (wheel, rail), &Conditions4::of(conditions)).arrays()
}

/// [`roll4_fma`] on registers: the masses and conditions given in AVX
/// registers, the results left in them (for a caller that keeps its lanes
/// there from one contact to the next).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn roll4_register(
    params: &ProductParams,
    (wheel, rail): (std::arch::x86_64::__m256d, std::arch::x86_64::__m256d),
    conditions: &Conditions4,
) -> Rolled4 {
    use std::arch::x86_64::*;
    let sign = _mm256_set1_pd(-0.0);
    // -m1 (1 / cm), m1 the larger mass; -m (1 / (m0 km2)).
    let transfer = _mm256_mul_pd(
        _mm256_xor_pd(_mm256_max_pd(wheel, rail), sign),
        _mm256_set1_pd(1.0 / params.cm_kg),
    );
    let saturation = _mm256_mul_pd(
        _mm256_xor_pd(_mm256_add_pd(wheel, rail), sign),
        _mm256_set1_pd(1.0 / (params.m0_kg * params.km2)),
    );
    let exps = (
        crate::exp::exp4_register(transfer),
        crate::exp::exp4_register(saturation),
    );
    roll_given4_register(params, (wheel, rail), conditions, exps)
}

/// Eight lanes' conditions in an AVX-512 register each: two groups of four
/// wheels ([`Conditions4`] side by side, lanes 0 to 3 the first).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub struct Conditions8 {
    /// The lanes whose `transfer_revolution` is `Some`.
    pub transfers: std::arch::x86_64::__mmask8,
    /// `transfer_revolution`, 0 where `None`.
    pub revolution: std::arch::x86_64::__m512d,
    pub factor: std::arch::x86_64::__m512d,
    pub fp_fc: std::arch::x86_64::__m512d,
}

/// [`Rolled4`] of eight lanes.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub struct Rolled8 {
    pub wheel: std::arch::x86_64::__m512d,
    pub rail: std::arch::x86_64::__m512d,
    pub consumed: std::arch::x86_64::__m512d,
    pub capped: std::arch::x86_64::__m512d,
}

/// [`roll4_register`] on eight lanes: lane by lane the same operations in
/// the same order ([`crate::exp::exp8_register`], the masks of AVX-512 for
/// AVX's blends), so the same bits; the eight lanes take about the
/// instructions that four take there.
///
/// # Safety
/// The CPU must have AVX-512F, AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn roll8_register(
    params: &ProductParams,
    (w0, r0): (std::arch::x86_64::__m512d, std::arch::x86_64::__m512d),
    conditions: &Conditions8,
) -> Rolled8 {
    use std::arch::x86_64::*;
    macro_rules! splat {
        ($x:expr) => {
            _mm512_set1_pd($x)
        };
    }
    // $a where $mask, else $b.
    macro_rules! pick {
        ($mask:expr, $a:expr, $b:expr $(,)?) => {
            _mm512_mask_blend_pd($mask, $b, $a)
        };
    }
    // -x, by the sign bit (AVX-512F has no floating-point xor).
    macro_rules! negate {
        ($x:expr) => {
            _mm512_castsi512_pd(_mm512_xor_si512(
                _mm512_castpd_si512($x),
                _mm512_set1_epi64(i64::MIN),
            ))
        };
    }
    let transfer = _mm512_mul_pd(negate!(_mm512_max_pd(w0, r0)), splat!(1.0 / params.cm_kg));
    let saturation = _mm512_mul_pd(
        negate!(_mm512_add_pd(w0, r0)),
        splat!(1.0 / (params.m0_kg * params.km2)),
    );
    let exps = (
        crate::exp::exp8_register(transfer),
        crate::exp::exp8_register(saturation),
    );
    // From here [`roll_given4_register`]'s steps, which say why.
    let m = _mm512_add_pd(w0, r0);
    let positive = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(m, _mm512_setzero_pd());
    let per_m = _mm512_div_pd(splat!(1.0), m);
    let Conditions8 {
        transfers,
        revolution,
        factor,
        fp_fc,
    } = *conditions;
    let t = _mm512_mul_pd(
        _mm512_mul_pd(splat!(params.kt), _mm512_sub_pd(splat!(1.0), exps.0)),
        revolution,
    );
    let fraction = _mm512_min_pd(_mm512_mul_pd(t, splat!(1.0)), splat!(TRANSFER_FRACTION_MAX));
    let moved = _mm512_mul_pd(fraction, _mm512_sub_pd(w0, r0));
    let w_t = _mm512_sub_pd(w0, moved);
    let r_t = _mm512_add_pd(r0, moved);
    let transferred = transfers & positive;
    let w1 = pick!(transferred, w_t, w0);
    let r1 = pick!(transferred, r_t, r0);
    let saturation = if params.m0_kg > 0.0 {
        _mm512_sub_pd(splat!(1.0), exps.1)
    } else {
        splat!(1.0)
    };
    let c = _mm512_min_pd(
        _mm512_add_pd(
            _mm512_mul_pd(splat!(params.k0_kg), factor),
            _mm512_mul_pd(
                _mm512_mul_pd(_mm512_mul_pd(splat!(params.km1_kg), fp_fc), factor),
                saturation,
            ),
        ),
        m,
    );
    let finite = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_abs_pd(per_m), splat!(f64::INFINITY));
    let left = _mm512_sub_pd(m, c);
    let f = _mm512_mul_pd(left, per_m);
    let f = if (positive & !finite) == 0 {
        f
    } else {
        pick!(finite, f, _mm512_div_pd(left, m))
    };
    let before = _mm512_add_pd(w1, r1);
    let w2 = _mm512_mul_pd(w1, f);
    let r2 = _mm512_mul_pd(r1, f);
    let consumed = _mm512_sub_pd(before, _mm512_add_pd(w2, r2));
    let w2 = pick!(positive, w2, w0);
    let r2 = pick!(positive, r2, r0);
    let consumed = _mm512_maskz_mov_pd(positive, consumed);
    let m_max = splat!(params.m_max_kg);
    let over_w = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(w2, m_max);
    let over_r = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(r2, m_max);
    let excess_w = _mm512_maskz_mov_pd(over_w, _mm512_sub_pd(w2, m_max));
    let excess_r = _mm512_maskz_mov_pd(over_r, _mm512_sub_pd(r2, m_max));
    Rolled8 {
        wheel: pick!(over_w, m_max, w2),
        rail: pick!(over_r, m_max, r2),
        consumed,
        capped: _mm512_add_pd(excess_w, excess_r),
    }
}

/// Caps one surface at `m_max`; returns the mass squeezed out.
#[inline]
pub fn cap(params: &ProductParams, mass_kg: &mut f64) -> f64 {
    if *mass_kg > params.m_max_kg {
        let excess = *mass_kg - params.m_max_kg;
        *mass_kg = params.m_max_kg;
        excess
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ModelConfig;
    use proptest::prelude::*;

    fn table2() -> ProductParams {
        ModelConfig::default().product
    }

    /// A lane's inputs for [`roll_given4`]: masses from clean to over the
    /// cap (equal, zero and subnormal ones among them), with and without a
    /// transfer.
    fn lane_inputs() -> impl Strategy<Value = (f64, f64, ContactConditions, [f64; 2])> {
        let mass = prop_oneof![
            Just(0.0),
            Just(1e-310),
            Just(2e-4),
            Just(5e-3),
            (-12.0..-2.0f64).prop_map(|e| 10f64.powf(e)),
        ];
        (
            mass.clone(),
            mass,
            prop::option::of(1e-3..1.0f64),
            0.5..2.0f64,
            0.0..1.5f64,
            0.0..=1.0f64,
            0.0..=1.0f64,
        )
            .prop_map(|(w, r, revolution, factor, fp_fc, e0, e1)| {
                let conditions = ContactConditions {
                    fp_fc,
                    transfer_revolution: revolution,
                    consumption_factor: factor,
                };
                (w, r, conditions, [e0, e1])
            })
    }

    #[cfg(target_arch = "x86_64")]
    proptest! {
        /// The vector roll gives the lane-by-lane roll's bits, masses and
        /// losses, whatever each lane's case (the cap low enough to act;
        /// m0 zero or not; a lane's masses equal).
        #[test]
        fn the_vector_rolls_are_roll_given_bit_for_bit(
            lanes in prop::array::uniform4(lane_inputs()),
            equal in 0..5usize,
            m_max_kg in prop_oneof![Just(4e-3), Just(1.0)],
            m0 in prop_oneof![Just(0.0), Just(1e-4)],
        ) {
            if !std::arch::is_x86_feature_detected!("avx") {
                return Ok(());
            }
            let params = ProductParams { m_max_kg, m0_kg: m0, ..table2() };
            let mut wheel = lanes.map(|l| l.0);
            let rail = lanes.map(|l| l.1);
            if equal < 4 {
                wheel[equal] = rail[equal];
            }
            let conditions = lanes.map(|l| l.2);
            let exps = (lanes.map(|l| l.3[0]), lanes.map(|l| l.3[1]));
            let scalar = roll_given4(&params, (wheel, rail), &conditions, exps);
            #[target_feature(enable = "avx")]
            fn given(
                p: &ProductParams,
                m: ([f64; 4], [f64; 4]),
                c: &[ContactConditions; 4],
                e: ([f64; 4], [f64; 4]),
            ) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
                // SAFETY: compiled for AVX, called only where it is.
                unsafe { roll_given4_avx(p, m, c, e) }
            }
            // SAFETY: the CPU has AVX (checked above).
            let vector = unsafe { given(&params, (wheel, rail), &conditions, exps) };
            let bits = |(w, r, l): ([f64; 4], [f64; 4], [ContactLosses; 4])| {
                (
                    w.map(f64::to_bits),
                    r.map(f64::to_bits),
                    l.map(|l| (l.consumed_kg.to_bits(), l.capped_kg.to_bits())),
                )
            };
            prop_assert_eq!(bits(vector), bits(scalar));
            // With the exponentials taken inside, from the masses.
            if crate::exp::exp4_is_vectorised() && cfg!(target_env = "gnu") {
                let scalar = roll4(&params, (wheel, rail), &conditions);
                #[target_feature(enable = "avx2,fma")]
                fn whole(
                    p: &ProductParams,
                    m: ([f64; 4], [f64; 4]),
                    c: &[ContactConditions; 4],
                ) -> ([f64; 4], [f64; 4], [ContactLosses; 4]) {
                    // SAFETY: compiled for AVX2 and FMA, called only there.
                    unsafe { roll4_fma(p, m, c) }
                }
                // SAFETY: the CPU has AVX2 and FMA (checked).
                let vector = unsafe { whole(&params, (wheel, rail), &conditions) };
                prop_assert_eq!(bits(vector), bits(scalar));
            }
        }

        /// Eight lanes roll as two groups of four, bit for bit, whatever
        /// each lane's case.
        #[test]
        fn eight_lanes_roll_as_two_groups_of_four(
            lanes in prop::array::uniform8(lane_inputs()),
            equal in 0..9usize,
            m_max_kg in prop_oneof![Just(4e-3), Just(1.0)],
            m0 in prop_oneof![Just(0.0), Just(1e-4)],
        ) {
            if !crate::exp::exp8_is_available() {
                return Ok(());
            }
            let params = ProductParams { m_max_kg, m0_kg: m0, ..table2() };
            let mut wheel = lanes.map(|l| l.0);
            let rail = lanes.map(|l| l.1);
            if equal < 8 {
                wheel[equal] = rail[equal];
            }
            let conditions = lanes.map(|l| l.2);
            type Lanes = [[u64; 8]; 4];
            #[target_feature(enable = "avx2,fma,avx512f")]
            fn both(
                p: &ProductParams,
                (wheel, rail): ([f64; 8], [f64; 8]),
                c: &[ContactConditions; 8],
            ) -> (Lanes, Lanes) {
                use std::arch::x86_64::*;
                macro_rules! bits {
                    ($($v:expr),+) => {{
                        let mut out = [0.0f64; 8];
                        let mut at = 0;
                        $(
                            let v: &[f64] = &$v;
                            out[at..at + v.len()].copy_from_slice(v);
                            at += v.len();
                        )+
                        debug_assert_eq!(at, 8);
                        out.map(f64::to_bits)
                    }};
                }
                macro_rules! four {
                    ($v:expr) => {{
                        let mut a = [0.0; 4];
                        _mm256_storeu_pd(a.as_mut_ptr(), $v);
                        a
                    }};
                }
                macro_rules! eight {
                    ($v:expr) => {{
                        let mut a = [0.0; 8];
                        _mm512_storeu_pd(a.as_mut_ptr(), $v);
                        a
                    }};
                }
                // SAFETY: compiled for these features, called where the CPU
                // has them; the loads and stores are of whole arrays.
                unsafe {
                    let halves: [[ContactConditions; 4]; 2] =
                        [std::array::from_fn(|j| c[j]), std::array::from_fn(|j| c[4 + j])];
                    let c4 = [Conditions4::of(&halves[0]), Conditions4::of(&halves[1])];
                    let a = roll4_register(
                        p,
                        (_mm256_loadu_pd(wheel.as_ptr()), _mm256_loadu_pd(rail.as_ptr())),
                        &c4[0],
                    );
                    let b = roll4_register(
                        p,
                        (_mm256_loadu_pd(wheel[4..].as_ptr()), _mm256_loadu_pd(rail[4..].as_ptr())),
                        &c4[1],
                    );
                    macro_rules! join {
                        ($a:expr, $b:expr) => {
                            _mm512_insertf64x4::<1>(_mm512_castpd256_pd512($a), $b)
                        };
                    }
                    let transfers = _mm256_movemask_pd(c4[0].transfers)
                        | (_mm256_movemask_pd(c4[1].transfers) << 4);
                    let c8 = Conditions8 {
                        transfers: transfers as u8,
                        revolution: join!(c4[0].revolution, c4[1].revolution),
                        factor: join!(c4[0].factor, c4[1].factor),
                        fp_fc: join!(c4[0].fp_fc, c4[1].fp_fc),
                    };
                    let w = roll8_register(
                        p,
                        (_mm512_loadu_pd(wheel.as_ptr()), _mm512_loadu_pd(rail.as_ptr())),
                        &c8,
                    );
                    let fours = [
                        bits!(four!(a.wheel), four!(b.wheel)),
                        bits!(four!(a.rail), four!(b.rail)),
                        bits!(four!(a.consumed), four!(b.consumed)),
                        bits!(four!(a.capped), four!(b.capped)),
                    ];
                    let eights = [
                        bits!(eight!(w.wheel)),
                        bits!(eight!(w.rail)),
                        bits!(eight!(w.consumed)),
                        bits!(eight!(w.capped)),
                    ];
                    (eights, fours)
                }
            }
            // SAFETY: the CPU has AVX-512F, AVX2 and FMA (checked above).
            let (eights, fours) = unsafe { both(&params, (wheel, rail), &conditions) };
            prop_assert_eq!(eights, fours);
        }
    }

    #[test]
    fn every_product_key_reads_and_writes_its_own_field() {
        let p = table2();
        let text = toml::to_string(&p).unwrap();
        for (k, key) in ProductKey::ALL.into_iter().enumerate() {
            // The serialized key of the field is the key's name.
            let line = format!("{} = ", key.name());
            assert!(text.contains(&line), "{line}");
            let mut q = p;
            key.set(&mut q, 1000.0 + k as f64);
            assert_eq!(key.get(&q), 1000.0 + k as f64);
            let changed: Vec<ProductKey> = ProductKey::ALL
                .into_iter()
                .filter(|o| o.get(&q) != o.get(&p))
                .collect();
            assert_eq!(changed, [key]);
        }
        // Every field of ProductParams has a key.
        assert_eq!(text.lines().count(), ProductKey::ALL.len());
    }

    #[test]
    fn factors_are_one_at_the_reference_condition() {
        let p = table2();
        assert_eq!(pressure_factor(&p, 1178e6), 1.0);
        assert!((creepage_factor(&p, 0.01, 0.0) - 1.0).abs() < 1e-15);
        // The clamps at zero (model.md).
        assert_eq!(pressure_factor(&p, 100e6), 0.0);
        assert_eq!(creepage_factor(&p, 0.0, 0.0), 1.0 - 0.57);
        // pm = 825.04 MPa of model.md's check: fp = 1 + 1.84 (825.04/1178 - 1).
        let fp = pressure_factor(&p, 825.04e6);
        assert!((fp - (1.0 + 1.84 * (825.04 / 1178.0 - 1.0))).abs() < 1e-12);
    }

    #[test]
    fn consumption_by_hand() {
        let p = table2();
        // Abundant product: k0 + km1 (eq. 1 with m >> m0 km2).
        assert_eq!(p.m0_kg, 1e-4);
        let c = consumption(&p, 1.0, 1.0, 1.0);
        assert!((c - (1.0449e-9 + 1.1617e-6)).abs() < 1e-21);
        // m = m0 km2: the saturation term is 1 - 1/e.
        let c = consumption(&p, 0.53e-4, 1.0, 1.0);
        let expect = 1.0449e-9 + 1.1617e-6 * (1.0 - (-1.0f64).exp());
        assert!((c - expect).abs() < 1e-21);
        // Never more than there is.
        assert_eq!(consumption(&p, 1e-12, 1.0, 1.0), 1e-12);
        // m0 = 0: the saturation term is 1.
        let p0 = ProductParams { m0_kg: 0.0, ..p };
        assert_eq!(
            consumption(&p0, 1e-5, 2.0, 1.0),
            1.0449e-9 + 1.1617e-6 * 2.0
        );
    }

    #[test]
    fn friction_limits() {
        let p = table2();
        assert_eq!(friction(&p, 0.0), 0.58);
        assert!((friction(&p, 1.0) - 0.15).abs() < 1e-15);
        // m = km: muC + (muD - muC)/e.
        let mu = friction(&p, 1.6290e-4);
        assert!((mu - (0.15 + 0.43 * (-1.0f64).exp())).abs() < 1e-15);
    }

    #[test]
    fn transfer_by_hand() {
        let p = table2();
        // Donor 0.1 g on the rail, clean wheel, N = 1: t = 0.5 (1 - exp(-0.1/0.035)).
        let t = transfer_fraction(&p, 1e-4, revolution_factor(&p, 1), 1.0);
        assert!((t - 0.5 * (1.0 - (-1e-4f64 / 3.5e-5).exp())).abs() < 1e-15);
        let (w, r) = transfer(0.0, 1e-4, |m1| transfer_fraction(&p, m1, 1.0, 1.0));
        assert!((w - t * 1e-4).abs() < 1e-20 && (r - (1.0 - t) * 1e-4).abs() < 1e-20);
        // The clamp at equal shares.
        assert_eq!(transfer_fraction(&p, 1.0, 1.0, 10.0), 0.5);
        // N = 13: exp(-12/12.1).
        assert!((revolution_factor(&p, 13) - (-12.0f64 / 12.1).exp()).abs() < 1e-16);
    }

    #[test]
    fn roll_without_product_only_caps() {
        let p = table2();
        let (mut w, mut r) = (0.0, 0.0);
        let cond = ContactConditions {
            fp_fc: 1.0,
            transfer_revolution: Some(1.0),
            consumption_factor: 1.0,
        };
        assert_eq!(roll(&p, &mut w, &mut r, &cond), ContactLosses::default());
        assert_eq!((w, r), (0.0, 0.0));
        let (mut w, mut r) = (0.0, 3e-4);
        let l = roll(
            &p,
            &mut w,
            &mut r,
            &ContactConditions {
                transfer_revolution: None,
                ..cond
            },
        );
        assert!(r <= p.m_max_kg && w == 0.0);
        assert!((l.consumed_kg + l.capped_kg + r - 3e-4).abs() < 1e-18);
    }

    /// A subnormal mass (ageing leaves one after years untouched) is
    /// consumed like any other, not turned into NaN by 0 · (1 / m) = 0 ·
    /// inf (found by the semantic fuzzer: a state holding 5e-324 kg).
    #[test]
    fn a_subnormal_mass_is_consumed_not_made_nan() {
        let p = table2();
        let cond = ContactConditions {
            fp_fc: 1.0,
            transfer_revolution: Some(1.0),
            consumption_factor: 1.0,
        };
        for (w0, r0) in [(0.0, 5e-324), (5e-324, 1e-310), (1e-310, 0.0)] {
            let (mut w, mut r) = (w0, r0);
            let l = roll(&p, &mut w, &mut r, &cond);
            assert_eq!((w, r), (0.0, 0.0), "{w0:e} {r0:e}");
            assert_eq!(l.consumed_kg, w0 + r0);
        }
    }

    fn mass() -> impl Strategy<Value = f64> {
        prop_oneof![Just(0.0), 0.0..3e-4f64, 1e-12..1e-6f64]
    }

    proptest! {
        #[test]
        fn transfer_conserves_and_levels(w in mass(), r in mass(), rev in 0.0..1.0f64, factor in 0.0..50.0f64) {
            let p = table2();
            let (w2, r2) = transfer(w, r, |m1| transfer_fraction(&p, m1, rev, factor));
            prop_assert!(w2 >= 0.0 && r2 >= 0.0);
            prop_assert!(((w2 + r2) - (w + r)).abs() <= 4.0 * f64::EPSILON * (w + r));
            // The donor never ends up with less than the receiver.
            prop_assert!((w >= r) == (w2 >= r2) || (w2 - r2).abs() <= 4.0 * f64::EPSILON * (w + r));
        }

        #[test]
        fn a_contact_keeps_masses_and_mu_in_range(
            w in mass(), r in mass(), m0 in prop_oneof![Just(0.0), 1e-6..5e-4f64],
            fp_fc in 0.0..5.0f64, rev in prop_oneof![Just(None), (0.0..1.0f64).prop_map(Some)],
            tf in 0.1..10.0f64,
        ) {
            let p = ProductParams { m0_kg: m0, ..table2() };
            let (mut w2, mut r2) = (w, r);
            let cond = ContactConditions { fp_fc, transfer_revolution: rev, consumption_factor: tf };
            let losses = roll(&p, &mut w2, &mut r2, &cond);
            prop_assert!(w2 >= 0.0 && r2 >= 0.0);
            prop_assert!(w2 <= p.m_max_kg && r2 <= p.m_max_kg);
            prop_assert!(losses.consumed_kg >= 0.0 && losses.capped_kg >= 0.0);
            // Consumption never takes more than there is.
            prop_assert!(losses.consumed_kg <= (w + r) * (1.0 + 1e-15));
            // Mass balance of one contact.
            let before = w + r;
            let after = w2 + r2 + losses.consumed_kg + losses.capped_kg;
            prop_assert!((before - after).abs() <= 1e-15 * before.max(1e-30), "{before} vs {after}");
            for m in [w2, r2, w2 + r2] {
                let mu = friction(&p, m);
                prop_assert!((p.mu_c..=p.mu_d).contains(&mu));
            }
        }
    }

    proptest! {
        /// The exponentials taken elsewhere (four contacts at once in the
        /// engine) give the bits of the contact that takes its own.
        #[test]
        fn roll_given_is_roll(
            wheel in prop_oneof![Just(0.0), 0.0..3e-4f64],
            rail in prop_oneof![Just(0.0), 0.0..3e-4f64],
            m0 in prop_oneof![Just(0.0), 1e-6..3e-4f64],
            fp_fc in 0.0..3.0f64,
            revolution in prop_oneof![Just(None), (0.0..1.0f64).prop_map(Some)],
            factor in 0.1..3.0f64,
        ) {
            let p = ProductParams { m0_kg: m0, ..table2() };
            let conditions = ContactConditions {
                fp_fc,
                transfer_revolution: revolution,
                consumption_factor: factor,
            };
            let (mut w1, mut r1) = (wheel, rail);
            let l1 = roll(&p, &mut w1, &mut r1, &conditions);
            let exps = roll_exp_args(&p, wheel, rail).map(f64::exp);
            let (mut w2, mut r2) = (wheel, rail);
            let l2 = roll_given(&p, &mut w2, &mut r2, &conditions, exps);
            prop_assert_eq!(w1.to_bits(), w2.to_bits());
            prop_assert_eq!(r1.to_bits(), r2.to_bits());
            prop_assert_eq!(l1.consumed_kg.to_bits(), l2.consumed_kg.to_bits());
            prop_assert_eq!(l1.capped_kg.to_bits(), l2.capped_kg.to_bits());
        }
    }
}
