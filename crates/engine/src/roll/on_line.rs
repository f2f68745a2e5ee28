//! Rolling a train on a line (line.md, "One contact"). A wheel's contact
//! at a point changes one band of its tread and one band of the rail head,
//! the row the line puts there for its rail and bogie position; every
//! other band is stored. The bands of one rail meet only through the
//! wheels, so the unit of independence is the rail (its crown and gauge
//! corner tracks together), where on a section it is the track. Each
//! contact is [`Roller::contact`]'s, on the row's tracks, with the wheel's
//! band in `WheelRoll::wheel_kg` for its duration and `fp fc` of the
//! point's segment: a line of one tangent is the section bit for bit.

use super::{
    Addend, AddendKind, Engine, EngineError, Lane, Ran, RollContext, SiteValue, TrackState,
    TrackWork, TrainRecord, NO_APPLICATOR, PARALLEL_MIN_CONTACTS,
};
use crate::line::RAIL_BANDS;
use crate::sink::{FieldSnapshot, Sink};
use crate::{enters_at_zero, SnapshotKind};
use tortwin_model::product;
use tortwin_recording::BogiePosition;

/// Marks a point no wheel of the train touched on a track.
const NO_AXLE: u32 = u32::MAX;

impl Engine {
    /// Rolls every wheel of the train on a line: each rail's wheels in axle
    /// order, the rails on as many threads as rayon offers; totals settled
    /// in the serial order as on a section.
    pub(super) fn roll_train_line(
        &mut self,
        record: &mut TrainRecord,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let rails = self.section.rails.len();
        let axles = record.passage.axles.len();
        let points = self.grid.d_m.len();
        for work in &mut self.work {
            let observed = &mut work.observed;
            observed.mass_kg.fill(f64::NAN);
            observed.wheel_mass_kg.fill(f64::NAN);
            observed.axle.clear();
            observed.axle.resize(points, NO_AXLE);
        }
        let keep_seen = self.opts.every_wheel_contacts;
        if keep_seen {
            for work in self.work.iter_mut().step_by(RAIL_BANDS) {
                work.wheel_seen.clear();
                work.wheel_seen.resize(axles * points, 0.0);
            }
        }
        if !self.opts.snapshot_every_wheel {
            let (mut ctx, states, works) = self.split();
            ctx.keep_seen = keep_seen;
            let record_ref: &TrainRecord = record;
            let parallel = rails > 1
                && rayon::current_num_threads() > 1
                && axles * points >= PARALLEL_MIN_CONTACTS;
            let rail_states = states.chunks_mut(RAIL_BANDS);
            let rail_works = works.chunks_mut(RAIL_BANDS);
            if parallel {
                use rayon::prelude::*;
                states
                    .par_chunks_mut(RAIL_BANDS)
                    .zip(works.par_chunks_mut(RAIL_BANDS))
                    .enumerate()
                    .for_each(|(rail, (states, works))| {
                        ctx.roll_rail_line(record_ref, rail, 0..axles, states, works);
                    });
            } else {
                for (rail, (states, works)) in rail_states.zip(rail_works).enumerate() {
                    ctx.roll_rail_line(record_ref, rail, 0..axles, states, works);
                }
            }
            self.settle(record);
        } else {
            for a in 0..axles {
                for r in 0..rails {
                    let (mut ctx, states, works) = self.split();
                    ctx.keep_seen = keep_seen;
                    let tracks = r * RAIL_BANDS..(r + 1) * RAIL_BANDS;
                    ctx.roll_rail_line(
                        record,
                        r,
                        a..a + 1,
                        &mut states[tracks.clone()],
                        &mut works[tracks.clone()],
                    );
                    self.settle(record);
                    let end_ns = self.wheel_exit_ns(record, a);
                    for track in tracks {
                        self.emit_line_field(record, track, SnapshotKind::Wheel, end_ns, sink)?;
                    }
                }
            }
        }
        if keep_seen {
            for a in 0..axles {
                for r in 0..rails {
                    let track = r * RAIL_BANDS;
                    let seen = std::mem::take(&mut self.work[track].wheel_seen);
                    let row = &seen[a * points..(a + 1) * points];
                    let result = self.wheel_contacts(record, track, r, a, row, sink);
                    self.work[track].wheel_seen = seen;
                    result?;
                }
            }
        }
        Ok(())
    }

    /// The wheel that made axle `axle`'s contact at measurement site `site`
    /// on `rail`: on a line, with its load and creepage in the site's
    /// segment.
    pub(crate) fn wheel_at_site<'r>(
        &self,
        record: &'r TrainRecord,
        axle: usize,
        rail: usize,
        site: usize,
    ) -> &'r crate::WheelOnRail {
        let rails = self.section.rails.len();
        match &self.line {
            Some(layout) => {
                let segment = layout.segment_of(self.site_points[site]);
                &record.seg_wheels[(axle * rails + rail) * layout.segments() + segment]
            }
            None => &record.wheels[axle * rails + rail],
        }
    }

    /// On a line: every wheel of the train per segment, with the load and
    /// creepage its axle gives for the segment (the axle field `segments`;
    /// its own where it gives none), into [`TrainRecord::seg_wheels`].
    pub(crate) fn line_wheels(&mut self, record: &mut TrainRecord) {
        record.seg_wheels.clear();
        let Some(segments) = self.line.as_ref().map(|l| l.segments()) else {
            return;
        };
        let rails = self.section.rails.len();
        let speed_mps = record.passage.speed_mps;
        for (a, axle) in record.passage.axles.iter().enumerate() {
            for rail in 0..rails {
                let own = record.wheels[a * rails + rail];
                for segment in 0..segments {
                    let entry = axle.segments.iter().find(|e| e.segment == segment);
                    let wheel = match entry {
                        None => own,
                        Some(e) => {
                            let q_n = e
                                .wheel_load_n
                                .as_ref()
                                .and_then(|q| q.get(rail).copied())
                                .unwrap_or(own.q_n);
                            let creepage = e
                                .creepage
                                .as_ref()
                                .and_then(|c| c.get(rail).copied())
                                .unwrap_or(own.creepage);
                            self.wheel_on_rail(axle, rail, q_n, creepage, speed_mps)
                        }
                    };
                    record.seg_wheels.push(wheel);
                }
            }
        }
    }

    /// The field of one track of a line after the train (line.md, "Outputs
    /// and state"): at each point what the train's last wheel whose contact
    /// there used this rail band saw, NaN (null in the outputs) where none
    /// did; the band's rail mass.
    pub(super) fn emit_line_field(
        &mut self,
        record: &TrainRecord,
        track: usize,
        kind: SnapshotKind,
        log_time_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let Some(layout) = self.line.as_ref() else {
            return Ok(());
        };
        let rails = self.section.rails.len();
        let segments = layout.segments();
        let rail = self.track_info[track].rail;
        let mut buf = std::mem::take(&mut self.snapshot);
        buf.mu.clear();
        buf.adhesion.clear();
        buf.wheel_mass_kg.clear();
        let observed = &self.work[track].observed;
        let speed_mps = record.passage.speed_mps;
        // The contact of the last (axle, segment) met: consecutive points
        // mostly share both.
        let mut contact = None;
        for (i, (&m, &a)) in observed.mass_kg.iter().zip(&observed.axle).enumerate() {
            if a == NO_AXLE {
                buf.mu.push(f64::NAN);
                buf.adhesion.push(f64::NAN);
                buf.wheel_mass_kg.push(f64::NAN);
                continue;
            }
            let mu = product::friction(&self.cfg.product, m);
            let key = (a as usize * rails + rail) * segments + layout.segment_of(i);
            let polach = match contact {
                Some((k, c)) if k == key => c,
                _ => {
                    let c = self.adhesion_contact(&record.seg_wheels[key], speed_mps);
                    contact = Some((key, c));
                    c
                }
            };
            buf.mu.push(mu);
            buf.adhesion.push(polach.forces(mu).t_over_q);
            buf.wheel_mass_kg.push(observed.wheel_mass_kg[i]);
        }
        let info = &self.track_info[track];
        let rail_mass_kg = &self.tracks[track].rail_mass_kg;
        let touched = |k: usize| observed.axle[k] != NO_AXLE;
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
            let error = EngineError::NotFinite {
                what: what.to_string(),
                value,
                topic: "/train/passage",
                log_time_ns: record.log_time_ns,
                index_in_file: record.index_in_file,
                about: format!(
                    "; train `{}`, rail `{}`, band {}, d = {} m",
                    record.passage.train_id,
                    info.rail_name,
                    info.band,
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

impl RollContext<'_> {
    /// The wheels of `axles` on `rail` of a line, one after the other over
    /// every point of their path; `states` and `works` are the rail's
    /// tracks (crown, gauge corner).
    pub(super) fn roll_rail_line(
        &self,
        record: &TrainRecord,
        rail: usize,
        axles: std::ops::Range<usize>,
        states: &mut [TrackState],
        works: &mut [TrackWork],
    ) {
        let Some(layout) = self.line else {
            return;
        };
        let points = self.d_m.len();
        let rails = self.section.rails.len();
        let segments = layout.segments();
        let up = enters_at_zero(record.passage.direction);
        let crown = rail * RAIL_BANDS;
        for a in axles {
            let trailing = record.passage.axles[a].bogie_position == BogiePosition::Trailing;
            let mut lane = self.lane(record, crown, a, a);
            lane.roller.observe = true;
            let wheels = &record.seg_wheels[(a * rails + rail) * segments..][..segments];
            let mut segment = usize::MAX;
            for step in 0..points {
                let i = if up { step } else { points - 1 - step };
                let s = layout.segment_of(i);
                if s != segment {
                    segment = s;
                    lane.roller.fp_fc = wheels[s].fp_fc;
                }
                let (wb, rb) = layout.row(rail, trailing, i);
                lane.st.wheel_kg = lane.st.bands[wb];
                let m_kg = if self.special[crown][i] {
                    self.line_special_contact(rail, states, works, &mut lane, i, rb)
                } else {
                    self.contact(&mut lane, &mut states[rb], &mut works[rb], i)
                };
                lane.st.bands[wb] = lane.st.wheel_kg;
                works[rb].observed.axle[i] = a as u32;
                if self.keep_seen {
                    works[0].wheel_seen[a * points + i] = m_kg;
                }
            }
            // What it carries off the line: its three bands.
            let [f, c, g] = lane.st.bands;
            lane.st.wheel_kg = f + c + g;
            self.finish_lane(&lane, &mut states[0], &mut works[0], points);
            states[1].wheel_pass += 1;
        }
    }

    /// A contact at a special point of a line: the pulses and readings there
    /// on either band of the rail that come before this wheel run first
    /// (line.md: before the first wheel, either bogie position, that
    /// reaches the point after them), then the contact on rail band `rb`.
    fn line_special_contact(
        &self,
        rail: usize,
        states: &mut [TrackState],
        works: &mut [TrackWork],
        lane: &mut Lane,
        i: usize,
        rb: usize,
    ) -> f64 {
        let t = lane.roller.time_at(self.d_m, i);
        for (band, (state, work)) in states.iter_mut().zip(works.iter_mut()).enumerate() {
            if work.pending_at[i] == 0 {
                continue;
            }
            let track = rail * RAIL_BANDS + band;
            for k in 0..work.events.len() {
                let ev = work.events[k];
                if !ev.done && ev.point == i && ev.time_s < t {
                    let weather = *self.timeline.at(ev.time_s);
                    if let Ran::Pulse(totals) =
                        self.run_point_event(track, state, work, k, &weather)
                    {
                        work.ledger.push(Addend {
                            order: lane.serial << 32 | lane.pulses,
                            kind: AddendKind::Pulse(totals),
                        });
                        lane.pulses += 1;
                    }
                }
            }
        }
        if self.applicator_at[rail * RAIL_BANDS][i] != NO_APPLICATOR {
            // The wheel passes this applicator on whatever band it runs.
            lane.st.applicator_point = Some(i);
        }
        let m_kg = self.contact(lane, &mut states[rb], &mut works[rb], i);
        let sites_here = &self.sites_at[i];
        if sites_here.is_empty() {
            return m_kg;
        }
        let weather = self.timeline.at(t).current;
        let (rails, sites) = (self.section.rails.len(), self.section.sites.len());
        for &s in sites_here {
            works[rb].sites.push(SiteValue {
                index: (lane.axle * rails + rail) * sites + s,
                mass_kg: m_kg,
                // A line takes no friction terms (line::check_config).
                levels: None,
                time_s: t,
                weather,
                tangent: lane.st.seen_tan,
            });
        }
        m_kg
    }
}
