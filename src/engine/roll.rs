//! The stepping loop: one wheel over every grid point of one track, in the
//! order of model.md "One contact". This is the hot path: no allocation,
//! everything that depends only on the wheel computed once before the loop.

use anyhow::Result;

use super::{enters_at_zero, Engine, SnapshotKind, TrainRecord, NO_APPLICATOR};
use crate::model::product::{self, ContactConditions};
use crate::sink::{FieldSnapshot, Sink};

/// What a wheel saw at one point (kept for the last wheel of each track).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Observed {
    /// Total mass at step 2.
    pub mass_kg: f64,
    /// The wheel's mass after the contact (after step 6).
    pub wheel_mass_kg: f64,
}

/// Reused buffers for the field snapshots.
#[derive(Debug, Default)]
pub(crate) struct SnapshotBuffers {
    mu: Vec<f64>,
    adhesion: Vec<f64>,
    wheel_mass_kg: Vec<f64>,
}

impl Engine {
    /// Rolls every wheel of the train, axle by axle, rail by rail.
    pub(super) fn roll_train(
        &mut self,
        record: &mut TrainRecord,
        sink: &mut dyn Sink,
    ) -> Result<()> {
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
                let observe = self.opts.snapshot_every_wheel || self.last_axle[track] == a;
                self.roll_wheel(record, a, r, observe);
                if self.opts.snapshot_every_wheel {
                    let end_s = self.wheel_exit_s(record, a);
                    let end_ns = (self.origin_ns as f64 + end_s * 1e9).round() as u64;
                    self.emit_field(record, track, a, SnapshotKind::Wheel, end_ns, sink)?;
                }
            }
        }
        Ok(())
    }

    /// time_s at which axle `a` leaves the section.
    fn wheel_exit_s(&self, record: &TrainRecord, a: usize) -> f64 {
        let t_pass = self.time_s(record.log_time_ns);
        let offset = record.passage.axles.get(a).map_or(0.0, |x| x.offset_m);
        t_pass + (self.section.length_m + offset) / record.passage.speed_mps
    }

    /// One wheel (axle `a` on rail `r`) over every grid point of its track.
    fn roll_wheel(&mut self, record: &mut TrainRecord, a: usize, r: usize, observe: bool) {
        let rails = self.section.rails.len();
        let sites = self.section.sites.len();
        let wheel = record.wheels[a * rails + r];
        let track = wheel.track;
        let n_tracks = self.tracks.len();
        let params = self.cfg.product;
        let time_effects = self.time_effects;
        let speed_mps = record.passage.speed_mps;
        let offset_m = record.passage.axles[a].offset_m;
        let t_passage = self.time_s(record.log_time_ns);
        let up = enters_at_zero(record.passage.direction);
        let d_entry = if up { 0.0 } else { self.section.length_m };
        let points = self.grid.d_m.len();

        // Effects that depend only on the wheel.
        let transfer_factor = self
            .cfg
            .effects
            .speed_transfer
            .map_or(1.0, |e| (speed_mps / 20.0).powf(-e.n));
        let temperature_beta = self
            .cfg
            .effects
            .temperature_consumption
            .map(|e| e.beta_per_k);
        let reservoir = self.cfg.effects.wheel_edge_reservoir;

        // Every wheel enters clean; before it passes an applicator, m0 is the
        // first listed applicator's nominal pulse and there is no transfer.
        let mut wheel_kg = 0.0;
        let mut edge_kg = 0.0;
        let mut m0_kg = self
            .section
            .applicators
            .first()
            .map_or(0.0, |x| x.nominal_pulse_kg);
        let mut applicator_point: Option<usize> = None;
        let mut consumed_kg = 0.0;
        let mut capped_kg = 0.0;
        let mut lost_kg = 0.0;

        for step in 0..points {
            let i = if up { step } else { points - 1 - step };
            let t = t_passage + ((self.grid.d_m[i] - d_entry).abs() + offset_m) / speed_mps;

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

            // Step 1: time effects since the last touch; touch.
            let weather = self.timeline.at(t);
            let precip_mm = weather.precip_mm_at(t);
            let temperature_c = weather.current.air_temperature_c;
            let state = &mut self.tracks[track];
            let mut rail_kg = state.rail_mass_kg[i];
            let last = state.last_touch_s[i];
            if time_effects.any() && !last.is_nan() {
                let aged =
                    time_effects.apply(rail_kg, t - last, precip_mm - state.precip_at_touch_mm[i]);
                lost_kg += rail_kg - aged;
                rail_kg = aged;
            }
            state.last_touch_s[i] = t;
            state.precip_at_touch_mm[i] = precip_mm;

            // Step 2: what a measurement of this contact sees.
            let m_kg = wheel_kg + rail_kg;
            if self.special[track][i] {
                for &s in &self.sites_at[i] {
                    record.site_mass_kg[(a * rails + r) * sites + s] = m_kg;
                }
                let app = self.applicator_at[track][i];
                if app != NO_APPLICATOR {
                    // The wheel passes this applicator: N counts from here and
                    // m0 is its latest pulse (that landed before this wheel).
                    applicator_point = Some(i);
                    let latest = self.latest_pulse_kg[app as usize * n_tracks + track];
                    m0_kg = if latest.is_nan() {
                        self.section.applicators[app as usize].nominal_pulse_kg
                    } else {
                        latest
                    };
                }
            }

            // Steps 3 to 5: transfer, consumption, cap.
            let conditions = ContactConditions {
                m0_kg,
                fp_fc: wheel.fp_fc,
                transfer_revolution: applicator_point
                    .map(|ia| self.revolution[i.abs_diff(ia)] * transfer_factor),
                consumption_factor: temperature_beta
                    .map_or(1.0, |b| (b * (temperature_c - 20.0)).exp()),
            };
            let losses = product::roll(&params, &mut wheel_kg, &mut rail_kg, &conditions);
            consumed_kg += losses.consumed_kg;
            capped_kg += losses.capped_kg;

            // Step 6: wheel-side effects.
            if let Some(e) = reservoir {
                let parked = e.alpha * wheel_kg;
                wheel_kg -= parked;
                edge_kg += parked;
                let back = e.r * edge_kg;
                edge_kg -= back;
                wheel_kg += back;
            }

            self.tracks[track].rail_mass_kg[i] = rail_kg;
            if observe {
                self.observed[track][i] = Observed {
                    mass_kg: m_kg,
                    wheel_mass_kg: wheel_kg,
                };
            }
        }

        let t = &mut self.totals;
        t.wheels += 1;
        t.contacts += points as u64;
        t.consumed_kg += consumed_kg;
        t.capped_kg += capped_kg;
        t.effects_lost_kg += lost_kg;
        t.carried_out_kg += wheel_kg + edge_kg;
        self.tracks[track].wheel_pass += 1;
    }

    /// Publishes the field of every track after the train.
    pub(super) fn emit_fields(
        &mut self,
        record: &TrainRecord,
        kind: SnapshotKind,
        sink: &mut dyn Sink,
    ) -> Result<()> {
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

    fn emit_field(
        &mut self,
        record: &TrainRecord,
        track: usize,
        a: usize,
        kind: SnapshotKind,
        log_time_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<()> {
        let rails = self.section.rails.len();
        let rail = self.track_info[track].rail;
        let wheel = record.wheels[a * rails + rail];
        let mut buf = std::mem::take(&mut self.snapshot);
        buf.mu.clear();
        buf.adhesion.clear();
        buf.wheel_mass_kg.clear();
        for o in &self.observed[track] {
            let mu = product::friction(&self.cfg.product, o.mass_kg);
            buf.mu.push(mu);
            buf.adhesion
                .push(self.adhesion(&wheel, record.passage.speed_mps, mu));
            buf.wheel_mass_kg.push(o.wheel_mass_kg);
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
        result
    }
}
