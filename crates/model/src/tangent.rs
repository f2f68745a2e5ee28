//! Tangent-linear stepping: the sensitivity of the product masses to the
//! constants that move them, carried beside the masses in one replay.
//!
//! A fit of the state constants ([`Role::State`](crate::role::Role): `kc`,
//! `kt`, `cn`, `k0`, `km1`, `m0`, `km2`, `kp`, `cm`, `m_max`) needs every
//! measurement's derivative with respect to each of them. By differences
//! that is one replay per constant; here every mass carries a [`Tangent`],
//! its derivatives with respect to `ln p` of the ten constants, and every
//! step of "one contact" (model.md) updates the tangents with the exact
//! derivative of what it does to the masses (forward-mode differentiation
//! of the stepping, written out by hand). One replay gives the masses and
//! all ten derivatives.
//!
//! The derivative is with respect to `θ = ln p` (a relative change): the
//! calibration's coordinate (`p ∂/∂p`).
//!
//! **Where the model is not smooth** the tangent is the one-sided
//! derivative of the branch the primal took: the clamps of eq. (2) and (3)
//! at 0, the transfer fraction's cap at 0.5, `c <= m` and the cap at
//! `m_max` (a capped surface's mass is `m_max`: derivative 1 in `m_max`, 0
//! in the rest), and which surface is the donor. A fit that steps across
//! such a kink sees the other branch at its next evaluation; the tests
//! compare with central differences away from the kinks.
//!
//! The time effects, the wheel edge reservoir, the bands and the generic
//! terms on transfer, consumption and the pulse mass are linear in the
//! masses or do not depend on the constants: their tangents follow from
//! the same multiplications.
//!
//! **The effects' own parameters** that act on the mass have
//! [`EFFECT_SLOTS`] slots more, after the constants': each follows one
//! [`EffectParam`] that a replay names, as `∂ mass / ∂ q` in the
//! parameter's own unit (not its logarithm: `n`, `beta` and a step's `f`
//! cross 0). A parameter enters a contact through the transfer factor
//! (`speed_transfer`, a generic transfer term), the consumption factor
//! (`temperature_consumption`, a generic consumption term), the pulse mass
//! (a generic pulse-mass term), the time effects (`rail_ageing`,
//! `rain_washoff`) or the wheel edge reservoir; the engine gives the
//! factors' derivatives ([`ConditionTangents`]) and here they enter the
//! contact as `cN` and `k0` do. A step's threshold `x0` moves the masses by
//! a jump and has no slot.

use crate::effects::Named;
use crate::product::{self, ContactConditions, ContactLosses, ProductKey, ProductParams};

/// How many constants a tangent follows: its first slots.
pub const STATE_SLOTS: usize = 10;

/// How many effect parameters a tangent follows: its last slots.
pub const EFFECT_SLOTS: usize = 2;

/// Slots in a [`Tangent`].
pub const SLOTS: usize = STATE_SLOTS + EFFECT_SLOTS;

/// The constants a [`Tangent`] follows, in the order of its slots: every
/// constant whose role is `State`.
pub const STATE_KEYS: [ProductKey; STATE_SLOTS] = [
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

const KC: usize = 0;
const KT: usize = 1;
const CN: usize = 2;
const K0: usize = 3;
const KM1: usize = 4;
const M0: usize = 5;
const KM2: usize = 6;
const KP: usize = 7;
const CM: usize = 8;
const M_MAX: usize = 9;

/// `∂ mass / ∂ ln p` for the constants of [`STATE_KEYS`], in kg, then
/// `∂ mass / ∂ q` for the effect parameters a replay follows
/// ([`EffectParam`]; zero for a slot that follows none).
pub type Tangent = [f64; SLOTS];

/// An effect parameter that acts on the mass, followed in a tangent's
/// effect slot ([`effect_slot`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectParam {
    /// Parameter `param` of a named effect (effects.md's table order):
    /// `rail_ageing`'s `tau_s`, `rain_washoff`'s `k_per_mm`,
    /// `temperature_consumption`'s `beta_per_k`, `speed_transfer`'s `n`,
    /// `wheel_edge_reservoir`'s `alpha` (0) and `r` (1).
    Named { effect: Named, param: usize },
    /// The smooth parameter ([`crate::generic::Form::dg_dq`]) of the
    /// configuration's `[[effects.generic]]` table `term` (0-based), a
    /// term on the pulse mass, the transfer or the consumption.
    Generic { term: usize },
}

/// The slot of effect parameter `k` (`k < EFFECT_SLOTS`).
#[inline]
pub const fn effect_slot(k: usize) -> usize {
    STATE_SLOTS + k
}

/// The slot of `key` in a [`Tangent`]; `None` for a read-out constant.
pub fn slot(key: ProductKey) -> Option<usize> {
    STATE_KEYS.iter().position(|&k| k == key)
}

/// The tangents of what a contact needs besides the masses
/// ([`ContactConditions`]); every other slot is zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConditionTangents {
    /// Of `fp · fc` (eq. 2 and 3): its slots `kp` and `kc`
    /// ([`fp_fc_tangent`]).
    pub fp_fc: [f64; 2],
    /// Of the transfer's `exp(-(N - 1) / cN)` times the effect factor: its
    /// slot `cN` ([`revolution_tangent`]).
    pub transfer_revolution: f64,
    /// Of the same transfer factor, in the effect parameters followed.
    pub transfer_effect: [f64; EFFECT_SLOTS],
    /// Of the consumption factor (eq. 1's `F`), in the effect parameters
    /// followed.
    pub consumption_effect: [f64; EFFECT_SLOTS],
}

/// The tangent of eq. (2) times eq. (3) for a wheel of mean pressure
/// `pm_pa` and creepages `cx`, `cy`, in its two slots (`kp`, `kc`): `fc ·
/// ∂fp/∂ln kp` and `fp · ∂fc/∂ln kc`, zero where a clamp at 0 holds.
pub fn fp_fc_tangent(params: &ProductParams, pm_pa: f64, cx: f64, cy: f64) -> [f64; 2] {
    let fp = product::pressure_factor(params, pm_pa);
    let fc = product::creepage_factor(params, cx, cy);
    let mut t = [0.0; 2];
    if fp > 0.0 {
        t[0] = fc * params.kp * (pm_pa / product::PM_REF_PA - 1.0);
    }
    if fc > 0.0 {
        t[1] = fp * params.kc * ((cx * cx + cy * cy).sqrt() / product::CREEPAGE_REF - 1.0);
    }
    t
}

/// The tangent of a transfer factor `revolution = exp(-n / cN) · g` (`n =
/// N - 1`) in its slot `cN`: `revolution · n / cN`.
pub fn revolution_tangent(params: &ProductParams, revolution: f64, n: usize) -> f64 {
    revolution * n as f64 / params.cn
}

/// `m_max`'s own tangent: what a capped surface holds.
pub fn capped(params: &ProductParams) -> Tangent {
    let mut t = [0.0; SLOTS];
    t[M_MAX] = params.m_max_kg;
    t
}

/// `a + b`, slot by slot.
#[inline]
pub fn add(a: &Tangent, b: &Tangent) -> Tangent {
    std::array::from_fn(|k| a[k] + b[k])
}

/// [`product::roll`] (steps 3 to 5 of one contact) with the tangents of
/// the two masses carried: the same masses bit for bit, and `wheel_tan`,
/// `rail_tan` updated to the masses' tangents after the contact (every
/// slot).
#[inline]
pub fn roll(
    params: &ProductParams,
    wheel_kg: &mut f64,
    rail_kg: &mut f64,
    conditions: &ContactConditions,
    tangents: &ConditionTangents,
    wheel_tan: &mut Tangent,
    rail_tan: &mut Tangent,
) -> ContactLosses {
    let exps = product::roll_exp_args(params, *wheel_kg, *rail_kg).map(f64::exp);
    roll_given::<SLOTS>(
        params,
        wheel_kg,
        rail_kg,
        conditions,
        tangents,
        (wheel_tan, rail_tan),
        exps,
    )
}

/// [`roll`] with its exponentials given: `exps` is `exp` of
/// [`product::roll_exp_args`] for the same masses (as
/// [`product::roll_given`]), so that four contacts can take theirs at once.
/// Only the first `W` slots are stepped (the rest are left as they are: a
/// replay that follows no effect parameter steps the constants' alone).
#[inline(always)]
pub fn roll_given<const W: usize>(
    params: &ProductParams,
    wheel_kg: &mut f64,
    rail_kg: &mut f64,
    conditions: &ContactConditions,
    tangents: &ConditionTangents,
    (wheel_tan, rail_tan): (&mut Tangent, &mut Tangent),
    exps: [f64; 2],
) -> ContactLosses {
    let m = *wheel_kg + *rail_kg;
    // The total's tangent: the transfer moves mass, it does not change it.
    let dm = add(wheel_tan, rail_tan);
    let mut losses = ContactLosses::default();
    if m > 0.0 {
        let per_m = 1.0 / m;
        if let Some(revolution) = conditions.transfer_revolution {
            transfer::<W>(
                params,
                (revolution, tangents),
                exps[0],
                (wheel_kg, wheel_tan),
                (rail_kg, rail_tan),
            );
        }
        // Eq. (1), as product::consumption_given computes it.
        let factor = conditions.consumption_factor;
        let (saturation, e_per_scale) = if params.m0_kg > 0.0 {
            let e = exps[1];
            (1.0 - e, e * (1.0 / (params.m0_kg * params.km2)))
        } else {
            (1.0, 0.0)
        };
        let raw = params.k0_kg * factor + (params.km1_kg * conditions.fp_fc * factor) * saturation;
        let c = raw.min(m);
        // ∂c = slope ∂m + own: where c = m, ∂c = ∂m; else ∂c = km1 F (S
        // ∂(fp fc) + fp fc ∂S) + ∂k0 F + ∂km1 fp fc F S, with ∂S = e/s (∂m
        // - m ∂ln s), s = m0 km2.
        let mut own = [0.0; SLOTS];
        let slope = if raw < m {
            let on_fp_fc = params.km1_kg * factor * saturation;
            let on_saturation = params.km1_kg * factor * conditions.fp_fc;
            own[KP] = on_fp_fc * tangents.fp_fc[0];
            own[KC] = on_fp_fc * tangents.fp_fc[1];
            own[M0] -= on_saturation * e_per_scale * m;
            own[KM2] -= on_saturation * e_per_scale * m;
            own[K0] += params.k0_kg * factor;
            own[KM1] += on_saturation * saturation;
            // raw = (k0 + km1 fp fc S) F.
            let per_factor = params.k0_kg + params.km1_kg * conditions.fp_fc * saturation;
            for (k, d) in tangents.consumption_effect.iter().enumerate() {
                own[effect_slot(k)] += per_factor * d;
            }
            on_saturation * e_per_scale
        } else {
            1.0
        };
        // As product::roll_core: a subnormal m has no finite reciprocal.
        let over_m = |x: f64| {
            if per_m.is_finite() {
                x * per_m
            } else {
                x / m
            }
        };
        let f = over_m(m - c);
        // ∂f = (∂m - ∂c - f ∂m) / m; both surfaces are scaled by f.
        let keep = over_m(1.0 - f - slope);
        let before = *wheel_kg + *rail_kg;
        // The slots' own terms over m first, the branch taken once: the
        // loop below is then straight-line work the compiler puts in
        // vector registers (the same operations on each slot, the same
        // bits; callgrind had the branch at every slot).
        let own_over_m: [f64; W] = match per_m.is_finite() {
            true => std::array::from_fn(|k| own[k] * per_m),
            false => std::array::from_fn(|k| own[k] / m),
        };
        let (w, r) = (*wheel_kg, *rail_kg);
        for k in 0..W {
            let df = keep * dm[k] - own_over_m[k];
            wheel_tan[k] = wheel_tan[k] * f + w * df;
            rail_tan[k] = rail_tan[k] * f + r * df;
        }
        *wheel_kg *= f;
        *rail_kg *= f;
        losses.consumed_kg = before - (*wheel_kg + *rail_kg);
    }
    losses.capped_kg = cap(params, wheel_kg, wheel_tan) + cap(params, rail_kg, rail_tan);
    losses
}

/// Eq. (5) and (6) with tangents: the donor (more product) gives `t (m1 -
/// m2)`, `t = min(kt (1 - e^(-m1/cm)) R, 0.5)`.
#[inline(always)]
fn transfer<const W: usize>(
    params: &ProductParams,
    (revolution, tangents): (f64, &ConditionTangents),
    e: f64,
    wheel: (&mut f64, &mut Tangent),
    rail: (&mut f64, &mut Tangent),
) {
    let (donor, receiver) = match (*wheel.0).partial_cmp(&*rail.0) {
        Some(std::cmp::Ordering::Greater) => (wheel, rail),
        Some(std::cmp::Ordering::Less) => (rail, wheel),
        _ => return,
    };
    let (m1, m2) = (*donor.0, *receiver.0);
    let raw = params.kt * (1.0 - e) * revolution;
    let t = (raw * 1.0).min(product::TRANSFER_FRACTION_MAX);
    let moved = t * (m1 - m2);
    // ∂moved = ∂t (m1 - m2) + t (∂m1 - ∂m2); where t is below its cap, ∂t
    // = kt R e (∂m1 - m1 ∂ln cm) / cm + kt (1 - e) ∂R + t ∂ln kt.
    let gap = if raw < product::TRANSFER_FRACTION_MAX {
        m1 - m2
    } else {
        0.0
    };
    let per_m1 = params.kt * revolution * e * (1.0 / params.cm_kg);
    let per_revolution = params.kt * (1.0 - e);
    let mut own = [0.0; SLOTS];
    own[CN] = per_revolution * tangents.transfer_revolution;
    for (k, d) in tangents.transfer_effect.iter().enumerate() {
        own[effect_slot(k)] = per_revolution * d;
    }
    own[CM] = -per_m1 * m1;
    own[KT] = raw;
    let on_donor = per_m1 * gap + t;
    let (d, r) = (donor.1, receiver.1);
    for k in 0..W {
        let d_moved = on_donor * d[k] - t * r[k] + gap * own[k];
        d[k] -= d_moved;
        r[k] += d_moved;
    }
    *donor.0 = m1 - moved;
    *receiver.0 = m2 + moved;
}

/// [`product::cap`] with the tangent: a capped surface holds `m_max`.
pub fn cap(params: &ProductParams, mass_kg: &mut f64, tangent: &mut Tangent) -> f64 {
    let excess = product::cap(params, mass_kg);
    if excess > 0.0 {
        *tangent = capped(params);
    }
    excess
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ModelConfig;
    use proptest::prelude::*;

    fn table2() -> ProductParams {
        ModelConfig::default().product
    }

    /// One contact from clean tangents at `params` (masses only), the
    /// transfer factor times `1 + q[0]`, the consumption factor times
    /// `exp(q[1])`: the two effect slots' parameters.
    #[allow(clippy::too_many_arguments)]
    fn contact(
        params: &ProductParams,
        w: f64,
        r: f64,
        pm_pa: f64,
        creep: f64,
        n: Option<usize>,
        q: [f64; 2],
    ) -> (f64, f64) {
        let mut conditions = conditions(params, pm_pa, creep, n);
        conditions.transfer_revolution = conditions.transfer_revolution.map(|r| r * (1.0 + q[0]));
        conditions.consumption_factor *= q[1].exp();
        let (mut w, mut r) = (w, r);
        product::roll(params, &mut w, &mut r, &conditions);
        (w, r)
    }

    fn conditions(
        params: &ProductParams,
        pm_pa: f64,
        creep: f64,
        n: Option<usize>,
    ) -> ContactConditions {
        ContactConditions {
            fp_fc: product::pressure_factor(params, pm_pa)
                * product::creepage_factor(params, creep, 0.0),
            transfer_revolution: n.map(|n| product::revolution_factor(params, n as u32 + 1)),
            consumption_factor: 1.0,
        }
    }

    proptest! {
        /// The tangent stepping gives the masses of the plain stepping bit
        /// for bit, and derivatives equal to central differences.
        #[test]
        fn one_contact_matches_the_plain_step_and_central_differences(
            w in 0.0f64..2.5e-4,
            r in 0.0f64..2.5e-4,
            pm in 600e6f64..1400e6,
            creep in 0.0f64..0.02,
            n in prop::option::of(0usize..40),
            // Tangents the masses arrive with (from earlier contacts), as
            // shares of the masses.
            aw in prop::array::uniform12(-1.0f64..1.0),
            ar in prop::array::uniform12(-1.0f64..1.0),
        ) {
            let p = table2();
            let (dw0, dr0): (Tangent, Tangent) = (aw.map(|a| a * w), ar.map(|a| a * r));
            let cond = conditions(&p, pm, creep, n);
            let tangents = ConditionTangents {
                fp_fc: fp_fc_tangent(&p, pm, creep, 0.0),
                transfer_revolution: n.map_or(0.0, |n| {
                    revolution_tangent(&p, cond.transfer_revolution.unwrap(), n)
                }),
                // ∂R/∂q0 = R, ∂F/∂q1 = F (= 1) at q = 0.
                transfer_effect: [cond.transfer_revolution.unwrap_or(0.0), 0.0],
                consumption_effect: [0.0, cond.consumption_factor],
            };
            let (mut w1, mut r1, mut dw, mut dr) = (w, r, dw0, dr0);
            let losses = roll(&p, &mut w1, &mut r1, &cond, &tangents, &mut dw, &mut dr);
            let (mut w2, mut r2) = (w, r);
            let plain = product::roll(&p, &mut w2, &mut r2, &cond);
            prop_assert_eq!((w1.to_bits(), r1.to_bits()), (w2.to_bits(), r2.to_bits()));
            prop_assert_eq!(losses, plain);
            // Central differences in ln p for each constant, the incoming
            // masses moved along their tangents.
            let h = 1e-6;
            for k in 0..SLOTS {
                let at = |s: f64| {
                    let mut q = p;
                    let mut e = [0.0; 2];
                    match STATE_KEYS.get(k) {
                        Some(key) => key.set(&mut q, key.get(&p) * s.exp()),
                        None => e[k - STATE_SLOTS] = s,
                    }
                    contact(&q, w + s * dw0[k], r + s * dr0[k], pm, creep, n, e)
                };
                let key = STATE_KEYS.get(k);
                let (hi, lo) = (at(h), at(-h));
                let fd = ((hi.0 - lo.0) / (2.0 * h), (hi.1 - lo.1) / (2.0 * h));
                // Only where no branch changes between the two sides.
                let kinked = |a: (f64, f64), b: (f64, f64)| (a.0 > a.1) != (b.0 > b.1);
                if kinked(hi, lo) || kinked((w, r), hi) {
                    continue;
                }
                let tol = |x: f64| 1e-6 * x.abs() + 1e-13;
                prop_assert!((fd.0 - dw[k]).abs() <= tol(fd.0), "{key:?} wheel {} vs {}", dw[k], fd.0);
                prop_assert!((fd.1 - dr[k]).abs() <= tol(fd.1), "{key:?} rail {} vs {}", dr[k], fd.1);
            }
        }
    }

    #[test]
    fn a_capped_surface_follows_m_max_alone() {
        let p = table2();
        let mut m = 3e-4;
        let mut t = [1.0; SLOTS];
        let excess = cap(&p, &mut m, &mut t);
        assert!(excess > 0.0);
        assert_eq!(t, capped(&p));
        let mut m = 1e-4;
        let mut t = [1.0; SLOTS];
        assert_eq!(cap(&p, &mut m, &mut t), 0.0);
        assert_eq!(t, [1.0; SLOTS]);
    }

    #[test]
    fn the_slots_are_the_state_constants() {
        use crate::role::Role;
        let state: Vec<ProductKey> = ProductKey::ALL
            .into_iter()
            .filter(|k| k.role() == Role::State)
            .collect();
        assert_eq!(state, STATE_KEYS.to_vec());
        assert_eq!(slot(ProductKey::MuD), None);
        assert_eq!(slot(ProductKey::MMaxKg), Some(M_MAX));
    }
}
