//! The stepping loop: one wheel over every grid point of one track, in the
//! order of model.md "One contact". This is the hot path: no allocation,
//! everything that depends only on the wheel computed once before the loop.

/// The vector kernel's operations in AVX2 and FMA registers ([`Vector`]):
/// four lanes' exponentials and quotients at once, steps 3 to 5 of four
/// contacts, and runs of steps in registers ([`RollContext::runs_fma`]). A
/// macro, to be expanded in a function compiled for AVX2 and FMA and run
/// only where the CPU has them: closures written there are compiled for
/// them and inlined into it (made in a function of their own, they were
/// left out of line: a day of the line 5 % slower, measured 2026-12-04).
/// (No multiply-add is fused that the source does not ask for: Rust never
/// contracts.)
#[cfg(target_arch = "x86_64")]
macro_rules! vector_fma {
    () => {
        $crate::roll::Vector {
            // SAFETY: expanded only in functions compiled for AVX2 and FMA
            // and called only where the CPU has them.
            exp: |x| unsafe { tortwin_model::exp::exp4_inline(x) },
            // SAFETY: as above.
            div: |a, b| unsafe { $crate::roll::div4_avx(a, b) },
            // SAFETY: as above.
            roll:
                |p: &tortwin_model::product::ProductParams,
                 m,
                 c: &[tortwin_model::product::ContactConditions; $crate::roll::LANES]| unsafe {
                    tortwin_model::product::roll4_fma(p, m, c)
                },
            // SAFETY: as above.
            run: Some(
                |ctx: &$crate::roll::RollContext<'_>,
                 parts: &mut [$crate::roll::RunPart<'_>],
                 first: usize,
                 end: usize| unsafe { ctx.runs_fma(parts, first, end) },
            ),
        }
    };
}

mod on_line;

use std::sync::Arc;

use super::terms::{GenericSet, When, Which};
use super::weather::WeatherState;
use super::weather::WeatherTimeline;
use super::weather::SECONDS_PER_HOUR;
use super::{
    enters_at_zero, Engine, EngineError, PointEvent, PointEventKind, SnapshotKind, Totals,
    TrackState, TrainRecord, NO_APPLICATOR,
};
use crate::sink::{FieldSnapshot, Sink, TrackInfo, WheelContacts};
use tortwin_model::effects::{self, Named, TimeEffects};
use tortwin_model::exp::exp4_is_vectorised;
use tortwin_model::generic::ActsOn;
use tortwin_model::product::{self, ContactConditions, ContactLosses, ProductParams};
use tortwin_model::tangent::{
    self, effect_slot, ConditionTangents, EffectParam, Tangent, EFFECT_SLOTS, SLOTS,
};
use tortwin_recording::Section;

/// In [`Observed::axle`]: a point no wheel of the train touched on a track.
const NO_AXLE: u32 = u32::MAX;

/// What a wheel saw at every point of its track (kept for the last wheel of
/// each track, or for every wheel when a sink asks for it).
#[derive(Debug, Clone, Default)]
pub(crate) struct Observed {
    /// Total mass at step 2, per point.
    pub(crate) mass_kg: Vec<f64>,
    /// The wheel's mass after the contact (after step 6), per point.
    pub(crate) wheel_mass_kg: Vec<f64>,
    /// On a line: the axle whose contact it was, per point (`u32::MAX`
    /// where no wheel of the train used this track there); else empty.
    pub(crate) axle: Vec<u32>,
}

impl Observed {
    pub(crate) fn new(points: usize) -> Self {
        Self {
            mass_kg: vec![0.0; points],
            wheel_mass_kg: vec![0.0; points],
            axle: Vec::new(),
        }
    }
}

/// The rolling wheel's own state.
#[derive(Clone)]
struct WheelRoll {
    wheel_kg: f64,
    /// On a line: the tread's bands F, C, G (line.md); `wheel_kg` holds the
    /// band in contact during a contact.
    bands: [f64; 3],
    /// The wheel_edge_reservoir effect's m_e.
    edge_kg: f64,
    /// Grid point of the applicator passed last (N = 1 there).
    applicator_point: Option<usize>,
    consumed_kg: f64,
    capped_kg: f64,
    lost_kg: f64,
    /// With tangents ([`crate::EngineOptions::tangents`]): the tangents of
    /// `wheel_kg` and `edge_kg`, and of the step-2 mass of the last contact.
    wheel_tan: Tangent,
    edge_tan: Tangent,
    seen_tan: Tangent,
}

/// What a contact needs that depends only on the wheel: computed once.
#[derive(Clone)]
struct Roller {
    params: ProductParams,
    time_effects: TimeEffects,
    t_passage_s: f64,
    offset_m: f64,
    speed_mps: f64,
    d_entry_m: f64,
    fp_fc: f64,
    /// speed_transfer's factor times the generic transfer terms driven by
    /// the wheel (1 when there are none).
    transfer_factor: f64,
    /// The generic consumption terms driven by the wheel (1 when none).
    consumption_generic: f64,
    /// Generic terms on transfer / consumption that change along the path
    /// (time, weather): evaluated at every contact.
    transfer_varies: bool,
    consumption_varies: bool,
    generic: Arc<GenericSet>,
    rail: usize,
    temperature_beta: Option<f64>,
    /// The temperature factor when the weather does not change while the
    /// train is in the section (the usual case): computed once.
    temperature_factor: Option<f64>,
    /// wheel_edge_reservoir's (alpha, r).
    reservoir: Option<(f64, f64)>,
    observe: bool,
    /// The tangent of `fp_fc` in its slots `kp`, `kc` (zero without
    /// tangents).
    fp_fc_tan: [f64; 2],
    /// With tangents, the effect parameters followed and the derivatives
    /// of `transfer_factor` and `consumption_generic` in them.
    effect_params: [Option<EffectParam>; EFFECT_SLOTS],
    transfer_factor_d: [f64; EFFECT_SLOTS],
    consumption_generic_d: [f64; EFFECT_SLOTS],
    /// The air temperature of `temperature_factor` (when that is constant).
    temperature_c: f64,
    /// The consumption factor of every contact, when nothing in it
    /// changes along the path: computed once, as [`Roller::conditions`]
    /// would compute it at each contact.
    consumption_constant: Option<f64>,
    /// A time effect is on ([`TimeEffects::any`], asked once).
    ages: bool,
}

impl Roller {
    /// The wheel's time at point i: `t_passage + (|d_i - d_entry| + offset) / v`
    /// (model.md, computed in that form).
    #[inline(always)]
    fn time_at(&self, d_m: &[f64], i: usize) -> f64 {
        wheel_time_s(
            self.t_passage_s,
            d_m[i],
            self.d_entry_m,
            self.offset_m,
            self.speed_mps,
        )
    }

    /// One contact at point i, steps 1 to 6 of model.md. Returns the total
    /// mass of step 2 (what a measurement of this contact sees). The
    /// phases are those [`RollContext::contacts4`] runs for four wheels at
    /// once, with the exponentials taken here one by one.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn contact(
        &self,
        st: &mut WheelRoll,
        track: &mut TrackState,
        observed: &mut Observed,
        d_m: &[f64],
        revolution: &[f64],
        timeline: &WeatherTimeline,
        i: usize,
    ) -> f64 {
        let mut touch = self.touch(track, d_m, timeline, i);
        if touch.aged {
            let exps = self
                .time_effects
                .exp_args(touch.dt_s, touch.rain_mm)
                .map(f64::exp);
            self.age(st, &mut touch, exps);
        }
        self.touched(track, &touch, i);
        let conditions = self.conditions(st, &touch, revolution, i);
        self.finish(st, track, observed, &touch, &conditions, i)
    }

    /// [`Roller::contact`] with the tangents carried
    /// ([`tortwin_model::tangent`]): the same masses, and the rail's
    /// tangent at `i` (`rail_tan`) and the wheel's updated by each step, in
    /// their first `W` slots ([`RollContext::tangent_width`]).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn contact_tangent<const W: usize>(
        &self,
        st: &mut WheelRoll,
        track: &mut TrackState,
        rail_tan: &mut [Tangent],
        observed: &mut Observed,
        d_m: &[f64],
        revolution: &[f64],
        timeline: &WeatherTimeline,
        i: usize,
    ) -> f64 {
        let mut touch = self.touch(track, d_m, timeline, i);
        let dr = &mut rail_tan[i];
        if touch.aged {
            let exps = self
                .time_effects
                .exp_args(touch.dt_s, touch.rain_mm)
                .map(f64::exp);
            self.age_tangent::<W>(st, &mut touch, dr, exps);
        }
        self.touched(track, &touch, i);
        let conditions = self.conditions(st, &touch, revolution, i);
        let exps = product::roll_exp_args(&self.params, st.wheel_kg, touch.rail_kg).map(f64::exp);
        let effect = self.effect_tangents_of::<W>(st, &touch, revolution, i);
        let given = (&conditions, effect);
        self.finish_tangent::<W>(true, st, track, dr, observed, touch.rail_kg, given, exps, i)
    }

    /// [`Roller::age`] with the rail mass's tangent `dr`: the time effects
    /// multiply the mass, and its tangent alike.
    #[inline(always)]
    fn age_tangent<const W: usize>(
        &self,
        st: &mut WheelRoll,
        touch: &mut Touch<'_>,
        dr: &mut Tangent,
        exps: [f64; 2],
    ) {
        let rain_mm = touch.rain_mm;
        self.age(st, touch, exps);
        for x in dr.iter_mut().take(W) {
            *x = self.time_effects.apply_given(*x, rain_mm, exps);
        }
        if W <= tangent::STATE_SLOTS {
            return;
        }
        time_effect_sources(
            &self.effect_params,
            &self.time_effects,
            touch.rail_kg,
            (touch.dt_s, rain_mm),
            dr,
        );
    }

    /// [`Roller::finish`] with the tangents (`dr`: the rail mass's after
    /// step 1, in its place in the track's tangents, stepped there), the
    /// rail mass after step 1, the effect tangents of the conditions
    /// ([`Roller::effect_tangents_of`]) and the exponentials given.
    /// `seen`: keep the step-2 mass's tangent (`WheelRoll::seen_tan`, what
    /// a site's measurement of this contact reads).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn finish_tangent<const W: usize>(
        &self,
        seen: bool,
        st: &mut WheelRoll,
        track: &mut TrackState,
        dr: &mut Tangent,
        observed: &mut Observed,
        mut rail_kg: f64,
        (conditions, effect): (&ContactConditions, EffectTangents),
        exps: [f64; 2],
        i: usize,
    ) -> f64 {
        let (transfer_effect, consumption_effect) = effect;
        let tangents = ConditionTangents {
            fp_fc: self.fp_fc_tan,
            transfer_revolution: match (conditions.transfer_revolution, st.applicator_point) {
                (Some(r), Some(ia)) => tangent::revolution_tangent(&self.params, r, i.abs_diff(ia)),
                _ => 0.0,
            },
            transfer_effect,
            consumption_effect,
        };
        let m_kg = st.wheel_kg + rail_kg;
        if seen {
            st.seen_tan = tangent::add(&st.wheel_tan, dr);
        }
        let losses = tangent::roll_given::<W>(
            &self.params,
            &mut st.wheel_kg,
            &mut rail_kg,
            conditions,
            &tangents,
            (&mut st.wheel_tan, dr),
            exps,
        );
        st.consumed_kg += losses.consumed_kg;
        st.capped_kg += losses.capped_kg;
        if let Some((alpha, r)) = self.reservoir {
            let (w, e) = (st.wheel_kg, st.edge_kg);
            (st.wheel_kg, st.edge_kg) = effects::wheel_edge_reservoir(w, e, alpha, r);
            for k in 0..W {
                (st.wheel_tan[k], st.edge_tan[k]) =
                    effects::wheel_edge_reservoir(st.wheel_tan[k], st.edge_tan[k], alpha, r);
            }
            // Its own parameters: wheel' = w (1 - alpha + r alpha) + r e,
            // edge' = (e + alpha w) (1 - r).
            for (k, p) in self.effect_params.iter().enumerate() {
                let (dw, de) = match *p {
                    Some(EffectParam::Named {
                        effect: Named::WheelEdgeReservoir,
                        param: 0,
                    }) => (w * (r - 1.0), w * (1.0 - r)),
                    Some(EffectParam::Named {
                        effect: Named::WheelEdgeReservoir,
                        param: 1,
                    }) => (e + alpha * w, -(e + alpha * w)),
                    _ => continue,
                };
                st.wheel_tan[effect_slot(k)] += dw;
                st.edge_tan[effect_slot(k)] += de;
            }
        }
        track.rail_mass_kg[i] = rail_kg;
        if self.observe {
            observed.mass_kg[i] = m_kg;
            observed.wheel_mass_kg[i] = st.wheel_kg;
        }
        m_kg
    }

    /// Step 1, what it reads: the time, the weather, the rail mass and the
    /// time since the point's last touch.
    #[inline(always)]
    fn touch<'w>(
        &self,
        track: &TrackState,
        d_m: &[f64],
        timeline: &'w WeatherTimeline,
        i: usize,
    ) -> Touch<'w> {
        let t = self.time_at(d_m, i);
        let weather = timeline.at(t);
        self.touch_at(track, t, weather, weather.precip_mm_at(t), i)
    }

    /// Step 1's reads at point i, given the wheel's time there, the weather
    /// in effect and the precipitation accumulated by then.
    #[inline(always)]
    fn touch_at<'w>(
        &self,
        track: &TrackState,
        t: f64,
        weather: &'w super::weather::WeatherState,
        precip_mm: f64,
        i: usize,
    ) -> Touch<'w> {
        let last = track.last_touch_s[i];
        Touch {
            t,
            weather,
            precip_mm,
            rail_kg: track.rail_mass_kg[i],
            aged: self.ages && !last.is_nan(),
            dt_s: t - last,
            rain_mm: precip_mm - track.precip_at_touch_mm[i],
        }
    }

    /// Step 1, the time effects since the last touch (`touch.aged`), their
    /// exponentials given.
    #[inline(always)]
    fn age(&self, st: &mut WheelRoll, touch: &mut Touch<'_>, exps: [f64; 2]) {
        let aged = self
            .time_effects
            .apply_given(touch.rail_kg, touch.rain_mm, exps);
        st.lost_kg += touch.rail_kg - aged;
        touch.rail_kg = aged;
    }

    /// Step 1, the touch.
    #[inline(always)]
    fn touched(&self, track: &mut TrackState, touch: &Touch<'_>, i: usize) {
        track.last_touch_s[i] = touch.t;
        track.precip_at_touch_mm[i] = touch.precip_mm;
    }

    /// Steps 3 to 5, what they need besides the masses. Effect factors: the
    /// named effect's first, then the generic terms'.
    #[inline(always)]
    fn conditions(
        &self,
        st: &WheelRoll,
        touch: &Touch<'_>,
        revolution: &[f64],
        i: usize,
    ) -> ContactConditions {
        let (t, weather) = (touch.t, touch.weather);
        let mut transfer_factor = self.transfer_factor;
        if self.transfer_varies {
            transfer_factor *= self.event_factor(ActsOn::Transfer, t, weather);
        }
        let consumption_factor = match self.consumption_constant {
            Some(constant) => constant,
            None => self.consumption_factor(t, weather),
        };
        self.conditions_given(st, (transfer_factor, consumption_factor), revolution, i)
    }

    /// [`Roller::conditions`] given the contact's transfer and consumption
    /// factors.
    #[inline(always)]
    fn conditions_given(
        &self,
        st: &WheelRoll,
        (transfer_factor, consumption_factor): (f64, f64),
        revolution: &[f64],
        i: usize,
    ) -> ContactConditions {
        ContactConditions {
            fp_fc: self.fp_fc,
            transfer_revolution: st
                .applicator_point
                .map(|ia| revolution[i.abs_diff(ia)] * transfer_factor),
            consumption_factor,
        }
    }

    /// The transfer and consumption factors of every contact of this wheel
    /// when no contact needs its time: no time effect is on, and neither
    /// the time nor the weather moves the two factors. `None` otherwise.
    fn clock_free(&self) -> Option<(f64, f64)> {
        match self.consumption_constant {
            Some(consumption) if !self.ages && !self.transfer_varies => {
                Some((self.transfer_factor, consumption))
            }
            _ => None,
        }
    }

    /// The consumption's effect factor at a contact at `t` under
    /// `weather`: temperature_consumption's, then the generic terms'
    /// driven by the wheel and by time or weather.
    #[inline(always)]
    fn consumption_factor(&self, t: f64, weather: &super::weather::WeatherState) -> f64 {
        let mut factor = match (self.temperature_factor, self.temperature_beta) {
            (Some(constant), _) => constant,
            (None, Some(beta)) => {
                effects::temperature_factor(weather.current.air_temperature_c, beta)
            }
            (None, None) => 1.0,
        } * self.consumption_generic;
        if self.consumption_varies {
            factor *= self.event_factor(ActsOn::Consumption, t, weather);
        }
        factor
    }

    /// Step 2 (what a measurement of this contact sees, returned), steps 3
    /// to 5 (transfer, consumption, cap; their exponentials taken here) and
    /// 6 (wheel-side effects), for one contact alone.
    #[inline(always)]
    fn finish(
        &self,
        st: &mut WheelRoll,
        track: &mut TrackState,
        observed: &mut Observed,
        touch: &Touch<'_>,
        conditions: &ContactConditions,
        i: usize,
    ) -> f64 {
        let mut wheel_kg = st.wheel_kg;
        let mut rail_kg = touch.rail_kg;
        let m_kg = wheel_kg + rail_kg;
        let losses = product::roll(&self.params, &mut wheel_kg, &mut rail_kg, conditions);
        self.rolled(st, track, observed, m_kg, (wheel_kg, rail_kg), losses, i)
    }

    /// What follows steps 3 to 5 (their masses and losses given): the
    /// losses to the wheel's totals, step 6 (wheel-side effects), the rail
    /// mass stored and what is observed; returns `m_kg`, the step-2 mass.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn rolled(
        &self,
        st: &mut WheelRoll,
        track: &mut TrackState,
        observed: &mut Observed,
        m_kg: f64,
        (wheel_kg, rail_kg): (f64, f64),
        losses: ContactLosses,
        i: usize,
    ) -> f64 {
        st.wheel_kg = wheel_kg;
        st.consumed_kg += losses.consumed_kg;
        st.capped_kg += losses.capped_kg;
        if let Some((alpha, r)) = self.reservoir {
            (st.wheel_kg, st.edge_kg) =
                effects::wheel_edge_reservoir(st.wheel_kg, st.edge_kg, alpha, r);
        }
        track.rail_mass_kg[i] = rail_kg;
        if self.observe {
            observed.mass_kg[i] = m_kg;
            observed.wheel_mass_kg[i] = st.wheel_kg;
        }
        m_kg
    }
}

/// The four lanes' clocks ([`wheel_time_s`]'s constants of each wheel),
/// gathered once per group for the vector division of every step.
#[derive(Clone, Copy)]
struct Clocks {
    t_passage_s: [f64; LANES],
    offset_m: [f64; LANES],
    speed_mps: [f64; LANES],
    d_entry_m: [f64; LANES],
}

impl Clocks {
    fn of(lanes: &[Lane; LANES]) -> Self {
        let r = |j: usize| &lanes[j].roller;
        Self {
            t_passage_s: std::array::from_fn(|j| r(j).t_passage_s),
            offset_m: std::array::from_fn(|j| r(j).offset_m),
            speed_mps: std::array::from_fn(|j| r(j).speed_mps),
            d_entry_m: std::array::from_fn(|j| r(j).d_entry_m),
        }
    }
}

/// The derivatives of a contact's transfer and consumption factors in the
/// effect parameters followed ([`Roller::effect_tangents`]).
type EffectTangents = ([f64; EFFECT_SLOTS], [f64; EFFECT_SLOTS]);

/// What step 1 of a contact read.
struct Touch<'w> {
    t: f64,
    weather: &'w super::weather::WeatherState,
    precip_mm: f64,
    rail_kg: f64,
    /// Whether the time effects act: one is on and the point was touched.
    aged: bool,
    dt_s: f64,
    rain_mm: f64,
}

impl Roller {
    /// [`Roller::effect_tangents`] where the tangents have effect slots
    /// (`W` beyond the state's), zeros otherwise.
    #[inline(always)]
    fn effect_tangents_of<const W: usize>(
        &self,
        st: &WheelRoll,
        touch: &Touch<'_>,
        revolution: &[f64],
        i: usize,
    ) -> EffectTangents {
        match W > tangent::STATE_SLOTS {
            true => self.effect_tangents(st, touch, revolution, i),
            false => Default::default(),
        }
    }

    /// The derivatives of a contact's transfer factor (with the revolution
    /// decay, as `ContactConditions::transfer_revolution`) and consumption
    /// factor in the effect parameters followed
    /// ([`ConditionTangents::transfer_effect`], `consumption_effect`).
    #[inline(never)]
    fn effect_tangents(
        &self,
        st: &WheelRoll,
        touch: &Touch<'_>,
        revolution: &[f64],
        i: usize,
    ) -> EffectTangents {
        let mut transfer = [0.0; EFFECT_SLOTS];
        let mut consumption = [0.0; EFFECT_SLOTS];
        let (t, weather) = (touch.t, touch.weather);
        let at = When {
            time_s: t,
            weather: &weather.current,
            wheel: None,
        };
        for (k, p) in self.effect_params.iter().enumerate() {
            // The time effects and the reservoir act elsewhere.
            let p = match *p {
                None
                | Some(EffectParam::Named {
                    effect: Named::RailAgeing | Named::RainWashoff | Named::WheelEdgeReservoir,
                    ..
                }) => continue,
                Some(p) => p,
            };
            // The time- and weather-driven factors and their derivatives.
            let event = |acts_on, varies: bool| match (p, varies) {
                (_, false) => (1.0, 0.0),
                (EffectParam::Generic { term }, true) => self.generic.factor_and_derivative(
                    acts_on,
                    Which::Event,
                    None,
                    self.rail,
                    at,
                    term,
                ),
                (_, true) => (self.event_factor(acts_on, t, weather), 0.0),
            };
            if let Some(ia) = st.applicator_point {
                let (g, dg) = event(ActsOn::Transfer, self.transfer_varies);
                let d = self.transfer_factor_d[k] * g + self.transfer_factor * dg;
                transfer[k] = revolution[i.abs_diff(ia)] * d;
            }
            let on_temperature = p
                == EffectParam::Named {
                    effect: Named::TemperatureConsumption,
                    param: 0,
                };
            // exp(beta (T - 20)) and its derivative in beta.
            let (temp, d_temp) = match (self.temperature_factor, self.temperature_beta) {
                (Some(f), _) => (f, (self.temperature_c - 20.0) * f),
                (None, Some(beta)) => {
                    let c = weather.current.air_temperature_c;
                    let f = effects::temperature_factor(c, beta);
                    (f, (c - 20.0) * f)
                }
                (None, None) => (1.0, 0.0),
            };
            let d_temp = if on_temperature { d_temp } else { 0.0 };
            let (g, dg) = event(ActsOn::Consumption, self.consumption_varies);
            let cg = self.consumption_generic;
            consumption[k] =
                d_temp * cg * g + temp * self.consumption_generic_d[k] * g + temp * cg * dg;
        }
        (transfer, consumption)
    }

    /// The generic terms on `acts_on` driven by time or weather, at a
    /// contact at `t_s`.
    #[inline(never)]
    fn event_factor(
        &self,
        acts_on: ActsOn,
        t_s: f64,
        weather: &super::weather::WeatherState,
    ) -> f64 {
        self.generic.factor(
            acts_on,
            Which::Event,
            None,
            self.rail,
            When {
                time_s: t_s,
                weather: &weather.current,
                wheel: None,
            },
        )
    }
}

/// Four lanes' exponentials (bit for bit `f64::exp`).
trait Exp4: Fn([f64; LANES]) -> [f64; LANES] + Copy {}
impl<F: Fn([f64; LANES]) -> [f64; LANES] + Copy> Exp4 for F {}

/// Four lanes' quotients `a / b`.
trait Div4: Fn([f64; LANES], [f64; LANES]) -> [f64; LANES] + Copy {}
impl<F: Fn([f64; LANES], [f64; LANES]) -> [f64; LANES] + Copy> Div4 for F {}

/// Four lanes' steps 3 to 5, exponentials included ([`product::roll4`]).
trait Roll4:
    Fn(
        &ProductParams,
        ([f64; LANES], [f64; LANES]),
        &[ContactConditions; LANES],
    ) -> ([f64; LANES], [f64; LANES], [ContactLosses; LANES])
    + Copy
{
}
impl<F> Roll4 for F where
    F: Fn(
            &ProductParams,
            ([f64; LANES], [f64; LANES]),
            &[ContactConditions; LANES],
        ) -> ([f64; LANES], [f64; LANES], [ContactLosses; LANES])
        + Copy
{
}

/// Runs of steps in registers ([`RollContext::runs_fma`]): given one or
/// two groups' lanes (of different tracks), the first step and the step to
/// stop before, returns the first step it did not take.
trait Run4: Fn(&RollContext<'_>, &mut [RunPart<'_>], usize, usize) -> usize + Copy {}
impl<F> Run4 for F where F: Fn(&RollContext<'_>, &mut [RunPart<'_>], usize, usize) -> usize + Copy {}

/// Wheels in a wavefront of two groups ([`RunPart`] with `G` = 2).
const DEEP: usize = 2 * LANES;

/// A wavefront's part in a run of steps ([`RollContext::run_lanes`]): `G`
/// consecutive groups of one track (one in [`RunLanes`], two in
/// [`RunDeep`]) as one wavefront of `G` x [`LANES`] wheels, lane j at step
/// s - j of its path (a second group four steps behind the first, so that
/// its lane 0 reads what the first's lane 3 left, as lane j + 1 reads what
/// lane j left).
struct RunPart<'s, const G: usize = 1> {
    record: &'s TrainRecord,
    track: usize,
    groups: [&'s mut [Lane; LANES]; G],
    state: &'s mut TrackState,
    work: &'s mut TrackWork,
    special: &'s [bool],
    up: bool,
    /// Each lane's constant transfer and consumption factors
    /// ([`Roller::clock_free`]); the first `G` x [`LANES`] used.
    factors: [(f64, f64); DEEP],
}

/// The point of a track of `points` points a wheel is at after `step`
/// steps of its path: it enters at 0 going up, at the last point going
/// down.
#[inline(always)]
fn point_of(up: bool, points: usize, step: usize) -> usize {
    match up {
        true => step,
        false => points - 1 - step,
    }
}

/// The points of a wavefront's four lanes at step `s` (lane j at step
/// s - j of its path), all four on the track.
#[inline(always)]
fn lane_points(up: bool, points: usize, s: usize) -> [usize; LANES] {
    std::array::from_fn(|j| point_of(up, points, s - j))
}

impl<const G: usize> RunPart<'_, G> {
    /// The wavefront's lanes.
    const N: usize = G * LANES;

    #[inline(always)]
    fn lane(&self, j: usize) -> &Lane {
        &self.groups[j / LANES][j % LANES]
    }

    #[inline(always)]
    fn lane_mut(&mut self, j: usize) -> &mut Lane {
        &mut self.groups[j / LANES][j % LANES]
    }

    /// The lanes' points at step `s` (0 past the last lane).
    #[inline(always)]
    fn at(&self, s: usize) -> [usize; DEEP] {
        let points = self.special.len();
        std::array::from_fn(|j| match j < Self::N {
            true => point_of(self.up, points, s - j),
            false => 0,
        })
    }

    /// Whether a lane is at a special point at step `s`.
    #[inline(always)]
    fn special_at(&self, s: usize) -> bool {
        self.at(s)[..Self::N].iter().any(|&i| self.special[i])
    }

    /// The first step from `s` on at which a lane is at a special point
    /// (`usize::MAX` if no lane reaches one).
    #[inline(always)]
    fn special_from(&self, s: usize) -> usize {
        match self.special_at(s) {
            true => s,
            false => self.next_special(s),
        }
    }

    /// The first step after `s` at which a lane is at a special point,
    /// none being at `s` (`usize::MAX` if no lane reaches one). Lane 0
    /// leads and the others follow it over the points it passed, none of
    /// them special between the last lane's and lane 0's at `s`: it is the step at
    /// which lane 0 reaches the next special point ahead of it.
    #[inline(always)]
    fn next_special(&self, s: usize) -> usize {
        let lead = self.at(s)[0];
        let ahead = match self.up {
            true => self.special[lead + 1..].iter().position(|&b| b),
            false => self.special[..lead].iter().rev().position(|&b| b),
        };
        ahead.map_or(usize::MAX, |k| s + 1 + k)
    }
}

/// What the wavefront computes four lanes at once.
#[derive(Clone, Copy)]
struct Vector<E, D, R, U> {
    exp: E,
    div: D,
    roll: R,
    /// Runs of steps in registers; `None` where the kernel has no such path
    /// (the portable kernel, the line's).
    run: Option<U>,
}

/// The type of [`Vector::run`] where there is none.
type NoRun = fn(&RollContext<'_>, &mut [RunPart<'_>], usize, usize) -> usize;

/// Four quotients in one AVX register.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn div4_avx(a: [f64; LANES], b: [f64; LANES]) -> [f64; LANES] {
    use std::arch::x86_64::{_mm256_div_pd, _mm256_loadu_pd, _mm256_storeu_pd};
    let mut q = [0.0; LANES];
    // SAFETY: four f64 read from and written to arrays of four.
    unsafe {
        let v = _mm256_div_pd(_mm256_loadu_pd(a.as_ptr()), _mm256_loadu_pd(b.as_ptr()));
        _mm256_storeu_pd(q.as_mut_ptr(), v);
    }
    q
}

/// The time effects' own parameters among those followed: `aged` is the
/// mass after them, `tan` its tangent (the multiplications done), `(dt_s,
/// rain_mm)` what they acted over. `m exp(-dt / tau)`: `∂/∂tau = aged dt /
/// tau²`; `m exp(-k R)`: `∂/∂k = -aged R`.
#[inline]
fn time_effect_sources(
    params: &[Option<EffectParam>; EFFECT_SLOTS],
    effects: &TimeEffects,
    aged: f64,
    (dt_s, rain_mm): (f64, f64),
    tan: &mut Tangent,
) {
    for (k, p) in params.iter().enumerate() {
        let source = match (*p, effects.ageing_tau_s, effects.rain_k_per_mm) {
            (
                Some(EffectParam::Named {
                    effect: Named::RailAgeing,
                    param: 0,
                }),
                Some(tau),
                _,
            ) => aged * dt_s / (tau * tau),
            (
                Some(EffectParam::Named {
                    effect: Named::RainWashoff,
                    param: 0,
                }),
                _,
                Some(_),
            ) if rain_mm != 0.0 => -aged * rain_mm,
            _ => continue,
        };
        tan[effect_slot(k)] += source;
    }
}

/// A wheel's time at a point: `t_passage + (|d - d_entry| + offset) / v`
/// (model.md, computed in that form).
#[inline(always)]
fn wheel_time_s(t_passage_s: f64, d_m: f64, d_entry_m: f64, offset_m: f64, speed_mps: f64) -> f64 {
    t_passage_s + wheel_path_m(d_m, d_entry_m, offset_m) / speed_mps
}

/// The four lanes' [`Roller::clock_free`] factors, when every lane has them.
fn clock_free(lanes: &[Lane; LANES]) -> Option<[(f64, f64); LANES]> {
    let mut factors = [(0.0, 0.0); LANES];
    for (f, lane) in factors.iter_mut().zip(lanes) {
        *f = lane.roller.clock_free()?;
    }
    Some(factors)
}

/// How far a wheel has come to reach a point: `|d - d_entry| + offset`.
#[inline(always)]
fn wheel_path_m(d_m: f64, d_entry_m: f64, offset_m: f64) -> f64 {
    (d_m - d_entry_m).abs() + offset_m
}

/// Reused buffers for the field snapshots.
#[derive(Debug, Clone, Default)]
pub(crate) struct SnapshotBuffers {
    mu: Vec<f64>,
    /// mu of every contact of one wheel, for [`WheelContacts::mu`].
    contact_mu: Vec<f64>,
    adhesion: Vec<f64>,
    wheel_mass_kg: Vec<f64>,
}

/// How many wheels of one track roll at once, as a wavefront: wheel k+1 at
/// point i while wheel k is at the next point of the path. Each wheel's
/// contacts depend on the one before through the wheel's own mass, a chain
/// of exponentials; interleaving the wheels lets the core overlap the
/// chains. Every contact computes exactly what it computes alone.
const LANES: usize = 4;

/// Rolling the tracks on several threads pays only when a train has this
/// many contacts on each (a thread's start is a few microseconds).
const PARALLEL_MIN_CONTACTS: usize = 4096;

/// [`PARALLEL_MIN_CONTACTS`] for a replay whose output threads take the
/// second core ([`crate::EngineOptions::beside_output_threads`]).
const PARALLEL_MIN_CONTACTS_BESIDE_OUTPUTS: usize = 1 << 17;

/// Whether rayon's pool has a thread besides this one for a train's
/// tracks, the command line's pool joined first where a replay deferred
/// it ([`tortwin_handover::pool`]).
pub(crate) fn pool_has_threads() -> bool {
    tortwin_handover::pool::before_pool_use();
    rayon::current_num_threads() > 1
}

/// The contacts a track must have in a train for the tracks to roll in
/// parallel.
fn parallel_min_contacts(opts: &crate::EngineOptions) -> usize {
    match opts.beside_output_threads {
        true => PARALLEL_MIN_CONTACTS_BESIDE_OUTPUTS,
        false => PARALLEL_MIN_CONTACTS,
    }
}

/// What one track's roll changes besides its [`TrackState`]: the track's
/// point events, and what the roll reports back to the
/// engine (settled in the serial order by [`Engine::settle`]). Each track
/// owns one, so that tracks can be rolled at once.
#[derive(Debug, Clone)]
pub(crate) struct TrackWork {
    /// The pulses and readings of the window on this track.
    pub(crate) events: Vec<PointEvent>,
    /// Per point: no later than the earliest time of `events` still to run
    /// there (infinite where none is). Exact after a wheel's look at the
    /// point ([`RollContext::run_events_before`]); an event run otherwise
    /// leaves it earlier, which only costs the next wheel a look.
    next_at: Vec<f64>,
    /// Per point, a chain of its events in the window's order: the first
    /// not known to have run ([`NO_EVENT`] where none is), the last, and
    /// per event the next at its point; whether the chain's times never
    /// fall. A wheel due at a point follows that point's chain only, from
    /// its first event still to run, and in time order stops at the first
    /// not yet due: a point where pulses come between a train's wheels is
    /// looked at once per pulse, not once per event of the window.
    first_event: Vec<usize>,
    last_event: Vec<usize>,
    next_event: Vec<usize>,
    in_time_order: Vec<bool>,
    /// What the last wheel (or every wheel) saw.
    pub(crate) observed: Observed,
    /// This train's axles whose wheel runs on this track, in order.
    axles: Vec<usize>,
    /// The roll's contributions to the run totals, to be added in the
    /// serial order (floating-point sums depend on their order).
    ledger: Vec<Addend>,
    /// Tribometer readings taken, by their window index.
    readings: Vec<(usize, Reading)>,
    /// Contacts at measurement sites.
    sites: Vec<SiteValue>,
    /// When a sink wants every wheel's contacts: the step-2 mass of every
    /// contact of this train's wheels on this track, a row of points per
    /// wheel in axle order (handed to the sink in the serial order after
    /// the roll).
    wheel_seen: Vec<f64>,
    /// With tangents ([`crate::EngineOptions::tangents`]): the tangent of
    /// the rail mass at every point (else empty).
    pub(crate) rail_tan: Vec<Tangent>,
    /// On a line with [`crate::EngineOptions::line_axle`], in the rail's
    /// crown track: what the two watched axles saw (else empty).
    pub(crate) watched: Watched,
    /// The lanes of the track's wavefronts, between two groups.
    wave_lanes: WaveLanes,
}

/// The end of a point's chain of events in [`TrackWork`].
const NO_EVENT: usize = usize::MAX;

/// What two chosen axles of a train saw along a rail of a line
/// ([`crate::sink::LineWheels`]).
#[derive(Debug, Clone, Default)]
pub(crate) struct Watched {
    /// Each axle's step-2 mass at every point.
    pub(crate) seen_kg: [Vec<f64>; 2],
    /// The first axle's tread bands F, C, G after its contact at every point.
    pub(crate) bands_kg: [Vec<f64>; 3],
}

/// A tribometer reading's simulated value, the rail mass it read and that
/// mass's tangent (zero without tangents).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Reading {
    pub(crate) value: f64,
    pub(crate) mass_kg: f64,
    pub(crate) tangent: Tangent,
}

impl TrackWork {
    /// Adds a pulse or reading of the window.
    pub(crate) fn push_event(&mut self, event: PointEvent) {
        let i = event.point;
        let at = &mut self.next_at[i];
        *at = at.min(event.time_s);
        let k = self.events.len();
        if self.first_event[i] == NO_EVENT {
            self.first_event[i] = k;
        }
        let last = self.last_event[i];
        if last != NO_EVENT {
            self.next_event[last] = k;
            if event.time_s < self.events[last].time_s {
                self.in_time_order[i] = false;
            }
        }
        self.last_event[i] = k;
        self.next_event.push(NO_EVENT);
        self.events.push(event);
    }

    /// Forgets the window's events, for the next train's.
    pub(crate) fn clear_events(&mut self) {
        for event in &self.events {
            let i = event.point;
            self.next_at[i] = f64::INFINITY;
            self.first_event[i] = NO_EVENT;
            self.last_event[i] = NO_EVENT;
            self.in_time_order[i] = true;
        }
        self.events.clear();
        self.next_event.clear();
    }

    pub(crate) fn new(points: usize) -> Self {
        Self {
            events: Vec::new(),
            next_at: vec![f64::INFINITY; points],
            first_event: vec![NO_EVENT; points],
            last_event: vec![NO_EVENT; points],
            next_event: Vec::new(),
            in_time_order: vec![true; points],
            observed: Observed::new(points),
            axles: Vec::new(),
            ledger: Vec::new(),
            readings: Vec::new(),
            sites: Vec::new(),
            wheel_seen: Vec::new(),
            rail_tan: Vec::new(),
            watched: Watched::default(),
            wave_lanes: WaveLanes::default(),
        }
    }
}

/// A wavefront's lanes, kept from one group of wheels to the next so that
/// each group's are made in their place: a lane is 776 bytes, and made in
/// an array and moved into the wavefront they were copied three to four
/// times (on the 3-day curve, callgrind: memcpy 5.0 % of the engine
/// thread's instructions before, 2.4 % after).
/// Two of them: a wavefront of eight wheels is two groups' ([`RunPart`]).
#[derive(Clone, Default)]
pub(crate) struct WaveLanes([Option<Box<[Lane; LANES]>>; 2]);

impl std::fmt::Debug for WaveLanes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("WaveLanes")
    }
}

/// A contact at a measurement site: [`TrainRecord::site_mass_kg`]'s index,
/// its step-2 mass and, with friction terms, muD and muC there.
#[derive(Debug, Clone, Copy)]
struct SiteValue {
    index: usize,
    mass_kg: f64,
    levels: Option<(f64, f64)>,
    /// The contact's time_s and weather (what a read-out needs).
    time_s: f64,
    weather: tortwin_recording::Weather,
    /// The step-2 mass's tangent (zero without tangents).
    tangent: Tangent,
}

/// One addition to the run totals, with its place in the serial order:
/// `(axle * rails + rail) << 32 | k`, k counting the pulses landed during
/// that wheel's roll and `u32::MAX` for the wheel's own totals at its end.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Addend {
    order: u64,
    kind: AddendKind,
}

#[derive(Debug, Clone, Copy)]
enum AddendKind {
    Pulse(PulseTotals),
    Wheel {
        contacts: u64,
        consumed_kg: f64,
        capped_kg: f64,
        lost_kg: f64,
        carried_kg: f64,
    },
}

/// What landing one pulse adds to the totals.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PulseTotals {
    /// What the time effects took since the point's last touch (none where
    /// there are no time effects or the point was never touched).
    pub(crate) lost_kg: Option<f64>,
    pub(crate) applied_kg: f64,
    pub(crate) capped_kg: f64,
}

impl Totals {
    pub(crate) fn add_pulse(&mut self, p: &PulseTotals) {
        if let Some(lost) = p.lost_kg {
            self.effects_lost_kg += lost;
        }
        self.applied_kg += p.applied_kg;
        self.capped_kg += p.capped_kg;
    }

    fn add(&mut self, addend: &Addend) {
        match addend.kind {
            AddendKind::Pulse(p) => self.add_pulse(&p),
            AddendKind::Wheel {
                contacts,
                consumed_kg,
                capped_kg,
                lost_kg,
                carried_kg,
            } => {
                self.wheels += 1;
                self.contacts += contacts;
                self.consumed_kg += consumed_kg;
                self.capped_kg += capped_kg;
                self.effects_lost_kg += lost_kg;
                self.carried_out_kg += carried_kg;
            }
        }
    }
}

/// What a point event did, for the engine to take in.
pub(crate) enum Ran {
    Pulse(PulseTotals),
    Reading,
}

/// Everything a roll reads and no roll changes: borrowed from the engine
/// beside the per-track state, so that tracks can be rolled at once.
pub(crate) struct RollContext<'a> {
    pub(crate) product: &'a ProductParams,
    effects: &'a tortwin_model::config::Effects,
    section: &'a Section,
    d_m: &'a [f64],
    revolution: &'a [f64],
    pub(crate) timeline: &'a WeatherTimeline,
    time_effects: TimeEffects,
    generic: &'a Arc<GenericSet>,
    track_info: &'a [TrackInfo],
    applicator_at: &'a [Vec<u32>],
    special: &'a [Vec<bool>],
    sites_at: &'a [Vec<usize>],
    last_axle: &'a [usize],
    /// Every wheel fills the track's [`Observed`] (a snapshot after every
    /// wheel), not only the train's last on it.
    observe_every_wheel: bool,
    /// Keep every wheel's step-2 masses in [`TrackWork::wheel_seen`].
    keep_seen: bool,
    /// On a line: the axles whose contacts go to [`TrackWork::watched`]
    /// (`usize::MAX`: none).
    watch: [usize; 2],
    /// On a line: the train's last leading and last trailing axle
    /// (`usize::MAX`: none), the only wheels that can be the last to use a
    /// rail band at a point (the rows depend on the point and the bogie
    /// position alone): they alone fill [`Observed`].
    observers: [usize; 2],
    /// The effect parameters the tangents' effect slots follow.
    effect_params: [Option<EffectParam>; EFFECT_SLOTS],
    /// How many of a tangent's slots the contacts step: 0 without tangents
    /// ([`crate::EngineOptions::tangents`]), the constants' alone when no
    /// effect slot is followed, else all. The slots past it stay zero.
    tangent_width: usize,
    /// Never the vector kernel ([`crate::EngineOptions::portable_kernel`]).
    portable: bool,
    /// Two consecutive groups of a track as one wavefront of eight wheels
    /// whose runs of steps take AVX-512 registers ([`RunDeep`]): the CPU
    /// has AVX-512F, and neither [`crate::EngineOptions::portable_kernel`]
    /// nor [`crate::EngineOptions::narrow_kernel`] is asked for.
    deep: bool,
    origin_ns: i64,
    /// On a line: its layout.
    line: Option<&'a crate::line::LineLayout>,
}

/// Consecutive wheels of one track (at most [`LANES`]), rolled together.
#[derive(Clone, Copy)]
struct Group<'a> {
    record: &'a TrainRecord,
    track: usize,
    axles: &'a [usize],
    /// The first wheel's row in [`TrackWork::wheel_seen`].
    first_row: usize,
}

/// One group's wavefront in progress ([`RollContext::roll_group_with`]).
struct Wave<'r> {
    record: &'r TrainRecord,
    track: usize,
    /// Wheels in the group, 1 to [`LANES`].
    n: usize,
    up: bool,
    /// The group holds the train's last wheel on the track.
    last: bool,
    lanes: Box<[Lane; LANES]>,
    clocks: Clocks,
    clock_free: Option<[(f64, f64); LANES]>,
    /// The lanes' constant factors where runs of steps in registers may take
    /// their steps ([`RollContext::runs`]).
    runs: Option<[(f64, f64); LANES]>,
    /// Where in [`TrackWork`]'s [`WaveLanes`] its lanes go back.
    slot: usize,
}

/// A wheel in the wavefront.
#[derive(Clone)]
struct Lane {
    axle: usize,
    /// Its row in [`TrackWork::wheel_seen`]: its place among the train's
    /// wheels on this track.
    row: usize,
    /// Its place in the serial order: axle * rails + rail.
    serial: u64,
    /// Pulses landed during its roll so far.
    pulses: u64,
    st: WheelRoll,
    roller: Roller,
}

/// One group's lanes in a run of steps ([`RollContext::runs_fma`]), in AVX
/// registers: what the lanes carry from one step to the next (the wheels'
/// masses and loss totals, the rail mass each lane leaves for the next
/// lane, which reads that point at the next step) and the conditions' parts
/// that change only where a special point's events act (whether and where
/// the wheel passed an applicator, its factors).
/// Of the rail masses left, only the last lane's is stored at each step
/// (no lane of the group reads its point again); the others' when the run
/// ends.
#[cfg(target_arch = "x86_64")]
struct RunLanes {
    observe: [bool; LANES],
    /// Whether a lane observes (`observe` has one), found once.
    observing: bool,
    /// Each lane's distance from the applicator it passed last (0 where it
    /// passed none), its index in the revolution factors, and how that
    /// changes from one step to the next (+1 where it passed one: a wheel
    /// moves away from it; passing another is a special step, after which
    /// the run takes its lanes up again).
    revolution_at: std::arch::x86_64::__m256i,
    revolution_step: std::arch::x86_64::__m256i,
    transfer_factor: std::arch::x86_64::__m256d,
    transfers: std::arch::x86_64::__m256d,
    factor: std::arch::x86_64::__m256d,
    fp_fc: std::arch::x86_64::__m256d,
    wheel: std::arch::x86_64::__m256d,
    consumed: std::arch::x86_64::__m256d,
    capped: std::arch::x86_64::__m256d,
    /// The rail masses the lanes read at this step, at the lanes' points.
    rail: std::arch::x86_64::__m256d,
    /// The point of lane 0 (which reads a new point at each step; lane j
    /// is j points behind it, [`Registers::points`]), and how it changes
    /// from one step to the next (+1 going up, -1 wrapped going down): an
    /// addition a step where the four points were worked out anew
    /// ([`RunPart::at`]).
    lead: usize,
    stride: usize,
    /// The rail masses the lanes left at the last step.
    left: std::arch::x86_64::__m256d,
}

/// Four lanes' values as an AVX register, lane 0 first.
macro_rules! lanes_pd {
    (|$j:ident| $e:expr) => {
        std::arch::x86_64::_mm256_setr_pd(
            {
                let $j = 0;
                $e
            },
            {
                let $j = 1;
                $e
            },
            {
                let $j = 2;
                $e
            },
            {
                let $j = 3;
                $e
            },
        )
    };
}

/// An AVX register's four lanes as an array.
macro_rules! store_pd {
    ($v:expr) => {{
        let mut a = [0.0; LANES];
        std::arch::x86_64::_mm256_storeu_pd(a.as_mut_ptr(), $v);
        a
    }};
}

/// Lanes in registers through a run of steps ([`RollContext::run_lanes`]):
/// [`RunLanes`], a wavefront of one group, and [`RunDeep`], of two. What
/// does not depend on the registers' width (the lanes' points, their
/// values back in memory) is said once here.
#[cfg(target_arch = "x86_64")]
trait Registers<const G: usize>: Sized {
    /// The lanes of `part` about to take step `s`.
    unsafe fn start(ctx: &RollContext<'_>, part: &RunPart<'_, G>, s: usize) -> Self;
    /// One step of every lane.
    unsafe fn step(
        &mut self,
        ctx: &RollContext<'_>,
        params: &ProductParams,
        part: &mut RunPart<'_, G>,
    );
    /// To the step after the last.
    unsafe fn advance(&mut self, part: &RunPart<'_, G>);
    /// Lane 0's point, and how it changes from one step to the next.
    fn lead(&self) -> (usize, usize);
    /// Lane `j` passes an applicator at this step: what [`Registers::start`]
    /// makes of a lane whose `applicator_point` is its point (distance 0,
    /// moving away, transferring), taken in place.
    unsafe fn pass_applicator(&mut self, j: usize);
    /// The lanes' registers as arrays (the first `G` x [`LANES`] of each).
    unsafe fn in_memory(&self) -> InMemory;

    /// The lanes' points (lane j follows lane 0 by j points; the first `G`
    /// x [`LANES`]).
    #[inline(always)]
    fn points(&self) -> [usize; DEEP] {
        let (lead, stride) = self.lead();
        std::array::from_fn(|j| lead.wrapping_add(stride.wrapping_mul(j).wrapping_neg()))
    }

    /// The lanes back in memory before step `s` (after
    /// [`Registers::advance`] to it), for a special point's events to act
    /// on: the rail masses lanes 1 and after are about to read (those the
    /// lane before left at the step before) at their points, and the lanes'
    /// masses and totals in their states. [`Registers::start`] takes them
    /// up again.
    #[inline(always)]
    unsafe fn suspend(&self, part: &mut RunPart<'_, G>) {
        let lanes = self.in_memory();
        let is = self.points();
        let n = RunPart::<'_, G>::N;
        for (&i, &m) in is.iter().zip(&lanes.rail).take(n).skip(1) {
            part.state.rail_mass_kg[i] = m;
        }
        lanes.store(part);
    }

    /// The end of the run after a step: the rail masses the lanes but the
    /// last left (the last lane's is stored at every step), and the lanes'
    /// masses and totals back in their states.
    #[inline(always)]
    unsafe fn finish(&self, part: &mut RunPart<'_, G>) {
        let lanes = self.in_memory();
        let is = self.points();
        let n = RunPart::<'_, G>::N;
        for (&i, &m) in is.iter().zip(&lanes.left).take(n - 1) {
            part.state.rail_mass_kg[i] = m;
        }
        lanes.store(part);
    }

    /// Each lane's wheel and rail mass before the step: the step-2 mass a
    /// site keeps (the first `G` x [`LANES`]).
    #[inline(always)]
    unsafe fn seen(&self) -> [f64; DEEP] {
        let lanes = self.in_memory();
        std::array::from_fn(|j| lanes.wheel[j] + lanes.rail[j])
    }
}

/// [`Registers`]' lanes as arrays, lane 0 first.
#[cfg(target_arch = "x86_64")]
struct InMemory {
    /// The rail masses the lanes read at this step.
    rail: [f64; DEEP],
    /// The rail masses the lanes left at the last step.
    left: [f64; DEEP],
    wheel: [f64; DEEP],
    consumed: [f64; DEEP],
    capped: [f64; DEEP],
}

#[cfg(target_arch = "x86_64")]
impl InMemory {
    /// The lanes' masses and loss totals back in their states.
    #[inline(always)]
    fn store<const G: usize>(&self, part: &mut RunPart<'_, G>) {
        for j in 0..RunPart::<'_, G>::N {
            let st = &mut part.lane_mut(j).st;
            st.wheel_kg = self.wheel[j];
            st.consumed_kg = self.consumed[j];
            st.capped_kg = self.capped[j];
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl Registers<1> for RunLanes {
    /// The lanes of `part` about to take step `s`.
    ///
    /// # Safety
    /// The CPU must have AVX.
    #[inline(always)]
    unsafe fn start(ctx: &RollContext<'_>, part: &RunPart<'_>, s: usize) -> Self {
        use std::arch::x86_64::_mm256_setzero_pd;
        const _: () = assert!(LANES == 4);
        use std::arch::x86_64::_mm256_setr_epi64x;
        let lanes = &*part.groups[0];
        let is = part.at(s);
        let rail_kg = &part.state.rail_mass_kg;
        // The revolution factors are read with a gather, which does not
        // check its indices: every distance on the track is in the table.
        assert!(ctx.revolution.len() >= part.special.len());
        let (at, step): ([i64; LANES], [i64; LANES]) = {
            // A wheel moves away from the applicator it passed last (from
            // its point, where a special step may start a run, on).
            let of = |j: usize| match lanes[j].st.applicator_point {
                Some(ia) => (is[j].abs_diff(ia) as i64, 1),
                None => (0, 0),
            };
            let lane = [of(0), of(1), of(2), of(3)];
            (lane.map(|l| l.0), lane.map(|l| l.1))
        };
        Self {
            observe: lanes.each_ref().map(|l| l.roller.observe),
            observing: lanes.iter().any(|l| l.roller.observe),
            revolution_at: _mm256_setr_epi64x(at[0], at[1], at[2], at[3]),
            revolution_step: _mm256_setr_epi64x(step[0], step[1], step[2], step[3]),
            transfer_factor: lanes_pd!(|j| part.factors[j].0),
            transfers: lanes_pd!(|j| match lanes[j].st.applicator_point {
                Some(_) => f64::from_bits(u64::MAX),
                None => 0.0,
            }),
            factor: lanes_pd!(|j| part.factors[j].1),
            fp_fc: lanes_pd!(|j| lanes[j].roller.fp_fc),
            wheel: lanes_pd!(|j| lanes[j].st.wheel_kg),
            consumed: lanes_pd!(|j| lanes[j].st.consumed_kg),
            capped: lanes_pd!(|j| lanes[j].st.capped_kg),
            rail: lanes_pd!(|j| rail_kg[is[j]]),
            lead: is[0],
            stride: if part.up { 1 } else { usize::MAX },
            left: _mm256_setzero_pd(),
        }
    }

    /// One step: [`Roller::conditions_given`] lane by lane, steps 3 to 5
    /// ([`product::roll4_register`]), then [`Roller::rolled`]'s totals and
    /// stores.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[inline(always)]
    unsafe fn step(
        &mut self,
        ctx: &RollContext<'_>,
        params: &ProductParams,
        part: &mut RunPart<'_>,
    ) {
        use std::arch::x86_64::*;
        // revolution[|i - ia|] times the transfer factor where the wheel
        // passed an applicator, 0 where it passed none (the product there
        // masked off).
        let revolution = _mm256_and_pd(
            _mm256_mul_pd(
                _mm256_i64gather_pd::<8>(ctx.revolution.as_ptr(), self.revolution_at),
                self.transfer_factor,
            ),
            self.transfers,
        );
        let conditions = product::Conditions4 {
            transfers: self.transfers,
            revolution,
            factor: self.factor,
            fp_fc: self.fp_fc,
        };
        let rolled = product::roll4_register(params, (self.wheel, self.rail), &conditions);
        if self.observing {
            let m = store_pd!(_mm256_add_pd(self.wheel, self.rail));
            let after = store_pd!(rolled.wheel);
            let is = self.points();
            for j in (0..LANES).filter(|&j| self.observe[j]) {
                part.work.observed.mass_kg[is[j]] = m[j];
                part.work.observed.wheel_mass_kg[is[j]] = after[j];
            }
        }
        self.wheel = rolled.wheel;
        self.consumed = _mm256_add_pd(self.consumed, rolled.consumed);
        self.capped = _mm256_add_pd(self.capped, rolled.capped);
        self.left = rolled.rail;
        part.state.rail_mass_kg[self.points()[LANES - 1]] =
            _mm256_cvtsd_f64(_mm256_permute4x64_pd::<0b11>(rolled.rail));
    }

    /// To the step after the last: lane j + 1 reads what lane j
    /// left, lane 0 a new point.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    unsafe fn advance(&mut self, part: &RunPart<'_>) {
        use std::arch::x86_64::*;
        self.lead = self.lead.wrapping_add(self.stride);
        self.rail = _mm256_blend_pd::<0b0001>(
            _mm256_permute4x64_pd::<0b10_01_00_11>(self.left),
            _mm256_set1_pd(part.state.rail_mass_kg[self.lead]),
        );
        self.revolution_at = _mm256_add_epi64(self.revolution_at, self.revolution_step);
    }

    /// # Safety
    /// The CPU must have AVX.
    #[inline(always)]
    unsafe fn pass_applicator(&mut self, j: usize) {
        use std::arch::x86_64::*;
        let mut at = [0i64; LANES];
        let mut step = [0i64; LANES];
        let mut transfers = [0.0; LANES];
        _mm256_storeu_si256(at.as_mut_ptr().cast(), self.revolution_at);
        _mm256_storeu_si256(step.as_mut_ptr().cast(), self.revolution_step);
        _mm256_storeu_pd(transfers.as_mut_ptr(), self.transfers);
        at[j] = 0;
        step[j] = 1;
        transfers[j] = f64::from_bits(u64::MAX);
        self.revolution_at = _mm256_loadu_si256(at.as_ptr().cast());
        self.revolution_step = _mm256_loadu_si256(step.as_ptr().cast());
        self.transfers = _mm256_loadu_pd(transfers.as_ptr());
    }

    #[inline(always)]
    fn lead(&self) -> (usize, usize) {
        (self.lead, self.stride)
    }

    #[inline(always)]
    unsafe fn in_memory(&self) -> InMemory {
        let eight = |v| {
            let mut a = [0.0; DEEP];
            a[..LANES].copy_from_slice(&store_pd!(v));
            a
        };
        InMemory {
            rail: eight(self.rail),
            left: eight(self.left),
            wheel: eight(self.wheel),
            consumed: eight(self.consumed),
            capped: eight(self.capped),
        }
    }
}

/// [`RunLanes`] of a wavefront of eight wheels on one track ([`RunPart`] of two groups)
/// in AVX-512 registers: each step lane by lane the operations of
/// [`RunLanes::step`] ([`product::roll8_register`]), so the same bits, in
/// about the instructions four lanes take there. Two tracks' wavefronts
/// are two chains of steps the core overlaps.
#[cfg(target_arch = "x86_64")]
struct RunDeep {
    observe: [bool; DEEP],
    observing: bool,
    revolution_at: std::arch::x86_64::__m512i,
    revolution_step: std::arch::x86_64::__m512i,
    transfer_factor: std::arch::x86_64::__m512d,
    /// The lanes whose wheel passed an applicator.
    transfers: std::arch::x86_64::__mmask8,
    factor: std::arch::x86_64::__m512d,
    fp_fc: std::arch::x86_64::__m512d,
    wheel: std::arch::x86_64::__m512d,
    consumed: std::arch::x86_64::__m512d,
    capped: std::arch::x86_64::__m512d,
    rail: std::arch::x86_64::__m512d,
    lead: usize,
    stride: usize,
    left: std::arch::x86_64::__m512d,
}

/// An AVX-512 register's eight lanes as an array.
macro_rules! store8_pd {
    ($v:expr) => {{
        let mut a = [0.0; DEEP];
        std::arch::x86_64::_mm512_storeu_pd(a.as_mut_ptr(), $v);
        a
    }};
}

/// Eight lanes' values as an AVX-512 register, lane 0 first.
macro_rules! lanes8_pd {
    (|$j:ident| $e:expr) => {{
        let a: [f64; DEEP] = std::array::from_fn(|$j| $e);
        std::arch::x86_64::_mm512_loadu_pd(a.as_ptr())
    }};
}

#[cfg(target_arch = "x86_64")]
impl Registers<2> for RunDeep {
    /// The lanes of `part` about to take step `s`, as [`RunLanes::start`].
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline(always)]
    unsafe fn start(ctx: &RollContext<'_>, part: &RunPart<'_, 2>, s: usize) -> Self {
        use std::arch::x86_64::*;
        let is = part.at(s);
        let rail_kg = &part.state.rail_mass_kg;
        // The gather does not check its indices: every distance on the
        // track is in the table.
        assert!(ctx.revolution.len() >= part.special.len());
        let of = |j: usize| match part.lane(j).st.applicator_point {
            Some(ia) => (is[j].abs_diff(ia) as i64, 1),
            None => (0, 0),
        };
        let lane: [(i64, i64); DEEP] = std::array::from_fn(of);
        let at = lane.map(|l| l.0);
        let step = lane.map(|l| l.1);
        let mut transfers = 0u8;
        for j in 0..DEEP {
            if part.lane(j).st.applicator_point.is_some() {
                transfers |= 1 << j;
            }
        }
        let observe: [bool; DEEP] = std::array::from_fn(|j| part.lane(j).roller.observe);
        Self {
            observe,
            observing: observe.iter().any(|&o| o),
            revolution_at: _mm512_loadu_si512(at.as_ptr().cast()),
            revolution_step: _mm512_loadu_si512(step.as_ptr().cast()),
            transfer_factor: lanes8_pd!(|j| part.factors[j].0),
            transfers,
            factor: lanes8_pd!(|j| part.factors[j].1),
            fp_fc: lanes8_pd!(|j| part.lane(j).roller.fp_fc),
            wheel: lanes8_pd!(|j| part.lane(j).st.wheel_kg),
            consumed: lanes8_pd!(|j| part.lane(j).st.consumed_kg),
            capped: lanes8_pd!(|j| part.lane(j).st.capped_kg),
            rail: lanes8_pd!(|j| rail_kg[is[j]]),
            lead: is[0],
            stride: if part.up { 1 } else { usize::MAX },
            left: _mm512_setzero_pd(),
        }
    }

    /// One step, as [`RunLanes::step`]: only the last lane's rail mass is
    /// stored (no lane of the wavefront reads its point again).
    ///
    /// # Safety
    /// The CPU must have AVX-512F, AVX2 and FMA.
    #[inline(always)]
    unsafe fn step(
        &mut self,
        ctx: &RollContext<'_>,
        params: &ProductParams,
        part: &mut RunPart<'_, 2>,
    ) {
        use std::arch::x86_64::*;
        let revolution = _mm512_maskz_mov_pd(
            self.transfers,
            _mm512_mul_pd(
                _mm512_i64gather_pd::<8>(self.revolution_at, ctx.revolution.as_ptr()),
                self.transfer_factor,
            ),
        );
        let conditions = product::Conditions8 {
            transfers: self.transfers,
            revolution,
            factor: self.factor,
            fp_fc: self.fp_fc,
        };
        let rolled = product::roll8_register(params, (self.wheel, self.rail), &conditions);
        if self.observing {
            let m = store8_pd!(_mm512_add_pd(self.wheel, self.rail));
            let after = store8_pd!(rolled.wheel);
            let is = self.points();
            for j in (0..DEEP).filter(|&j| self.observe[j]) {
                part.work.observed.mass_kg[is[j]] = m[j];
                part.work.observed.wheel_mass_kg[is[j]] = after[j];
            }
        }
        self.wheel = rolled.wheel;
        self.consumed = _mm512_add_pd(self.consumed, rolled.consumed);
        self.capped = _mm512_add_pd(self.capped, rolled.capped);
        self.left = rolled.rail;
        let high = _mm512_extractf64x4_pd::<1>(rolled.rail);
        part.state.rail_mass_kg[self.points()[DEEP - 1]] =
            _mm256_cvtsd_f64(_mm256_permute4x64_pd::<0b11>(high));
    }

    /// To the step after the last: lane j + 1 reads what lane j left, lane
    /// 0 a new point.
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline(always)]
    unsafe fn advance(&mut self, part: &RunPart<'_, 2>) {
        use std::arch::x86_64::*;
        self.lead = self.lead.wrapping_add(self.stride);
        let shifted = _mm512_permutexvar_pd(_mm512_setr_epi64(7, 0, 1, 2, 3, 4, 5, 6), self.left);
        self.rail = _mm512_mask_blend_pd(
            0b0000_0001,
            shifted,
            _mm512_set1_pd(part.state.rail_mass_kg[self.lead]),
        );
        self.revolution_at = _mm512_add_epi64(self.revolution_at, self.revolution_step);
    }

    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline(always)]
    unsafe fn pass_applicator(&mut self, j: usize) {
        use std::arch::x86_64::*;
        let lane = 1u8 << j;
        self.revolution_at = _mm512_mask_set1_epi64(self.revolution_at, lane, 0);
        self.revolution_step = _mm512_mask_set1_epi64(self.revolution_step, lane, 1);
        self.transfers |= lane;
    }

    #[inline(always)]
    fn lead(&self) -> (usize, usize) {
        (self.lead, self.stride)
    }

    #[inline(always)]
    unsafe fn in_memory(&self) -> InMemory {
        InMemory {
            rail: store8_pd!(self.rail),
            left: store8_pd!(self.left),
            wheel: store8_pd!(self.wheel),
            consumed: store8_pd!(self.consumed),
            capped: store8_pd!(self.capped),
        }
    }
}

impl Engine {
    /// The engine's fields split into what rolling reads and the per-track
    /// state it changes.
    pub(crate) fn split(&mut self) -> (RollContext<'_>, &mut [TrackState], &mut [TrackWork]) {
        (
            RollContext {
                product: &self.cfg.product,
                effects: &self.cfg.effects,
                section: &self.section,
                d_m: &self.grid.d_m,
                revolution: &self.revolution,
                timeline: &self.timeline,
                time_effects: self.time_effects,
                generic: &self.generic,
                track_info: &self.track_info,
                applicator_at: &self.applicator_at,
                special: &self.special,
                sites_at: &self.sites_at,
                last_axle: &self.last_axle,
                observe_every_wheel: self.opts.snapshot_every_wheel,
                keep_seen: self.opts.every_wheel_contacts && !self.opts.snapshot_every_wheel,
                watch: [usize::MAX; 2],
                observers: [usize::MAX; 2],
                effect_params: self.opts.effect_tangents,
                tangent_width: match (self.opts.tangents, self.opts.effect_tangents) {
                    (false, _) => 0,
                    (true, e) if e.iter().all(Option::is_none) => tangent::STATE_SLOTS,
                    (true, _) => SLOTS,
                },
                portable: self.opts.portable_kernel,
                deep: !self.opts.portable_kernel
                    && !self.opts.narrow_kernel
                    && tortwin_model::exp::exp8_is_available(),
                origin_ns: self.origin_ns,
                line: self.line.as_ref(),
            },
            &mut self.tracks,
            &mut self.work,
        )
    }

    /// Rolls every wheel of the train. Tracks (rail x band) are independent
    /// within a train: each track's wheels roll in axle order, the tracks on
    /// as many threads as rayon offers, and what they add to the totals is
    /// settled in the serial order (axle by axle, rail by rail), so that
    /// the result does not depend on the threads. Every wheel's contacts,
    /// when a sink asks for them, are kept per track and handed over after
    /// the roll in the serial order; a field snapshot after every wheel
    /// makes the wheels roll one at a time in the serial order.
    pub(super) fn roll_train(
        &mut self,
        record: &mut TrainRecord,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        if self.line.is_some() {
            return self.roll_train_line(record, sink);
        }
        let rails = self.section.rails.len();
        let axles = record.passage.axles.len();
        self.last_axle.fill(usize::MAX);
        for work in &mut self.work {
            work.axles.clear();
        }
        for a in 0..axles {
            for r in 0..rails {
                let track = record.wheels[a * rails + r].track;
                self.last_axle[track] = a;
                self.work[track].axles.push(a);
            }
        }
        if !self.opts.snapshot_every_wheel {
            let points = self.grid.d_m.len();
            if self.opts.every_wheel_contacts {
                for work in &mut self.work {
                    work.wheel_seen.clear();
                    work.wheel_seen.resize(work.axles.len() * points, 0.0);
                }
            }
            let min_contacts = parallel_min_contacts(&self.opts);
            let (ctx, states, works) = self.split();
            let record_ref: &TrainRecord = record;
            let parallel = states.len() > 1
                && works
                    .iter()
                    .filter(|w| w.axles.len() * points >= min_contacts)
                    .count()
                    > 1
                && pool_has_threads();
            if parallel {
                use rayon::prelude::*;
                states
                    .par_iter_mut()
                    .zip(works.par_iter_mut())
                    .enumerate()
                    .for_each(|(track, (state, work))| {
                        ctx.roll_track(record_ref, track, state, work);
                    });
            } else {
                // Two tracks at a time, their groups side by side.
                let pairs = states.chunks_mut(2).zip(works.chunks_mut(2));
                for (p, (states, works)) in pairs.enumerate() {
                    match (states, works) {
                        ([state_a, state_b], [work_a, work_b]) => ctx.roll_tracks(
                            record_ref,
                            [2 * p, 2 * p + 1],
                            [(state_a, work_a), (state_b, work_b)],
                        ),
                        (states, works) => {
                            for (k, (state, work)) in states.iter_mut().zip(works).enumerate() {
                                ctx.roll_track(record_ref, 2 * p + k, state, work);
                            }
                        }
                    }
                }
            }
            self.settle(record);
            if self.opts.every_wheel_contacts {
                self.every_wheel_contacts(record, sink)?;
            }
            return Ok(());
        }
        for a in 0..axles {
            for r in 0..rails {
                let track = record.wheels[a * rails + r].track;
                {
                    let (ctx, states, works) = self.split();
                    let group = Group {
                        record,
                        track,
                        axles: &[a],
                        first_row: 0,
                    };
                    ctx.roll_group(&group, &mut states[track], &mut works[track]);
                }
                self.settle(record);
                if self.opts.every_wheel_contacts {
                    let seen = std::mem::take(&mut self.work[track].observed.mass_kg);
                    let result = self.wheel_contacts(record, track, r, a, &seen, sink);
                    self.work[track].observed.mass_kg = seen;
                    result?;
                }
                if self.opts.snapshot_every_wheel {
                    let end_ns = self.wheel_exit_ns(record, a);
                    self.emit_field(record, track, a, SnapshotKind::Wheel, end_ns, sink)?;
                }
            }
        }
        Ok(())
    }

    /// Every wheel's contacts to the sink, in the serial order (axle by
    /// axle, rail by rail), from the rows the wavefront kept.
    fn every_wheel_contacts(
        &mut self,
        record: &TrainRecord,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let rails = self.section.rails.len();
        let points = self.grid.d_m.len();
        let mut rows = std::mem::take(&mut self.last_row);
        rows.clear();
        rows.resize(self.work.len(), 0);
        let mut result = Ok(());
        'wheels: for a in 0..record.passage.axles.len() {
            for r in 0..rails {
                let track = record.wheels[a * rails + r].track;
                let row = rows[track];
                rows[track] += 1;
                let seen = std::mem::take(&mut self.work[track].wheel_seen);
                result = self.wheel_contacts(
                    record,
                    track,
                    r,
                    a,
                    &seen[row * points..(row + 1) * points],
                    sink,
                );
                self.work[track].wheel_seen = seen;
                if result.is_err() {
                    break 'wheels;
                }
            }
        }
        self.last_row = rows;
        result
    }

    /// One wheel's contacts (`seen`: its step-2 masses) to the sink. With
    /// friction terms mu is not eq. (4) of the mass alone: it goes along.
    fn wheel_contacts(
        &mut self,
        record: &TrainRecord,
        track: usize,
        r: usize,
        a: usize,
        seen: &[f64],
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let mut mu = std::mem::take(&mut self.snapshot.contact_mu);
        let with_terms = self.generic.any_friction();
        if with_terms {
            self.fill_mu(record, track, a, seen, &mut mu);
        }
        let result = sink.wheel_contacts(&WheelContacts {
            track,
            rail: r,
            direction: record.passage.direction,
            train_seq: record.passage.train_seq,
            axle: a,
            seen_mass_kg: seen.into(),
            mu: with_terms.then_some(mu.as_slice().into()),
        });
        self.snapshot.contact_mu = mu;
        Ok(result?)
    }

    /// Takes in what the tracks' rolls (or point events) reported: the
    /// readings into the window, the site contacts into the record, and the
    /// totals in the serial order.
    pub(crate) fn settle(&mut self, record: &mut TrainRecord) {
        let mut ledger = std::mem::take(&mut self.ledger);
        for work in &mut self.work {
            for &(b, reading) in &work.readings {
                self.window[b].reading = Some(reading);
            }
            work.readings.clear();
            for site in &work.sites {
                record.site_mass_kg[site.index] = site.mass_kg;
                record.site_at[site.index] = (site.time_s, site.weather);
                if let Some(levels) = site.levels {
                    record.site_levels[site.index] = levels;
                }
                if let Some(slot) = record.site_tan.get_mut(site.index) {
                    *slot = site.tangent;
                }
            }
            work.sites.clear();
            ledger.append(&mut work.ledger);
        }
        // Every order is distinct: the sort's result is the serial order.
        ledger.sort_unstable_by_key(|a| a.order);
        for addend in &ledger {
            self.totals.add(addend);
        }
        ledger.clear();
        self.ledger = ledger;
    }

    /// The log_time at which axle `a` leaves the section: the passage's
    /// log_time plus its time on the section in integer nanoseconds.
    fn wheel_exit_ns(&self, record: &TrainRecord, a: usize) -> u64 {
        let offset = record.passage.axles.get(a).map_or(0.0, |x| x.offset_m);
        let on_section_s = (self.section.length_m + offset) / record.passage.speed_mps;
        record
            .log_time_ns
            .saturating_add((on_section_s * 1e9).round() as u64)
    }
}

impl RollContext<'_> {
    /// `time_s = (log_time_ns - origin_ns) * 1e-9` (model.md).
    fn time_s(&self, log_time_ns: u64) -> f64 {
        (log_time_ns as i64).wrapping_sub(self.origin_ns) as f64 * 1e-9
    }

    /// Every wheel of this train on `track`, in axle order, [`LANES`] at a
    /// time.
    fn roll_track(
        &self,
        record: &TrainRecord,
        track: usize,
        state: &mut TrackState,
        work: &mut TrackWork,
    ) {
        let axles = std::mem::take(&mut work.axles);
        let group = |g: usize| Group {
            record,
            track,
            axles: &axles[g * LANES..axles.len().min((g + 1) * LANES)],
            first_row: g * LANES,
        };
        let groups = axles.len().div_ceil(LANES);
        let mut g = 0;
        while g < groups {
            // Two full groups as one wavefront of eight wheels.
            if (g + 2) * LANES <= axles.len()
                && self.roll_deep_one([&group(g), &group(g + 1)], state, work)
            {
                g += 2;
                continue;
            }
            self.roll_group(&group(g), state, work);
            g += 1;
        }
        work.axles = axles;
    }

    /// Two full groups of one track, if this kernel may roll them as one
    /// wavefront of eight ([`RollContext::rolls_deep`]): so where both
    /// groups' lanes allow runs in registers, else one after the other as
    /// wavefronts of four (the eight-lane code gains only in runs, and its
    /// wavefront steps, compiled for AVX-512, took a quarter longer than
    /// the four-lane code's in discover's replays with time effects).
    fn roll_deep_one(
        &self,
        groups: [&Group<'_>; 2],
        state: &mut TrackState,
        work: &mut TrackWork,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.rolls_deep() {
            let kept = &mut work.wave_lanes;
            let waves = [
                self.wave(groups[0], true, kept, 0),
                self.wave(groups[1], true, kept, 1),
            ];
            if waves.iter().all(|w| w.runs.is_some()) {
                // SAFETY: the CPU has AVX-512F, AVX2 and FMA (`deep`).
                unsafe { self.roll_deep_with_one(waves, state, work) };
            } else {
                for wave in waves {
                    // SAFETY: as above.
                    unsafe { self.roll_wave_fma(wave, state, work) };
                }
            }
            return true;
        }
        let _ = (groups, state, work);
        false
    }

    /// Two full groups of each of two tracks, as [`RollContext::roll_deep_one`].
    fn roll_deep_two(
        &self,
        tracks: [([&Group<'_>; 2], &mut TrackState, &mut TrackWork); 2],
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.rolls_deep() {
            let [a, b] = tracks.map(|(groups, state, work)| {
                let kept = &mut work.wave_lanes;
                let waves = [
                    self.wave(groups[0], true, kept, 0),
                    self.wave(groups[1], true, kept, 1),
                ];
                (waves, state, work)
            });
            if [&a.0, &b.0]
                .iter()
                .all(|w| w.iter().all(|w| w.runs.is_some()))
            {
                // SAFETY: the CPU has AVX-512F, AVX2 and FMA (`deep`).
                unsafe { self.roll_deep_with_two([a, b]) };
            } else {
                let ([a0, a1], state_a, work_a) = a;
                let ([b0, b1], state_b, work_b) = b;
                // SAFETY: as above.
                unsafe {
                    self.roll_waves_fma(
                        [a0, b0],
                        [(&mut *state_a, &mut *work_a), (&mut *state_b, &mut *work_b)],
                    );
                    self.roll_waves_fma([a1, b1], [(state_a, work_a), (state_b, work_b)]);
                }
            }
            return true;
        }
        let _ = tracks;
        false
    }

    /// [`RollContext::roll_track`] of two tracks: their groups of
    /// [`LANES`] wheels side by side ([`RollContext::roll_pair_with`]),
    /// the others one by one.
    fn roll_tracks(
        &self,
        record: &TrainRecord,
        tracks: [usize; 2],
        [(state_a, work_a), (state_b, work_b)]: [(&mut TrackState, &mut TrackWork); 2],
    ) {
        let axles = [
            std::mem::take(&mut work_a.axles),
            std::mem::take(&mut work_b.axles),
        ];
        let groups = axles.each_ref().map(|a| a.len().div_ceil(LANES));
        let group = |k: usize, g: usize| {
            let axles = axles[k].chunks(LANES).nth(g)?;
            Some(Group {
                record,
                track: tracks[k],
                axles,
                first_row: g * LANES,
            })
        };
        let mut g = 0;
        while g < groups[0].max(groups[1]) {
            // Two full groups of each track as wavefronts of eight wheels.
            if (g + 2) * LANES <= axles[0].len().min(axles[1].len()) {
                let full = |k: usize, g: usize| Group {
                    record,
                    track: tracks[k],
                    axles: &axles[k][g * LANES..(g + 1) * LANES],
                    first_row: g * LANES,
                };
                let [a, b] = [0, 1].map(|k| [full(k, g), full(k, g + 1)]);
                let tracks = [
                    ([&a[0], &a[1]], &mut *state_a, &mut *work_a),
                    ([&b[0], &b[1]], &mut *state_b, &mut *work_b),
                ];
                if self.roll_deep_two(tracks) {
                    g += 2;
                    continue;
                }
            }
            let this = g;
            g += 1;
            match (group(0, this), group(1, this)) {
                (Some(a), Some(b)) if a.axles.len() == LANES && b.axles.len() == LANES => {
                    self.roll_pair(&a, &b, [(state_a, work_a), (state_b, work_b)]);
                }
                (a, b) => {
                    if let Some(a) = a {
                        self.roll_group(&a, state_a, work_a);
                    }
                    if let Some(b) = b {
                        self.roll_group(&b, state_b, work_b);
                    }
                }
            }
        }
        let [a, b] = axles;
        (work_a.axles, work_b.axles) = (a, b);
    }

    /// [`RollContext::roll_group`] of two full groups on different tracks,
    /// side by side where the kernel takes runs of steps in
    /// registers; one after the other where it does not.
    fn roll_pair(
        &self,
        a: &Group<'_>,
        b: &Group<'_>,
        [(state_a, work_a), (state_b, work_b)]: [(&mut TrackState, &mut TrackWork); 2],
    ) {
        #[cfg(target_arch = "x86_64")]
        if !self.portable && exp4_is_vectorised() {
            // SAFETY: the CPU has AVX2 and FMA.
            unsafe { self.roll_pair_fma([a, b], [(state_a, work_a), (state_b, work_b)]) };
            return;
        }
        self.roll_group(a, state_a, work_a);
        self.roll_group(b, state_b, work_b);
    }

    /// The wheels of `group` (consecutive wheels of one track, at most
    /// [`LANES`]) as a wavefront: at step s, wheel j of the group is at step
    /// s - j of its path. Wheel j reaches every point one step after wheel
    /// j - 1 left it and before wheel j + 1, so every point sees the wheels
    /// in their order; the pulses and readings at a special point run when
    /// the first wheel after them arrives, as in the serial order. Nothing
    /// else is shared between the wheels of a track.
    fn roll_group(&self, group: &Group<'_>, state: &mut TrackState, work: &mut TrackWork) {
        #[cfg(target_arch = "x86_64")]
        if !self.portable && exp4_is_vectorised() {
            // SAFETY: the CPU has AVX2 and FMA.
            unsafe { self.roll_group_fma(group, state, work) };
            return;
        }
        let v = Vector {
            exp: |x: [f64; LANES]| x.map(f64::exp),
            div: |a: [f64; LANES], b: [f64; LANES]| std::array::from_fn(|j| a[j] / b[j]),
            roll: product::roll4,
            run: None::<NoRun>,
        };
        self.roll_group_with(group, state, work, v);
    }

    /// [`RollContext::roll_group`] compiled for AVX2 and FMA, the four
    /// lanes' exponentials in one vector register. (No multiply-add is
    /// fused that the source does not ask for: Rust never contracts.)
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn roll_group_fma(&self, group: &Group<'_>, state: &mut TrackState, work: &mut TrackWork) {
        let v = vector_fma!();
        self.roll_group_with(group, state, work, v);
    }

    /// [`RollContext::roll_pair_with`] compiled for AVX2 and FMA, as
    /// [`RollContext::roll_group_fma`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn roll_pair_fma(
        &self,
        groups: [&Group<'_>; 2],
        tracks: [(&mut TrackState, &mut TrackWork); 2],
    ) {
        let v = vector_fma!();
        self.roll_pair_with(groups, tracks, v);
    }

    /// [`RollContext::roll_wave_with`] compiled for AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn roll_wave_fma(&self, wave: Wave<'_>, state: &mut TrackState, work: &mut TrackWork) {
        self.roll_wave_with(wave, state, work, vector_fma!());
    }

    /// [`RollContext::roll_waves_with`] compiled for AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn roll_waves_fma(&self, waves: [Wave<'_>; 2], tracks: [(&mut TrackState, &mut TrackWork); 2]) {
        self.roll_waves_with(waves, tracks, vector_fma!());
    }

    /// The steps of one or two groups' lanes (on different tracks) from
    /// `first` until before `end`, in registers ([`RunLanes`]): each step is
    /// [`RollContext::contacts4`]'s with clock-free lanes, the same
    /// operations on the same values, so the same bits. Two groups' steps
    /// are independent chains the core overlaps. A step where a lane is at
    /// a special point is taken in the run too
    /// ([`RollContext::special_step`]; before 2026-12-04 the run stopped
    /// there, and the wavefront's own step, four times as costly, took
    /// it). Returns the step it stopped at (`end`).
    ///
    /// Only for lanes without tangents, the wheel_edge_reservoir effect or
    /// every wheel's contacts kept ([`RollContext::runs`]).
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn runs_fma(&self, parts: &mut [RunPart<'_>], first: usize, end: usize) -> usize {
        if let Ok(one) = <&mut [RunPart<'_>; 1]>::try_from(&mut *parts) {
            return self.run_lanes::<RunLanes, 1, 1>(one, first, end);
        }
        if let Ok(two) = <&mut [RunPart<'_>; 2]>::try_from(&mut *parts) {
            return self.run_lanes::<RunLanes, 1, 2>(two, first, end);
        }
        first
    }

    /// The steps of `K` wavefronts (on different tracks) from `first` until
    /// before `end` in registers `R` ([`RunLanes`] of one group each,
    /// [`RunDeep`] of two): [`RollContext::runs_fma`]'s steps.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and AVX-512F for [`RunDeep`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn run_lanes<R: Registers<G>, const G: usize, const K: usize>(
        &self,
        parts: &mut [RunPart<'_, G>; K],
        first: usize,
        end: usize,
    ) -> usize {
        let mut s = first;
        if s >= end {
            return s;
        }
        // The next step at which a lane of each group is at a special
        // point, found when the run starts and after each such step rather
        // than by looking at the lanes' points at every step.
        let mut next: [usize; K] = std::array::from_fn(|k| parts[k].special_from(s));
        let mut runs: [R; K] = std::array::from_fn(|k| R::start(self, &parts[k], s));
        // A copy the loop's stores cannot reach: its reciprocals are taken
        // once, not at every step.
        let params = *self.product;
        loop {
            if next.contains(&s) {
                self.special_step(&mut runs, parts, &next, &params, s);
                for (n, part) in next.iter_mut().zip(parts.iter()) {
                    if *n == s {
                        *n = part.special_from(s + 1);
                    }
                }
            } else {
                for (run, part) in runs.iter_mut().zip(parts.iter_mut()) {
                    run.step(self, &params, part);
                }
            }
            s += 1;
            if s >= end {
                break;
            }
            for (run, part) in runs.iter_mut().zip(parts.iter()) {
                run.advance(part);
            }
        }
        for (run, part) in runs.iter().zip(parts.iter_mut()) {
            run.finish(part);
        }
        s
    }

    /// Two consecutive full groups of each of `K` tracks (one or two) as
    /// wavefronts of eight wheels ([`RunPart`] of two groups): each track's second group
    /// steps four steps behind its first, so every point still sees the
    /// wheels in their order, and each wave steps as in
    /// [`RollContext::roll_group_with`]; where every lane of every wave is
    /// on its track, their runs of steps go to [`RollContext::run_deep`].
    ///
    /// # Safety
    /// The CPU must have AVX-512F, AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn roll_deep_with<const K: usize>(
        &self,
        mut tracks: [([Wave<'_>; 2], &mut TrackState, &mut TrackWork); K],
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) {
        let end = self.d_m.len() - 1;
        // Every wave has LANES wheels: the same steps each.
        let steps = self.d_m.len() + LANES - 1;
        let mut s = 0;
        while s < steps + LANES {
            let runs = s >= LANES
                && tracks
                    .iter()
                    .all(|([a, b], ..)| self.runs_at(a, s) && self.runs_at(b, s - LANES));
            if runs {
                let mut parts = tracks.each_mut().map(|([a, b], state, work)| {
                    let mut factors = [(0.0, 0.0); DEEP];
                    factors[..LANES].copy_from_slice(&a.runs.unwrap_or_default());
                    factors[LANES..].copy_from_slice(&b.runs.unwrap_or_default());
                    RunPart {
                        record: a.record,
                        track: a.track,
                        special: &self.special[a.track],
                        up: a.up,
                        groups: [&mut a.lanes, &mut b.lanes],
                        state,
                        work,
                        factors,
                    }
                });
                let next = self.run_lanes::<RunDeep, 2, K>(&mut parts, s, end);
                if next > s {
                    s = next;
                    continue;
                }
            }
            for ([a, b], state, work) in tracks.iter_mut() {
                if s < steps {
                    self.wave_step(a, state, work, s, v);
                }
                if s >= LANES {
                    self.wave_step(b, state, work, s - LANES, v);
                }
            }
            s += 1;
        }
        for ([a, b], state, work) in tracks {
            self.wave_end(a, state, work);
            self.wave_end(b, state, work);
        }
    }

    /// [`RollContext::roll_deep_with`] of one track, compiled for AVX-512F,
    /// AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX-512F, AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,avx512f")]
    unsafe fn roll_deep_with_one(
        &self,
        waves: [Wave<'_>; 2],
        state: &mut TrackState,
        work: &mut TrackWork,
    ) {
        self.roll_deep_with([(waves, state, work)], vector_fma!());
    }

    /// [`RollContext::roll_deep_with`] of two tracks, compiled for
    /// AVX-512F, AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX-512F, AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,avx512f")]
    unsafe fn roll_deep_with_two(
        &self,
        tracks: [([Wave<'_>; 2], &mut TrackState, &mut TrackWork); 2],
    ) {
        self.roll_deep_with(tracks, vector_fma!());
    }

    /// Whether two consecutive groups of a track roll as one wavefront of
    /// eight wheels ([`RollContext::roll_deep_with`]): the CPU has AVX-512
    /// ([`RollContext::deep`]), and the steps are those runs take (no
    /// tangents, no row of every wheel's contacts kept).
    fn rolls_deep(&self) -> bool {
        self.deep && self.tangent_width == 0 && !self.keep_seen
    }

    /// Step `s` of a run where a lane of a wavefront is at a special point,
    /// in [`RollContext::wave_step`]'s order: the events there before its
    /// wheel (on the lanes back in memory, then taken up again), the step,
    /// then its sites. The lanes' points are distinct and each event acts
    /// on its own point only.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and AVX-512F for [`RunDeep`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn special_step<R: Registers<G>, const G: usize, const K: usize>(
        &self,
        runs: &mut [R; K],
        parts: &mut [RunPart<'_, G>; K],
        next: &[usize; K],
        params: &ProductParams,
        s: usize,
    ) {
        let n = RunPart::<'_, G>::N;
        let mut at_s = [[f64::NAN; DEEP]; K];
        let mut seen = [[0.0; DEEP]; K];
        for k in (0..K).filter(|&k| next[k] == s) {
            let part = &mut parts[k];
            let is = part.at(s);
            // Pulses or readings due before a lane's wheel act on the
            // masses in memory: the lanes go back there, and the run takes
            // them up again. Without, `special_before` changes at most a
            // lane's count of revolutions (an applicator it passes), which
            // the registers take in place; at a site alone only the wheel's
            // time is wanted.
            let due = |j: usize| {
                let t = part.lane(j).roller.time_at(self.d_m, is[j]);
                self.events_due(part.work, is[j], t)
            };
            let in_memory = (0..n).any(|j| part.special[is[j]] && due(j));
            if in_memory {
                runs[k].suspend(part);
            }
            for j in (0..n).filter(|&j| part.special[is[j]]) {
                let track = part.track;
                let lane = &mut part.groups[j / LANES][j % LANES];
                at_s[k][j] = self.special_before(track, part.state, part.work, lane, is[j]);
                if !in_memory && self.applicator_at[track][is[j]] != NO_APPLICATOR {
                    runs[k].pass_applicator(j);
                }
            }
            if in_memory {
                runs[k] = R::start(self, part, s);
            }
            seen[k] = runs[k].seen();
        }
        for (run, part) in runs.iter_mut().zip(parts.iter_mut()) {
            run.step(self, params, part);
        }
        for k in (0..K).filter(|&k| next[k] == s) {
            let part = &mut parts[k];
            let is = part.at(s);
            for j in (0..n).filter(|&j| part.special[is[j]]) {
                let (t, m) = (at_s[k][j], seen[k][j]);
                let lane = &part.groups[j / LANES][j % LANES];
                self.special_after(part.record, part.track, part.work, lane, is[j], t, m);
            }
        }
    }

    #[inline(always)]
    fn roll_group_with(
        &self,
        group: &Group<'_>,
        state: &mut TrackState,
        work: &mut TrackWork,
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) {
        let wave = self.wave(group, v.run.is_some(), &mut work.wave_lanes, 0);
        self.roll_wave_with(wave, state, work, v);
    }

    /// [`RollContext::roll_group_with`] of a wavefront already made.
    #[inline(always)]
    fn roll_wave_with(
        &self,
        mut wave: Wave<'_>,
        state: &mut TrackState,
        work: &mut TrackWork,
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) {
        let end = self.d_m.len() - 1;
        let mut s = 0;
        while s < self.wave_steps(&wave) {
            if let (Some(run), true) = (v.run, self.runs_at(&wave, s)) {
                let part = self.run_part(&mut wave, state, work);
                let next = run(self, &mut [part], s, end);
                if next > s {
                    s = next;
                    continue;
                }
            }
            self.wave_step(&mut wave, state, work, s, v);
            s += 1;
        }
        self.wave_end(wave, state, work);
    }

    /// Two groups of as many wheels as there are lanes, on different
    /// tracks, rolled step by step side by side: [`RollContext::roll_group`]
    /// of each, with their runs of steps in registers taken together (two
    /// independent chains for the core to overlap). The tracks share
    /// nothing while a train rolls (they may roll on different threads), so
    /// the order of one's steps against the other's changes nothing.
    #[inline(always)]
    fn roll_pair_with(
        &self,
        groups: [&Group<'_>; 2],
        [(state_a, work_a), (state_b, work_b)]: [(&mut TrackState, &mut TrackWork); 2],
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) {
        let a = self.wave(groups[0], v.run.is_some(), &mut work_a.wave_lanes, 0);
        let b = self.wave(groups[1], v.run.is_some(), &mut work_b.wave_lanes, 0);
        self.roll_waves_with([a, b], [(state_a, work_a), (state_b, work_b)], v);
    }

    /// [`RollContext::roll_pair_with`] of two wavefronts already made.
    #[inline(always)]
    fn roll_waves_with(
        &self,
        [mut a, mut b]: [Wave<'_>; 2],
        [(state_a, work_a), (state_b, work_b)]: [(&mut TrackState, &mut TrackWork); 2],
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) {
        let end = self.d_m.len() - 1;
        let steps = self.wave_steps(&a).max(self.wave_steps(&b));
        let mut s = 0;
        while s < steps {
            if let (Some(run), true) = (v.run, self.runs_at(&a, s) && self.runs_at(&b, s)) {
                let parts = [
                    self.run_part(&mut a, state_a, work_a),
                    self.run_part(&mut b, state_b, work_b),
                ];
                let next = run(self, &mut { parts }, s, end);
                if next > s {
                    s = next;
                    continue;
                }
            }
            if s < self.wave_steps(&a) {
                self.wave_step(&mut a, state_a, work_a, s, v);
            }
            if s < self.wave_steps(&b) {
                self.wave_step(&mut b, state_b, work_b, s, v);
            }
            s += 1;
        }
        self.wave_end(a, state_a, work_a);
        self.wave_end(b, state_b, work_b);
    }

    /// The wavefront of `group` before its first step. `runs`: the kernel
    /// has runs of steps in registers ([`Vector::run`]).
    #[inline(always)]
    fn wave<'r>(
        &self,
        group: &Group<'r>,
        runs: bool,
        kept: &mut WaveLanes,
        slot: usize,
    ) -> Wave<'r> {
        let Group {
            record,
            track,
            axles: group,
            first_row,
        } = *group;
        let n = group.len();
        debug_assert!((1..=LANES).contains(&n));
        // Unused lanes repeat the first wheel and are never stepped (made
        // anew: a full group, the common case, then clones no lane).
        let lane = |j: usize| match group.get(j) {
            Some(&a) => self.lane(record, track, a, first_row + j),
            None => self.lane(record, track, group[0], first_row),
        };
        let lanes = match kept.0[slot].take() {
            Some(mut lanes) => {
                for (j, l) in lanes.iter_mut().enumerate() {
                    *l = lane(j);
                }
                lanes
            }
            None => Box::new(std::array::from_fn(lane)),
        };
        let clocks = Clocks::of(&lanes);
        // The portable kernel stores every contact's touch (the reference
        // order, which the kernel test holds the vector kernel's stores to);
        // contacts with effect tangents take the clock (their factors'
        // derivatives read the time and the weather).
        let clock_free = match self.portable || self.tangent_width > tangent::STATE_SLOTS {
            true => None,
            false => clock_free(&lanes),
        };
        // Runs of steps in registers where the kernel has them and the lanes
        // allow.
        let runs = match runs && self.runs(&lanes) {
            true => clock_free,
            false => None,
        };
        Wave {
            record,
            track,
            n,
            up: enters_at_zero(record.passage.direction),
            last: group[n - 1] == self.last_axle[track],
            lanes,
            clocks,
            clock_free,
            runs,
            slot,
        }
    }

    /// How many steps the wavefront takes: the first wheel's points, then
    /// one more for each wheel after it.
    #[inline(always)]
    fn wave_steps(&self, wave: &Wave<'_>) -> usize {
        self.d_m.len() + wave.n - 1
    }

    /// Whether a run of steps may start at step `s`: every lane is
    /// on the track, none takes its last step, and the lanes allow runs.
    #[inline(always)]
    fn runs_at(&self, wave: &Wave<'_>, s: usize) -> bool {
        wave.runs.is_some() && wave.n == LANES && s + 1 >= LANES && s + 1 < self.d_m.len()
    }

    /// A wavefront's part in a run of steps.
    #[inline(always)]
    fn run_part<'s>(
        &'s self,
        wave: &'s mut Wave<'_>,
        state: &'s mut TrackState,
        work: &'s mut TrackWork,
    ) -> RunPart<'s> {
        RunPart {
            record: wave.record,
            track: wave.track,
            groups: [&mut wave.lanes],
            state,
            work,
            special: &self.special[wave.track],
            up: wave.up,
            factors: {
                let mut factors = [(0.0, 0.0); DEEP];
                factors[..LANES].copy_from_slice(&wave.runs.unwrap_or_default());
                factors
            },
        }
    }

    /// Step `s` of a wavefront: the four contacts at once where every lane
    /// is on the track ([`RollContext::contacts4`]), else lane by lane.
    #[inline(always)]
    fn wave_step(
        &self,
        wave: &mut Wave<'_>,
        state: &mut TrackState,
        work: &mut TrackWork,
        s: usize,
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) {
        let Wave {
            record,
            track,
            n,
            up,
            ref mut lanes,
            ref clocks,
            clock_free,
            ..
        } = *wave;
        let points = self.d_m.len();
        let special = &self.special[track];
        let lo = s.saturating_sub(points - 1);
        let hi = n.min(s + 1);
        if lo == 0 && hi == LANES {
            let is = lane_points(up, points, s);
            // A special point's events before its wheel, then the four
            // contacts at once, then its sites: the four points are
            // distinct and each event acts on its own point only, so
            // this is the order of the contacts one by one.
            let specials = is.map(|i| special[i]);
            let mut at_s = [f64::NAN; LANES];
            for j in (0..LANES).filter(|&j| specials[j]) {
                at_s[j] = self.special_before(track, state, work, &mut lanes[j], is[j]);
            }
            // Compiled three times: without tangents nothing of them is
            // left; without effect slots only the constants'.
            let (states, works) = (std::slice::from_mut(state), std::slice::from_mut(work));
            let tracks = [0; LANES];
            let seen = match self.tangent_width {
                0 => self.contacts4::<0>(lanes, clocks, states, works, tracks, is, clock_free, v),
                tangent::STATE_SLOTS => self.contacts4::<{ tangent::STATE_SLOTS }>(
                    lanes, clocks, states, works, tracks, is, clock_free, v,
                ),
                _ => self.contacts4::<SLOTS>(lanes, clocks, states, works, tracks, is, None, v),
            };
            for j in (0..LANES).filter(|&j| specials[j]) {
                self.special_after(record, track, work, &lanes[j], is[j], at_s[j], seen[j]);
            }
            if self.keep_seen {
                for (lane, (&i, &m)) in lanes.iter().zip(is.iter().zip(&seen)) {
                    work.wheel_seen[lane.row * points + i] = m;
                }
            }
            if s + 1 >= points {
                self.finish_lane(&lanes[s + 1 - points], state, work, points);
            }
            return;
        }
        for (j, lane) in lanes.iter_mut().enumerate().take(hi).skip(lo) {
            let i = point_of(up, points, s - j);
            let m_kg = if special[i] {
                self.special_contact(record, track, state, work, lane, i)
            } else {
                self.contact(lane, state, work, i)
            };
            if self.keep_seen {
                work.wheel_seen[lane.row * points + i] = m_kg;
            }
        }
        // The lane that took its last step now.
        if s + 1 >= points {
            self.finish_lane(&lanes[s + 1 - points], state, work, points);
        }
    }

    /// After a wavefront's last step: step 1's stores again where no step
    /// left them out (a group of fewer than four wheels steps lane by
    /// lane): the same values. The lanes go back to `work` for the next
    /// group.
    fn wave_end(&self, wave: Wave<'_>, state: &mut TrackState, work: &mut TrackWork) {
        if wave.clock_free.is_some() && wave.last {
            self.store_touches(&wave.lanes[wave.n - 1], state);
        }
        work.wave_lanes.0[wave.slot] = Some(wave.lanes);
    }

    /// One contact of `lane`'s wheel at point `i`, its exponentials taken
    /// one by one ([`Roller::contact`], or [`Roller::contact_tangent`] with
    /// tangents); returns the step-2 mass.
    #[inline(always)]
    fn contact(
        &self,
        lane: &mut Lane,
        state: &mut TrackState,
        work: &mut TrackWork,
        i: usize,
    ) -> f64 {
        let (rail_tan, observed) = (&mut work.rail_tan, &mut work.observed);
        let (d_m, revolution, timeline) = (self.d_m, self.revolution, self.timeline);
        let st = &mut lane.st;
        match self.tangent_width {
            0 => {}
            tangent::STATE_SLOTS => {
                return lane.roller.contact_tangent::<{ tangent::STATE_SLOTS }>(
                    st, state, rail_tan, observed, d_m, revolution, timeline, i,
                )
            }
            _ => {
                return lane.roller.contact_tangent::<SLOTS>(
                    st, state, rail_tan, observed, d_m, revolution, timeline, i,
                )
            }
        }
        lane.roller.contact(
            &mut lane.st,
            state,
            &mut work.observed,
            self.d_m,
            self.revolution,
            self.timeline,
            i,
        )
    }

    /// Whether [`RollContext::runs_fma`] may take these lanes'
    /// steps: no tangents, no wheel_edge_reservoir and no row of every
    /// wheel's contacts to keep (the steps it leaves out).
    fn runs(&self, lanes: &[Lane; LANES]) -> bool {
        self.tangent_width == 0
            && !self.keep_seen
            && lanes.iter().all(|l| l.roller.reservoir.is_none())
    }

    /// A wheel that has left the track: its totals for the ledger.
    fn finish_lane(
        &self,
        lane: &Lane,
        state: &mut TrackState,
        work: &mut TrackWork,
        points: usize,
    ) {
        let st = &lane.st;
        work.ledger.push(Addend {
            order: lane.serial << 32 | u64::from(u32::MAX),
            kind: AddendKind::Wheel {
                contacts: points as u64,
                consumed_kg: st.consumed_kg,
                capped_kg: st.capped_kg,
                lost_kg: st.lost_kg,
                carried_kg: st.wheel_kg + st.edge_kg,
            },
        });
        state.wheel_pass += 1;
    }

    /// Step 1's reads for four lanes at the distinct points `is`:
    /// [`Roller::touch`] lane by lane, with its two divisions (the wheel's
    /// time, the precipitation since the weather message) taken for the
    /// four lanes at once. Division is correctly rounded in a vector as in
    /// a scalar register: the same quotients, the same bits.
    #[inline(always)]
    fn touches4(
        &self,
        lanes: &[Lane; LANES],
        clocks: &Clocks,
        states: &[TrackState],
        tracks: [usize; LANES],
        is: [usize; LANES],
        div4: impl Div4,
    ) -> [Touch<'_>; LANES] {
        use std::array::from_fn;
        let r = |j: usize| &lanes[j].roller;
        // wheel_time_s, the division four at once.
        let path =
            from_fn(|j| wheel_path_m(self.d_m[is[j]], clocks.d_entry_m[j], clocks.offset_m[j]));
        let q = div4(path, clocks.speed_mps);
        let t: [f64; LANES] = from_fn(|j| clocks.t_passage_s[j] + q[j]);
        let weather: [&WeatherState; LANES] = from_fn(|j| self.timeline.at(t[j]));
        // WeatherState::precip_mm_at, likewise.
        let parts = from_fn(|j| weather[j].precip_parts(t[j]));
        let rises = div4(
            parts.map(|p| p.map_or(0.0, |(_, rise)| rise)),
            [SECONDS_PER_HOUR; LANES],
        );
        // Written out by a macro, not `from_fn` or a closure: the compiler
        // outlines those for a `Touch` array, and an outlined call loses
        // this function's AVX2 and the inlining (7 % of a replay, measured
        // 2026-11-28; 10 % once the closure read each lane's track).
        macro_rules! touch {
            ($j:literal) => {
                r($j).touch_at(
                    &states[tracks[$j]],
                    t[$j],
                    weather[$j],
                    parts[$j].map_or(0.0, |(at_since, _)| at_since + rises[$j]),
                    is[$j],
                )
            };
        }
        const _: () = assert!(LANES == 4);
        [touch!(0), touch!(1), touch!(2), touch!(3)]
    }

    /// Four ordinary contacts (no special point), one per lane, at the
    /// distinct points `is`: the phases of [`Roller::contact`] lane by
    /// lane, with each phase's exponentials taken for the four lanes at
    /// once ([`exp4`]; bit for bit `f64::exp` with glibc on an FMA CPU).
    /// Lane j's contact is on track `tracks[j]` of `states` and `works`
    /// (a section's one track; a line's rail band of the lane's row).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn contacts4<const W: usize>(
        &self,
        lanes: &mut [Lane; LANES],
        clocks: &Clocks,
        states: &mut [TrackState],
        works: &mut [TrackWork],
        tracks: [usize; LANES],
        is: [usize; LANES],
        clock_free: Option<[(f64, f64); LANES]>,
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) -> [f64; LANES] {
        use std::array::from_fn;
        let (rail, conditions, effects) = match clock_free {
            // No time, no weather and no touch to store: the rail masses and
            // the conditions from the wheels' constant factors (and no
            // effect slot: those take the clock).
            Some(factors) => (
                from_fn(|j| states[tracks[j]].rail_mass_kg[is[j]]),
                from_fn(|j| {
                    lanes[j].roller.conditions_given(
                        &lanes[j].st,
                        factors[j],
                        self.revolution,
                        is[j],
                    )
                }),
                [EffectTangents::default(); LANES],
            ),
            None => {
                let touches = self.touch4::<W>(lanes, clocks, states, works, tracks, is, v);
                let conditions: [ContactConditions; LANES] = from_fn(|j| {
                    lanes[j]
                        .roller
                        .conditions(&lanes[j].st, &touches[j], self.revolution, is[j])
                });
                let effects = from_fn(|j| {
                    let (lane, touch) = (&lanes[j], &touches[j]);
                    (lane.roller).effect_tangents_of::<W>(&lane.st, touch, self.revolution, is[j])
                });
                (from_fn(|j| touches[j].rail_kg), conditions, effects)
            }
        };
        if W > 0 {
            let given = (rail, &conditions, effects);
            return self.finish4_tangent::<W>(lanes, states, works, tracks, is, given, v.exp);
        }
        // Steps 3 to 5 of the four lanes at once, then each lane's rest.
        let wheel = std::array::from_fn(|j| lanes[j].st.wheel_kg);
        let (wheel_after, rail_after, losses) = (v.roll)(self.product, (wheel, rail), &conditions);
        let mut seen = [0.0; LANES];
        for (j, lane) in lanes.iter_mut().enumerate() {
            let (state, work) = (&mut states[tracks[j]], &mut works[tracks[j]]);
            seen[j] = lane.roller.rolled(
                &mut lane.st,
                state,
                &mut work.observed,
                wheel[j] + rail[j],
                (wheel_after[j], rail_after[j]),
                losses[j],
                is[j],
            );
        }
        seen
    }

    /// Step 1 of four lanes ([`RollContext::touches4`]): the time effects
    /// since each point's last touch (on the rail masses' tangents too,
    /// with tangents, in their places in the track's tangents) and the
    /// touches stored. Returns the touches.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn touch4<const W: usize>(
        &self,
        lanes: &mut [Lane; LANES],
        clocks: &Clocks,
        states: &mut [TrackState],
        works: &mut [TrackWork],
        tracks: [usize; LANES],
        is: [usize; LANES],
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl Run4>,
    ) -> [Touch<'_>; LANES] {
        let exp4 = v.exp;
        let mut touches = self.touches4(lanes, clocks, states, tracks, is, v.div);
        if touches.iter().any(|t| t.aged) {
            let args: [[f64; 2]; LANES] = std::array::from_fn(|j| {
                self.time_effects
                    .exp_args(touches[j].dt_s, touches[j].rain_mm)
            });
            let ageing = exp4(args.map(|a| a[0]));
            let washoff = if self.time_effects.rain_k_per_mm.is_some() {
                exp4(args.map(|a| a[1]))
            } else {
                [1.0; LANES]
            };
            for (j, (lane, touch)) in lanes.iter_mut().zip(&mut touches).enumerate() {
                if touch.aged {
                    let exps = [ageing[j], washoff[j]];
                    if W > 0 {
                        // The rail mass's tangent aged in its place, not
                        // copied out and back (perf put 7 % of a
                        // calibration's samples on the copy back; its time
                        // moved to the loads, the outputs are the same).
                        let dr = &mut works[tracks[j]].rail_tan[is[j]];
                        lane.roller.age_tangent::<W>(&mut lane.st, touch, dr, exps);
                    } else {
                        lane.roller.age(&mut lane.st, touch, exps);
                    }
                }
            }
        }
        for (j, (lane, (touch, &i))) in lanes.iter().zip(touches.iter().zip(&is)).enumerate() {
            lane.roller.touched(&mut states[tracks[j]], touch, i);
        }
        touches
    }

    /// Steps 3 to 5 with tangents (W > 0), lane by lane, given the rail
    /// masses after step 1, the conditions and their effect tangents, the
    /// four lanes' exponentials taken at once; returns the step-2 masses.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn finish4_tangent<const W: usize>(
        &self,
        lanes: &mut [Lane; LANES],
        states: &mut [TrackState],
        works: &mut [TrackWork],
        tracks: [usize; LANES],
        is: [usize; LANES],
        (rail, conditions, effects): (
            [f64; LANES],
            &[ContactConditions; LANES],
            [EffectTangents; LANES],
        ),
        exp4: impl Exp4,
    ) -> [f64; LANES] {
        let args: [[f64; 2]; LANES] = std::array::from_fn(|j| {
            product::roll_exp_args(self.product, lanes[j].st.wheel_kg, rail[j])
        });
        let transfer = exp4(args.map(|a| a[0]));
        let consumption = exp4(args.map(|a| a[1]));
        let mut seen = [0.0; LANES];
        for (j, lane) in lanes.iter_mut().enumerate() {
            let (state, work) = (&mut states[tracks[j]], &mut works[tracks[j]]);
            // A site's measurement reads the contact's tangent there.
            let at_site = !self.sites_at[is[j]].is_empty();
            seen[j] = lane.roller.finish_tangent::<W>(
                at_site,
                &mut lane.st,
                state,
                &mut work.rail_tan[is[j]],
                &mut work.observed,
                rail[j],
                (&conditions[j], effects[j]),
                [transfer[j], consumption[j]],
                is[j],
            );
        }
        seen
    }

    /// Step 1's stores (the time of the touch and the rain by then) of
    /// `lane`'s wheel at every point, as its contacts would have stored
    /// them. The vector kernel leaves them out of clock-free contacts
    /// ([`Roller::clock_free`]): with no time effect on, nothing reads
    /// them while a train passes, and after it each point holds its last
    /// touch, the track's last wheel's, which this writes.
    fn store_touches(&self, lane: &Lane, state: &mut TrackState) {
        for i in 0..self.d_m.len() {
            let touch = lane.roller.touch(state, self.d_m, self.timeline, i);
            lane.roller.touched(state, &touch, i);
        }
    }

    /// A contact at a special point (an applicator or a measurement site):
    /// the pulses and readings there that come before this wheel run first.
    fn special_contact(
        &self,
        record: &TrainRecord,
        track: usize,
        state: &mut TrackState,
        work: &mut TrackWork,
        lane: &mut Lane,
        i: usize,
    ) -> f64 {
        let t = self.special_before(track, state, work, lane, i);
        let m_kg = self.contact(lane, state, work, i);
        self.special_after(record, track, work, lane, i, t, m_kg);
        m_kg
    }

    /// Whether a pulse or reading at point `i` may still have to run before
    /// a wheel there at `t` ([`RollContext::run_events_before`]).
    fn events_due(&self, work: &TrackWork, i: usize, t: f64) -> bool {
        work.next_at[i] < t
    }

    /// What comes before `lane`'s contact at the special point `i`: the
    /// pulses and readings there before its wheel, and N's count from an
    /// applicator. Returns the wheel's time there.
    fn special_before(
        &self,
        track: usize,
        state: &mut TrackState,
        work: &mut TrackWork,
        lane: &mut Lane,
        i: usize,
    ) -> f64 {
        let t = lane.roller.time_at(self.d_m, i);
        self.run_events_before(track, state, work, lane, i, t);
        if self.applicator_at[track][i] != NO_APPLICATOR {
            // The wheel passes this applicator: N counts from here.
            lane.st.applicator_point = Some(i);
        }
        t
    }

    /// What comes after `lane`'s contact at the special point `i` (at time
    /// `t`, step-2 mass `m_kg`): the contact kept for the sites there.
    #[allow(clippy::too_many_arguments)]
    fn special_after(
        &self,
        record: &TrainRecord,
        track: usize,
        work: &mut TrackWork,
        lane: &Lane,
        i: usize,
        t: f64,
        m_kg: f64,
    ) {
        let sites_here = &self.sites_at[i];
        if sites_here.is_empty() {
            return;
        }
        let rail = self.track_info[track].rail;
        let weather = self.timeline.at(t).current;
        let levels = (!record.site_levels.is_empty()).then(|| {
            let rails = self.section.rails.len();
            self.generic.friction_levels(
                self.product.mu_d,
                self.product.mu_c,
                rail,
                t,
                &weather,
                Some(&record.wheels[lane.axle * rails + rail].drivers),
            )
        });
        let (rails, sites) = (self.section.rails.len(), self.section.sites.len());
        for &s in sites_here {
            work.sites.push(SiteValue {
                index: (lane.axle * rails + rail) * sites + s,
                mass_kg: m_kg,
                levels,
                time_s: t,
                weather,
                tangent: lane.st.seen_tan,
            });
        }
    }

    /// The pulses and readings of `track` at point `i` that come before
    /// `lane`'s wheel there (at `t`, strictly after them), in the window's
    /// order; a pulse's totals go to the ledger in the wheel's serial place.
    fn run_events_before(
        &self,
        track: usize,
        state: &mut TrackState,
        work: &mut TrackWork,
        lane: &mut Lane,
        i: usize,
        t: f64,
    ) {
        // Most wheels find nothing due: the window's events at the point
        // come after them (the next train's), or ran before them.
        if !self.events_due(work, i, t) {
            return;
        }
        // The events that have run at the head of the chain are left
        // behind for good.
        let mut link = work.first_event[i];
        while link != NO_EVENT && work.events[link].done {
            link = work.next_event[link];
        }
        work.first_event[i] = link;
        let mut next = f64::INFINITY;
        while link != NO_EVENT {
            let k = link;
            link = work.next_event[k];
            let ev = work.events[k];
            if ev.done {
                continue;
            }
            let due = ev.time_s < t;
            if !due {
                next = next.min(ev.time_s);
                // In time order the rest come no earlier.
                if work.in_time_order[i] {
                    break;
                }
                continue;
            }
            let weather = *self.timeline.at(ev.time_s);
            if let Ran::Pulse(totals) = self.run_point_event(track, state, work, k, &weather) {
                work.ledger.push(Addend {
                    order: lane.serial << 32 | lane.pulses,
                    kind: AddendKind::Pulse(totals),
                });
                lane.pulses += 1;
            }
        }
        work.next_at[i] = next;
    }

    /// A wheel (axle `a` on `track`'s rail) ready to roll: everything that
    /// depends only on the wheel, computed once.
    fn lane(&self, record: &TrainRecord, track: usize, a: usize, row: usize) -> Lane {
        let rails = self.section.rails.len();
        let r = self.track_info[track].rail;
        let wheel = record.wheels[a * rails + r];
        let speed_mps = record.passage.speed_mps;
        let up = enters_at_zero(record.passage.direction);
        // Every wheel enters clean; before it passes an applicator there is
        // no transfer.
        let st = WheelRoll {
            wheel_kg: 0.0,
            bands: [0.0; 3],
            edge_kg: 0.0,
            applicator_point: None,
            consumed_kg: 0.0,
            capped_kg: 0.0,
            lost_kg: 0.0,
            wheel_tan: [0.0; SLOTS],
            edge_tan: [0.0; SLOTS],
            seen_tan: [0.0; SLOTS],
        };
        let generic = self.generic;
        let wheel_generic = |acts_on| {
            generic.factor(
                acts_on,
                Which::Wheel,
                None,
                r,
                When {
                    time_s: 0.0,
                    weather: &tortwin_recording::Weather::default(),
                    wheel: Some(&wheel.drivers),
                },
            )
        };
        let transfer_generic = wheel_generic(ActsOn::Transfer);
        let consumption_generic = wheel_generic(ActsOn::Consumption);
        let speed_n = self.effects.param(Named::SpeedTransfer, 0);
        let speed_factor = speed_n.map_or(1.0, |n| effects::speed_transfer_factor(speed_mps, n));
        // With tangents: the wheel factors' derivatives in the effect
        // parameters followed (a term switched off has none).
        let mut transfer_factor_d = [0.0; EFFECT_SLOTS];
        let mut consumption_generic_d = [0.0; EFFECT_SLOTS];
        for (k, p) in self.effect_params.iter().enumerate() {
            match (*p, self.tangent_width > 0) {
                (
                    Some(EffectParam::Named {
                        effect: Named::SpeedTransfer,
                        param: 0,
                    }),
                    true,
                ) if speed_n.is_some() => {
                    // ∂(v / 20)^(-n) / ∂n = -ln(v / 20) (v / 20)^(-n).
                    transfer_factor_d[k] =
                        -(speed_mps / 20.0).ln() * speed_factor * transfer_generic;
                }
                (Some(EffectParam::Generic { term }), true) => {
                    let at = When {
                        time_s: 0.0,
                        weather: &tortwin_recording::Weather::default(),
                        wheel: Some(&wheel.drivers),
                    };
                    let derivative = |acts_on| {
                        generic
                            .factor_and_derivative(acts_on, Which::Wheel, None, r, at, term)
                            .1
                    };
                    transfer_factor_d[k] = speed_factor * derivative(ActsOn::Transfer);
                    consumption_generic_d[k] = derivative(ActsOn::Consumption);
                }
                _ => {}
            }
        }
        let mut roller = Roller {
            params: *self.product,
            time_effects: self.time_effects,
            t_passage_s: self.time_s(record.log_time_ns),
            offset_m: record.passage.axles[a].offset_m,
            speed_mps,
            d_entry_m: if up { 0.0 } else { self.section.length_m },
            fp_fc: wheel.fp_fc,
            transfer_factor: speed_factor * transfer_generic,
            consumption_generic,
            transfer_varies: generic.varies(ActsOn::Transfer, r),
            consumption_varies: generic.varies(ActsOn::Consumption, r),
            generic: Arc::clone(generic),
            rail: r,
            temperature_beta: self.effects.param(Named::TemperatureConsumption, 0),
            temperature_factor: self
                .effects
                .param(Named::TemperatureConsumption, 0)
                .filter(|_| self.timeline.is_constant())
                .map(|beta_per_k| {
                    effects::temperature_factor(
                        self.timeline.last().current.air_temperature_c,
                        beta_per_k,
                    )
                }),
            reservoir: self
                .effects
                .get(Named::WheelEdgeReservoir)
                .map(|p| (p[0], p[1])),
            observe: self.observe_every_wheel || self.last_axle[track] == a,
            fp_fc_tan: if self.tangent_width > 0 {
                tangent::fp_fc_tangent(
                    self.product,
                    wheel.hertz.pm_pa,
                    wheel.creepage.cx,
                    wheel.creepage.cy,
                )
            } else {
                [0.0; 2]
            },
            effect_params: if self.tangent_width > 0 {
                self.effect_params
            } else {
                [None; EFFECT_SLOTS]
            },
            transfer_factor_d,
            consumption_generic_d,
            temperature_c: self.timeline.last().current.air_temperature_c,
            consumption_constant: None,
            ages: self.time_effects.any(),
        };
        // Neither the weather nor a term driven by time or weather moves it:
        // what every contact would compute (the time and weather unread).
        if !roller.consumption_varies
            && (roller.temperature_factor.is_some() || roller.temperature_beta.is_none())
        {
            let weather = self.timeline.first();
            roller.consumption_constant = Some(roller.consumption_factor(f64::NAN, &weather));
        }
        Lane {
            axle: a,
            row,
            serial: (a * rails + r) as u64,
            pulses: 0,
            st,
            roller,
        }
    }

    /// A pulse landing at `point` of `track` at `time_s` (model.md, "A pulse
    /// landing"): time effects up to now, add, cap, touch. Returns what it
    /// adds to the totals. The pulse changes only the rail's mass: m0 of
    /// eq. (1) is a constant of the product.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn land_pulse(
        &self,
        track: usize,
        state: &mut TrackState,
        rail_tan: &mut [Tangent],
        point: usize,
        time_s: f64,
        applicator: usize,
        mass_kg: f64,
        weather: &WeatherState,
    ) -> PulseTotals {
        let share = mass_kg;
        let mut mass_kg = mass_kg;
        let rail = self.track_info[track].rail;
        let at = When {
            time_s,
            weather: &weather.current,
            wheel: None,
        };
        if self.generic.any(ActsOn::PulseMass) {
            let g = self
                .generic
                .factor(ActsOn::PulseMass, Which::All, Some(applicator), rail, at);
            mass_kg *= g;
        }
        let effects = self.time_effects;
        let precip = weather.precip_mm_at(time_s);
        let mut m = state.rail_mass_kg[point];
        let last = state.last_touch_s[point];
        let mut lost_kg = None;
        let mut tan = rail_tan.get(point).copied();
        if effects.any() && !last.is_nan() {
            let (dt_s, rain_mm) = (time_s - last, precip - state.precip_at_touch_mm[point]);
            let aged = effects.apply(m, dt_s, rain_mm);
            lost_kg = Some(m - aged);
            m = aged;
            // The same multiplications on the tangent.
            if let Some(t) = &mut tan {
                for x in t.iter_mut() {
                    *x = effects.apply(*x, dt_s, rain_mm);
                }
                time_effect_sources(&self.effect_params, &effects, aged, (dt_s, rain_mm), t);
            }
        }
        // The pulse's mass does not depend on the constants; a generic
        // pulse-mass term's parameter moves it.
        m += mass_kg;
        if let Some(t) = &mut tan {
            for (k, p) in self.effect_params.iter().enumerate() {
                if let Some(EffectParam::Generic { term }) = *p {
                    let (_, dg) = self.generic.factor_and_derivative(
                        ActsOn::PulseMass,
                        Which::All,
                        Some(applicator),
                        rail,
                        at,
                        term,
                    );
                    t[effect_slot(k)] += share * dg;
                }
            }
        }
        let capped_kg = match &mut tan {
            Some(t) => tangent::cap(self.product, &mut m, t),
            None => product::cap(self.product, &mut m),
        };
        if let Some(t) = tan {
            rail_tan[point] = t;
        }
        state.rail_mass_kg[point] = m;
        state.last_touch_s[point] = time_s;
        state.precip_at_touch_mm[point] = precip;
        PulseTotals {
            lost_kg,
            applied_kg: mass_kg,
            capped_kg,
        }
    }

    /// A tribometer reading (model.md): eq. (4) with the rail mass alone, the
    /// time effects since the last touch applied to the value read only.
    /// Returns the value, the mass it read and that mass's tangent (from
    /// `rail_tan`, zero when it is empty).
    pub(crate) fn read_rail(
        &self,
        track: usize,
        state: &TrackState,
        rail_tan: &[Tangent],
        point: usize,
        time_s: f64,
        weather: &WeatherState,
    ) -> Reading {
        let mut m = state.rail_mass_kg[point];
        let mut tan = rail_tan.get(point).copied().unwrap_or([0.0; SLOTS]);
        let last = state.last_touch_s[point];
        if self.time_effects.any() && !last.is_nan() {
            let rain = weather.precip_mm_at(time_s) - state.precip_at_touch_mm[point];
            m = self.time_effects.apply(m, time_s - last, rain);
            for x in &mut tan {
                *x = self.time_effects.apply(*x, time_s - last, rain);
            }
            let since = (time_s - last, rain);
            time_effect_sources(&self.effect_params, &self.time_effects, m, since, &mut tan);
        }
        let reading = |value| Reading {
            value,
            mass_kg: m,
            tangent: tan,
        };
        if self.generic.any_friction() {
            let levels = self.generic.friction_levels(
                self.product.mu_d,
                self.product.mu_c,
                self.track_info[track].rail,
                time_s,
                &weather.current,
                None,
            );
            return reading(super::friction_at(self.product, levels, m));
        }
        reading(product::friction(self.product, m))
    }

    /// Runs point event `k` of `track` (a pulse or a reading of the window);
    /// a reading's value goes to the track's readings.
    pub(crate) fn run_point_event(
        &self,
        track: usize,
        state: &mut TrackState,
        work: &mut TrackWork,
        k: usize,
        weather: &WeatherState,
    ) -> Ran {
        let ev = work.events[k];
        let ran = match ev.kind {
            PointEventKind::Pulse {
                applicator,
                mass_kg,
            } => Ran::Pulse(self.land_pulse(
                track,
                state,
                &mut work.rail_tan,
                ev.point,
                ev.time_s,
                applicator,
                mass_kg,
                weather,
            )),
            PointEventKind::Reading => {
                let reading =
                    self.read_rail(track, state, &work.rail_tan, ev.point, ev.time_s, weather);
                work.readings.push((ev.buffered, reading));
                Ran::Reading
            }
        };
        work.events[k].done = true;
        ran
    }
}

impl Engine {
    /// Publishes the field of every track after the train.
    pub(super) fn emit_fields(
        &mut self,
        record: &TrainRecord,
        kind: SnapshotKind,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        if self.line.is_some() {
            for track in 0..self.tracks.len() {
                self.emit_line_field(record, track, kind, record.end_ns, sink)?;
            }
            if kind == SnapshotKind::Train {
                self.emit_line_wheels(record, sink)?;
            }
            return Ok(());
        }
        for track in 0..self.tracks.len() {
            let a = self.last_axle[track];
            // A track no wheel of this train ran on (a band only leading or
            // only trailing axles use) has no "last wheel": nothing to show.
            if a == usize::MAX {
                continue;
            }
            self.emit_field(record, track, a, kind, record.end_ns, sink)?;
        }
        Ok(())
    }

    /// mu of every contact axle `a` made on `track` (its step-2 masses in
    /// `observed`): eq. (4), with muD and muC as the friction terms make
    /// them at each contact's time and weather.
    fn fill_mu(
        &self,
        record: &TrainRecord,
        track: usize,
        a: usize,
        seen_mass_kg: &[f64],
        out: &mut Vec<f64>,
    ) {
        out.clear();
        if !self.generic.any_friction() {
            out.extend(
                seen_mass_kg
                    .iter()
                    .map(|&m| product::friction(&self.cfg.product, m)),
            );
            return;
        }
        let rails = self.section.rails.len();
        let rail = self.track_info[track].rail;
        let wheel = record.wheels[a * rails + rail];
        let up = enters_at_zero(record.passage.direction);
        let d_entry_m = if up { 0.0 } else { self.section.length_m };
        let t_passage_s = self.time_s(record.log_time_ns);
        let offset_m = record.passage.axles.get(a).map_or(0.0, |x| x.offset_m);
        let p = &self.cfg.product;
        for (&d_m, &m) in self.grid.d_m.iter().zip(seen_mass_kg) {
            let t = wheel_time_s(
                t_passage_s,
                d_m,
                d_entry_m,
                offset_m,
                record.passage.speed_mps,
            );
            let levels = self.generic.friction_levels(
                p.mu_d,
                p.mu_c,
                rail,
                t,
                &self.timeline.at(t).current,
                Some(&wheel.drivers),
            );
            out.push(self.friction_at(levels, m));
        }
    }

    fn emit_field(
        &mut self,
        record: &TrainRecord,
        track: usize,
        a: usize,
        kind: SnapshotKind,
        log_time_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let rails = self.section.rails.len();
        let rail = self.track_info[track].rail;
        let wheel = record.wheels[a * rails + rail];
        let mut buf = std::mem::take(&mut self.snapshot);
        buf.adhesion.clear();
        buf.wheel_mass_kg.clear();
        let seen = std::mem::take(&mut self.work[track].observed.mass_kg);
        self.fill_mu(record, track, a, &seen, &mut buf.mu);
        self.work[track].observed.mass_kg = seen;
        let observed = &self.work[track].observed;
        let contact = self.adhesion_contact(&wheel, record.passage.speed_mps);
        for (&mu, &wheel_mass_kg) in buf.mu.iter().zip(&observed.wheel_mass_kg) {
            buf.adhesion.push(contact.forces(mu).t_over_q);
            buf.wheel_mass_kg.push(wheel_mass_kg);
        }
        self.send_field(record, track, kind, log_time_ns, buf, sink)
    }

    /// Hands `track`'s field, computed into `buf`, to the sink, once every
    /// value there is checked finite (on a line, NaN stands where no wheel
    /// used the band: [`Observed::axle`]); `buf` goes back to the engine.
    pub(super) fn send_field(
        &mut self,
        record: &TrainRecord,
        track: usize,
        kind: SnapshotKind,
        log_time_ns: u64,
        buf: SnapshotBuffers,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let info = &self.track_info[track];
        let rail_mass_kg = &self.tracks[track].rail_mass_kg;
        let axle = &self.work[track].observed.axle;
        let touched = |k: usize| axle.get(k).is_none_or(|&a| a != NO_AXLE);
        // (what, values, whether a missing wheel leaves it NaN)
        let columns: [(&str, &[f64], bool); 4] = [
            ("mu", &buf.mu, true),
            ("adhesion", &buf.adhesion, true),
            ("the rail mass", rail_mass_kg, false),
            ("the wheel mass", &buf.wheel_mass_kg, true),
        ];
        let non_finite = match self.opts.non_finite_allowed {
            true => None,
            false => columns.iter().find_map(|(what, values, per_wheel)| {
                let k = (0..values.len())
                    .position(|k| (!per_wheel || touched(k)) && !values[k].is_finite())?;
                Some((what, k, values[k]))
            }),
        };
        if let Some((what, k, value)) = non_finite {
            let band = match self.line {
                Some(_) => format!(", band {}", info.band),
                None => String::new(),
            };
            let error = EngineError::NotFinite {
                what: what.to_string(),
                value,
                topic: "/train/passage",
                log_time_ns: record.log_time_ns,
                index_in_file: record.index_in_file,
                about: format!(
                    "; train `{}`, rail `{}`{band}, d = {} m",
                    record.passage.train_id,
                    info.rail_name,
                    self.grid.d_m.get(k).copied().unwrap_or(f64::NAN)
                ),
            };
            self.snapshot = buf;
            return Err(error);
        }
        let result = sink.field(&FieldSnapshot {
            kind,
            log_time_ns,
            train_id: record.passage.train_id.as_str().into(),
            track,
            rail_name: info.rail_name.as_str().into(),
            band: info.band.as_str().into(),
            wheel_pass: self.tracks[track].wheel_pass,
            d_m: self.grid.d_m.as_slice().into(),
            mu: buf.mu.as_slice().into(),
            adhesion: buf.adhesion.as_slice().into(),
            rail_mass_kg: self.tracks[track].rail_mass_kg.as_slice().into(),
            wheel_mass_kg: buf.wheel_mass_kg.as_slice().into(),
        });
        self.snapshot = buf;
        Ok(result?)
    }
}
