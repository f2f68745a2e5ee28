//! The stepping loop: one wheel over every grid point of one track, in the
//! order of model.md "One contact". This is the hot path: no allocation,
//! everything that depends only on the wheel computed once before the loop.

use std::sync::Arc;

use super::generic::{GenericSet, When, Which};
use super::weather::WeatherTimeline;
use super::{
    enters_at_zero, Engine, EngineError, SnapshotKind, TrackState, TrainRecord, NO_APPLICATOR,
};
use crate::sink::{FieldSnapshot, Sink, WheelContacts};
use tortwin_model::effects::{self, Named, TimeEffects};
use tortwin_model::generic::ActsOn;
use tortwin_model::product::{self, ContactConditions, ProductParams};

/// What a wheel saw at every point of its track (kept for the last wheel of
/// each track, or for every wheel when a sink asks for it).
#[derive(Debug, Clone, Default)]
pub(crate) struct Observed {
    /// Total mass at step 2, per point.
    pub(crate) mass_kg: Vec<f64>,
    /// The wheel's mass after the contact (after step 6), per point.
    pub(crate) wheel_mass_kg: Vec<f64>,
}

impl Observed {
    pub(crate) fn new(points: usize) -> Self {
        Self {
            mass_kg: vec![0.0; points],
            wheel_mass_kg: vec![0.0; points],
        }
    }
}

/// The rolling wheel's own state.
struct WheelRoll {
    wheel_kg: f64,
    /// The wheel_edge_reservoir effect's m_e.
    edge_kg: f64,
    m0_kg: f64,
    /// Grid point of the applicator passed last (N = 1 there).
    applicator_point: Option<usize>,
    consumed_kg: f64,
    capped_kg: f64,
    lost_kg: f64,
}

/// What a contact needs that depends only on the wheel: computed once.
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
    /// mass of step 2 (what a measurement of this contact sees).
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
        let t = self.time_at(d_m, i);
        // Step 1: time effects since the last touch; touch.
        let weather = timeline.at(t);
        let precip_mm = weather.precip_mm_at(t);
        let mut rail_kg = track.rail_mass_kg[i];
        let last = track.last_touch_s[i];
        if self.time_effects.any() && !last.is_nan() {
            let aged =
                self.time_effects
                    .apply(rail_kg, t - last, precip_mm - track.precip_at_touch_mm[i]);
            st.lost_kg += rail_kg - aged;
            rail_kg = aged;
        }
        track.last_touch_s[i] = t;
        track.precip_at_touch_mm[i] = precip_mm;

        // Step 2: what a measurement of this contact sees.
        let m_kg = st.wheel_kg + rail_kg;

        // Steps 3 to 5: transfer, consumption, cap. Effect factors: the
        // named effect's first, then the generic terms'.
        let mut transfer_factor = self.transfer_factor;
        if self.transfer_varies {
            transfer_factor *= self.event_factor(ActsOn::Transfer, t, weather);
        }
        let mut consumption_factor = match (self.temperature_factor, self.temperature_beta) {
            (Some(constant), _) => constant,
            (None, Some(beta)) => {
                effects::temperature_factor(weather.current.air_temperature_c, beta)
            }
            (None, None) => 1.0,
        } * self.consumption_generic;
        if self.consumption_varies {
            consumption_factor *= self.event_factor(ActsOn::Consumption, t, weather);
        }
        let conditions = ContactConditions {
            m0_kg: st.m0_kg,
            fp_fc: self.fp_fc,
            transfer_revolution: st
                .applicator_point
                .map(|ia| revolution[i.abs_diff(ia)] * transfer_factor),
            consumption_factor,
        };
        let losses = product::roll(&self.params, &mut st.wheel_kg, &mut rail_kg, &conditions);
        st.consumed_kg += losses.consumed_kg;
        st.capped_kg += losses.capped_kg;

        // Step 6: wheel-side effects.
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

impl Roller {
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

/// A wheel's time at a point: `t_passage + (|d - d_entry| + offset) / v`
/// (model.md, computed in that form).
#[inline(always)]
fn wheel_time_s(t_passage_s: f64, d_m: f64, d_entry_m: f64, offset_m: f64, speed_mps: f64) -> f64 {
    t_passage_s + ((d_m - d_entry_m).abs() + offset_m) / speed_mps
}

/// Reused buffers for the field snapshots.
#[derive(Debug, Default)]
pub(crate) struct SnapshotBuffers {
    mu: Vec<f64>,
    /// mu of every contact of one wheel, for [`WheelContacts::mu`].
    contact_mu: Vec<f64>,
    adhesion: Vec<f64>,
    wheel_mass_kg: Vec<f64>,
}

impl Engine {
    /// Rolls every wheel of the train, axle by axle, rail by rail.
    pub(super) fn roll_train(
        &mut self,
        record: &mut TrainRecord,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let rails = self.section.rails.len();
        let axles = record.passage.axles.len();
        self.last_axle.fill(usize::MAX);
        for a in 0..axles {
            for r in 0..rails {
                self.last_axle[record.wheels[a * rails + r].track] = a;
            }
        }
        for a in 0..axles {
            for r in 0..rails {
                let track = record.wheels[a * rails + r].track;
                let observe = self.opts.snapshot_every_wheel
                    || self.opts.every_wheel_contacts
                    || self.last_axle[track] == a;
                self.roll_wheel(record, a, r, observe);
                if self.opts.every_wheel_contacts {
                    // With friction terms mu is not eq. (4) of the mass alone.
                    let mut mu = std::mem::take(&mut self.snapshot.contact_mu);
                    let with_terms = self.generic.any_friction();
                    if with_terms {
                        self.fill_mu(record, track, a, &mut mu);
                    }
                    let result = sink.wheel_contacts(&WheelContacts {
                        track,
                        rail: r,
                        direction: record.passage.direction,
                        train_seq: record.passage.train_seq,
                        axle: a,
                        seen_mass_kg: &self.observed[track].mass_kg,
                        mu: with_terms.then_some(mu.as_slice()),
                    });
                    self.snapshot.contact_mu = mu;
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

    /// The log_time at which axle `a` leaves the section: the passage's
    /// log_time plus its time on the section in integer nanoseconds.
    fn wheel_exit_ns(&self, record: &TrainRecord, a: usize) -> u64 {
        let offset = record.passage.axles.get(a).map_or(0.0, |x| x.offset_m);
        let on_section_s = (self.section.length_m + offset) / record.passage.speed_mps;
        record
            .log_time_ns
            .saturating_add((on_section_s * 1e9).round() as u64)
    }

    /// One wheel (axle `a` on rail `r`) over every grid point of its track.
    ///
    /// The path runs in tight segments between the track's special points
    /// (applicators and measurement sites, the only places where a pulse
    /// lands, a reading is taken or a contact is recorded); at a special
    /// point the events that come before this wheel run first.
    fn roll_wheel(&mut self, record: &mut TrainRecord, a: usize, r: usize, observe: bool) {
        let rails = self.section.rails.len();
        let sites = self.section.sites.len();
        let wheel = record.wheels[a * rails + r];
        let track = wheel.track;
        let n_tracks = self.tracks.len();
        let speed_mps = record.passage.speed_mps;
        let up = enters_at_zero(record.passage.direction);
        let points = self.grid.d_m.len();
        let point_of = |step: usize| if up { step } else { points - 1 - step };

        // Every wheel enters clean; before it passes an applicator, m0 is the
        // first listed applicator's nominal pulse and there is no transfer.
        let mut st = WheelRoll {
            wheel_kg: 0.0,
            edge_kg: 0.0,
            m0_kg: self
                .section
                .applicators
                .first()
                .map_or(0.0, |x| x.nominal_pulse_kg),
            applicator_point: None,
            consumed_kg: 0.0,
            capped_kg: 0.0,
            lost_kg: 0.0,
        };
        let generic = &self.generic;
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
        let roller = Roller {
            params: self.cfg.product,
            time_effects: self.time_effects,
            t_passage_s: self.time_s(record.log_time_ns),
            offset_m: record.passage.axles[a].offset_m,
            speed_mps,
            d_entry_m: if up { 0.0 } else { self.section.length_m },
            fp_fc: wheel.fp_fc,
            transfer_factor: self
                .cfg
                .effects
                .param(Named::SpeedTransfer, 0)
                .map_or(1.0, |n| effects::speed_transfer_factor(speed_mps, n))
                * transfer_generic,
            consumption_generic,
            transfer_varies: generic.varies(ActsOn::Transfer, r),
            consumption_varies: generic.varies(ActsOn::Consumption, r),
            generic: Arc::clone(generic),
            rail: r,
            temperature_beta: self.cfg.effects.param(Named::TemperatureConsumption, 0),
            temperature_factor: self
                .cfg
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
                .cfg
                .effects
                .get(Named::WheelEdgeReservoir)
                .map(|p| (p[0], p[1])),
            observe,
        };

        let mut next_special = if up {
            0
        } else {
            self.special_points[track].len()
        };
        let mut step = 0;
        while step < points {
            // The next special point on the path, as a step.
            let specials = &self.special_points[track];
            let special_step = if up {
                specials.get(next_special).copied()
            } else {
                next_special
                    .checked_sub(1)
                    .and_then(|k| specials.get(k))
                    .map(|&i| points - 1 - i)
            }
            .unwrap_or(points);
            {
                let d_m = &self.grid.d_m;
                let revolution = &self.revolution;
                let timeline = &self.timeline;
                let state = &mut self.tracks[track];
                let observed = &mut self.observed[track];
                for s in step..special_step {
                    roller.contact(
                        &mut st,
                        state,
                        observed,
                        d_m,
                        revolution,
                        timeline,
                        point_of(s),
                    );
                }
            }
            if special_step == points {
                break;
            }
            let i = point_of(special_step);
            let t = roller.time_at(&self.grid.d_m, i);
            // Pulses and readings at this point that come before this wheel.
            if self.pending_at[track][i] > 0 {
                for k in 0..self.point_events[track].len() {
                    let ev = self.point_events[track][k];
                    if !ev.done && ev.point == i && ev.time_s < t {
                        let weather = *self.timeline.at(ev.time_s);
                        self.run_point_event(track, k, &weather);
                    }
                }
            }
            let app = self.applicator_at[track][i];
            if app != NO_APPLICATOR {
                // The wheel passes this applicator: N counts from here and m0
                // is its latest pulse that landed before this wheel.
                st.applicator_point = Some(i);
                let latest = self.latest_pulse_kg[app as usize * n_tracks + track];
                st.m0_kg = if latest.is_nan() {
                    self.section.applicators[app as usize].nominal_pulse_kg
                } else {
                    latest
                };
            }
            let m_kg = roller.contact(
                &mut st,
                &mut self.tracks[track],
                &mut self.observed[track],
                &self.grid.d_m,
                &self.revolution,
                &self.timeline,
                i,
            );
            for &s in &self.sites_at[i] {
                record.site_mass_kg[(a * rails + r) * sites + s] = m_kg;
            }
            if !record.site_levels.is_empty() {
                let p = &self.cfg.product;
                let levels = self.generic.friction_levels(
                    p.mu_d,
                    p.mu_c,
                    r,
                    t,
                    &self.timeline.at(t).current,
                    Some(&wheel.drivers),
                );
                for &s in &self.sites_at[i] {
                    record.site_levels[(a * rails + r) * sites + s] = levels;
                }
            }
            step = special_step + 1;
            if up {
                next_special += 1;
            } else {
                next_special -= 1;
            }
        }

        let t = &mut self.totals;
        t.wheels += 1;
        t.contacts += points as u64;
        t.consumed_kg += st.consumed_kg;
        t.capped_kg += st.capped_kg;
        t.effects_lost_kg += st.lost_kg;
        t.carried_out_kg += st.wheel_kg + st.edge_kg;
        self.tracks[track].wheel_pass += 1;
    }

    /// Publishes the field of every track after the train.
    pub(super) fn emit_fields(
        &mut self,
        record: &TrainRecord,
        kind: SnapshotKind,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
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
    fn fill_mu(&self, record: &TrainRecord, track: usize, a: usize, out: &mut Vec<f64>) {
        out.clear();
        let observed = &self.observed[track];
        if !self.generic.any_friction() {
            out.extend(
                observed
                    .mass_kg
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
        for (&d_m, &m) in self.grid.d_m.iter().zip(&observed.mass_kg) {
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
        self.fill_mu(record, track, a, &mut buf.mu);
        let observed = &self.observed[track];
        for (&mu, &wheel_mass_kg) in buf.mu.iter().zip(&observed.wheel_mass_kg) {
            buf.adhesion
                .push(self.adhesion(&wheel, record.passage.speed_mps, mu));
            buf.wheel_mass_kg.push(wheel_mass_kg);
        }
        let info = &self.track_info[track];
        let result = sink.field(&FieldSnapshot {
            kind,
            log_time_ns,
            train_id: &record.passage.train_id,
            track,
            rail_name: &info.rail_name,
            band: &info.band,
            wheel_pass: self.tracks[track].wheel_pass,
            d_m: &self.grid.d_m,
            mu: &buf.mu,
            adhesion: &buf.adhesion,
            rail_mass_kg: &self.tracks[track].rail_mass_kg,
            wheel_mass_kg: &buf.wheel_mass_kg,
        });
        self.snapshot = buf;
        Ok(result?)
    }
}
