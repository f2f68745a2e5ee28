//! Rolling a train on a line (line.md, "One contact"). A wheel's contact
//! at a point changes one band of its tread and one band of the rail head,
//! the row the line puts there for its rail and bogie position; every
//! other band is stored. The bands of one rail meet only through the
//! wheels, so the unit of independence is the rail (its crown and gauge
//! corner tracks together), where on a section it is the track. Each
//! contact is [`Roller::contact`]'s, on the row's tracks, with the wheel's
//! band in `WheelRoll::wheel_kg` for its duration and `fp fc` of the
//! point's segment: a line of one tangent is the section bit for bit.

#[cfg(target_arch = "x86_64")]
use super::exp4_is_vectorised;
use super::{
    clock_free, lane_points, parallel_min_contacts, point_of, pool_has_threads, wheel_time_s,
    Clocks, Div4, Engine, EngineError, Exp4, Lane, NoRun, Roll4, RollContext, SiteValue,
    TrackState, TrackWork, TrainRecord, Vector, LANES, NO_APPLICATOR, NO_AXLE,
};
use crate::line::{LineLayout, RAIL_BANDS};
use crate::sink::Sink;
use crate::{enters_at_zero, SnapshotKind};
use tortwin_model::product;
use tortwin_recording::BogiePosition;

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
        let watch = self.watched_axles(record);
        if watch[0] != usize::MAX {
            for work in self.work.iter_mut().step_by(RAIL_BANDS) {
                let watched = &mut work.watched;
                for v in watched.seen_kg.iter_mut().chain(&mut watched.bands_kg) {
                    v.clear();
                    v.resize(points, f64::NAN);
                }
            }
        }
        let last_at = |position: BogiePosition| {
            let axles = &record.passage.axles;
            axles.iter().rposition(|a| a.bogie_position == position)
        };
        let observers = [BogiePosition::Leading, BogiePosition::Trailing]
            .map(|position| last_at(position).unwrap_or(usize::MAX));
        let keep_seen = self.opts.every_wheel_contacts;
        if keep_seen {
            for work in self.work.iter_mut().step_by(RAIL_BANDS) {
                work.wheel_seen.clear();
                work.wheel_seen.resize(axles * points, 0.0);
            }
        }
        if !self.opts.snapshot_every_wheel {
            let min_contacts = parallel_min_contacts(&self.opts);
            let (mut ctx, states, works) = self.split();
            ctx.keep_seen = keep_seen;
            ctx.watch = watch;
            ctx.observers = observers;
            let record_ref: &TrainRecord = record;
            let parallel = rails > 1 && axles * points >= min_contacts && pool_has_threads();
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
                let rails = states
                    .chunks_mut(RAIL_BANDS)
                    .zip(works.chunks_mut(RAIL_BANDS));
                for (rail, (states, works)) in rails.enumerate() {
                    ctx.roll_rail_line(record_ref, rail, 0..axles, states, works);
                }
            }
            self.settle(record);
        } else {
            for a in 0..axles {
                for r in 0..rails {
                    let (mut ctx, states, works) = self.split();
                    ctx.keep_seen = keep_seen;
                    ctx.watch = watch;
                    ctx.observers = observers;
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

    /// The axles [`crate::EngineOptions::line_axle`] asks to watch in this
    /// train (`usize::MAX` twice when none): the chosen one and the next,
    /// the last two when the train is shorter.
    fn watched_axles(&self, record: &TrainRecord) -> [usize; 2] {
        let axles = record.passage.axles.len();
        match self.opts.line_axle {
            Some(k) if axles > 0 => {
                let first = k.min(axles.saturating_sub(2));
                [first, (first + 1).min(axles - 1)]
            }
            _ => [usize::MAX; 2],
        }
    }

    /// What the watched axles saw along each rail of the line, to
    /// [`Sink::line_wheels`] after the train's fields.
    pub(crate) fn emit_line_wheels(
        &mut self,
        record: &TrainRecord,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let axles = self.watched_axles(record);
        if axles[0] == usize::MAX || self.line.is_none() {
            return Ok(());
        }
        let product = &self.cfg.product;
        let friction = |masses: &[f64]| -> Vec<f64> {
            masses
                .iter()
                .map(|&m| product::friction(product, m))
                .collect()
        };
        for (rail, rail_name) in self.section.rails.iter().enumerate() {
            let crown = rail * RAIL_BANDS;
            let watched = &self.work[crown].watched;
            let wheels = crate::sink::LineWheels {
                log_time_ns: record.end_ns,
                train_id: std::borrow::Cow::Borrowed(&record.passage.train_id),
                rail,
                rail_name: std::borrow::Cow::Borrowed(rail_name),
                axles,
                bogie_positions: axles.map(|a| record.passage.axles[a].bogie_position),
                mu: [0, 1].map(|k| friction(&watched.seen_kg[k]).into()),
                rail_mu: friction(&self.tracks[crown].rail_mass_kg).into(),
                bands_kg: [0, 1, 2].map(|b| std::borrow::Cow::Borrowed(&watched.bands_kg[b][..])),
            };
            sink.line_wheels(&wheels)?;
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
        self.send_field(record, track, kind, log_time_ns, buf, sink)
    }
}

impl RollContext<'_> {
    /// The wheels of `axles` on `rail` of a line, in axle order, [`LANES`]
    /// at a time in a wavefront as on a section ([`RollContext::roll_group`]);
    /// with tangents (never asked for on a line today) one after the
    /// other. `states` and `works` are the rail's tracks (crown, gauge
    /// corner).
    pub(super) fn roll_rail_line(
        &self,
        record: &TrainRecord,
        rail: usize,
        axles: std::ops::Range<usize>,
        states: &mut [TrackState],
        works: &mut [TrackWork],
    ) {
        let points = self.d_m.len();
        if self.tangent_width > 0 {
            for a in axles {
                let mut lane = self.line_lane(record, rail, a);
                self.roll_wheel_line(record, rail, &mut lane, 0..points, states, works);
                self.finish_line_lane(&mut lane, states, works);
            }
            return;
        }
        let mut first = axles.start;
        let mut touches_left_out = false;
        while first < axles.end {
            let group = first..axles.end.min(first + LANES);
            first = group.end;
            #[cfg(target_arch = "x86_64")]
            if !self.portable && exp4_is_vectorised() {
                // SAFETY: the CPU has AVX2 and FMA.
                touches_left_out |=
                    unsafe { self.roll_group_line_fma(record, rail, group, states, works) };
                continue;
            }
            let v = Vector {
                exp: |x: [f64; LANES]| x.map(f64::exp),
                div: |a: [f64; LANES], b: [f64; LANES]| std::array::from_fn(|j| a[j] / b[j]),
                roll: tortwin_model::product::roll4,
                run: None::<NoRun>,
            };
            touches_left_out |= self.roll_group_line_with(record, rail, group, states, works, v);
        }
        if touches_left_out {
            self.store_line_touches(record, rail, states);
        }
    }

    /// Step 1's stores that clock-free contacts on `rail` of a line left
    /// out ([`RollContext::store_touches`] on a section): at every point,
    /// on each of the rail's bands, the touch of the last wheel that met
    /// that band there, the train's last leading or last trailing axle
    /// (a wheel's rows depend on the point and its bogie position alone),
    /// unless a pulse landed there after it: the stores come in time order.
    fn store_line_touches(&self, record: &TrainRecord, rail: usize, states: &mut [TrackState]) {
        let Some(layout) = self.line else {
            return;
        };
        let t_passage_s = self.time_s(record.log_time_ns);
        let d_entry_m = match enters_at_zero(record.passage.direction) {
            true => 0.0,
            false => self.section.length_m,
        };
        let speed_mps = record.passage.speed_mps;
        let last = [(self.observers[0], false), (self.observers[1], true)];
        for i in 0..self.d_m.len() {
            // Per rail band, the last axle whose row meets it at point i.
            let mut toucher = [usize::MAX; RAIL_BANDS];
            for &(a, trailing) in &last {
                if a != usize::MAX {
                    let rb = usize::from(layout.rows_of(rail, trailing)[i]) % RAIL_BANDS;
                    if toucher[rb] == usize::MAX || a > toucher[rb] {
                        toucher[rb] = a;
                    }
                }
            }
            for (state, &a) in states.iter_mut().zip(&toucher) {
                if a == usize::MAX {
                    continue;
                }
                let offset_m = record.passage.axles[a].offset_m;
                let t = wheel_time_s(t_passage_s, self.d_m[i], d_entry_m, offset_m, speed_mps);
                // A pulse after that wheel, run by a later wheel on the
                // other band, touched this band last: its store stays.
                if state.last_touch_s[i] > t {
                    continue;
                }
                state.last_touch_s[i] = t;
                state.precip_at_touch_mm[i] = self.timeline.at(t).precip_mm_at(t);
            }
        }
    }

    /// [`RollContext::roll_group_line_with`] compiled for AVX2 and FMA, as
    /// [`RollContext::roll_group`]'s.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn roll_group_line_fma(
        &self,
        record: &TrainRecord,
        rail: usize,
        axles: std::ops::Range<usize>,
        states: &mut [TrackState],
        works: &mut [TrackWork],
    ) -> bool {
        // The line's lanes change rail bands from point to point: its
        // groups take no runs of ordinary steps (`Vector::run`).
        let v = vector_fma!();
        self.roll_group_line_with(record, rail, axles, states, works, v)
    }

    /// The wheels of `axles` (at most [`LANES`] consecutive axles) on
    /// `rail` as a wavefront: at step s, wheel j is at step s - j of its
    /// path, so every point sees the wheels in axle order, and each wheel's
    /// contact there is on its row's bands, which depend on the point and
    /// the wheel's bogie position alone. Four ordinary contacts run as
    /// [`RollContext::contacts4`] on the four lanes' rail bands; a step
    /// with a special point among its four runs lane by lane
    /// ([`RollContext::step_line`]), as does a group's start and end.
    /// Returns whether clock-free contacts left step 1's stores out
    /// ([`RollContext::store_line_touches`] writes them).
    #[inline(always)]
    fn roll_group_line_with(
        &self,
        record: &TrainRecord,
        rail: usize,
        axles: std::ops::Range<usize>,
        states: &mut [TrackState],
        works: &mut [TrackWork],
        v: Vector<impl Exp4, impl Div4, impl Roll4, impl super::Run4>,
    ) -> bool {
        let Some(layout) = self.line else {
            return false;
        };
        let n = axles.len();
        debug_assert!((1..=LANES).contains(&n));
        let points = self.d_m.len();
        let up = enters_at_zero(record.passage.direction);
        // Unused lanes repeat the first wheel and are never stepped.
        let first = self.line_lane(record, rail, axles.start);
        let mut lanes: [Lane; LANES] = std::array::from_fn(|j| {
            if j > 0 && j < n {
                self.line_lane(record, rail, axles.start + j)
            } else {
                first.clone()
            }
        });
        let clocks = Clocks::of(&lanes);
        let mut paths: [LinePath<'_>; LANES] =
            std::array::from_fn(|j| self.line_path(layout, record, rail, lanes[j].axle));
        let special = &self.special[rail * RAIL_BANDS];
        // As on a section: the portable kernel stores every touch.
        let clock_free = match self.portable {
            true => None,
            false => clock_free(&lanes),
        };
        let mut touches_left_out = false;
        for s in 0..points + n - 1 {
            let lo = s.saturating_sub(points - 1);
            let hi = n.min(s + 1);
            if lo == 0 && hi == LANES {
                let is = lane_points(up, points, s);
                if !is.iter().any(|&i| special[i]) {
                    let mut wheel_bands = [0; LANES];
                    let mut rail_bands = [0; LANES];
                    for (j, (lane, path)) in lanes.iter_mut().zip(&mut paths).enumerate() {
                        (wheel_bands[j], rail_bands[j]) = path.enter(lane, is[j]);
                    }
                    touches_left_out |= clock_free.is_some();
                    let seen = self.contacts4::<0>(
                        &mut lanes, &clocks, states, works, rail_bands, is, clock_free, v,
                    );
                    for (j, lane) in lanes.iter_mut().enumerate() {
                        self.leave_line(lane, wheel_bands[j], rail_bands[j], is[j], seen[j], works);
                    }
                    if s + 1 >= points {
                        self.finish_line_lane(&mut lanes[s + 1 - points], states, works);
                    }
                    continue;
                }
            }
            for j in lo..hi {
                let i = point_of(up, points, s - j);
                self.step_line(rail, &mut lanes[j], &mut paths[j], i, states, works);
            }
            // The lane that took its last step now.
            if s + 1 >= points {
                self.finish_line_lane(&mut lanes[s + 1 - points], states, works);
            }
        }
        touches_left_out
    }

    /// What a wheel of axle `a` on `rail` meets along the line: its row's
    /// bogie position and its contact conditions per segment.
    fn line_path<'r>(
        &self,
        layout: &'r LineLayout,
        record: &'r TrainRecord,
        rail: usize,
        a: usize,
    ) -> LinePath<'r> {
        let segments = layout.segments();
        let rails = self.section.rails.len();
        let trailing = record.passage.axles[a].bogie_position == BogiePosition::Trailing;
        LinePath {
            rows: layout.rows_of(rail, trailing),
            segment_of: layout.segments_of(),
            wheels: &record.seg_wheels[(a * rails + rail) * segments..][..segments],
            segment: u32::MAX,
        }
    }

    /// After `lane`'s contact at point `i` on wheel band `wb` and rail band
    /// `rb`: the wheel band keeps what the contact left, the rail band's
    /// field records the axle, and its step-2 mass `m_kg` is kept when
    /// asked for.
    #[inline(always)]
    fn leave_line(
        &self,
        lane: &mut Lane,
        wb: usize,
        rb: usize,
        i: usize,
        m_kg: f64,
        works: &mut [TrackWork],
    ) {
        lane.st.bands[wb] = lane.st.wheel_kg;
        if lane.roller.observe {
            works[rb].observed.axle[i] = lane.axle as u32;
        }
        if lane.axle == self.watch[0] {
            let watched = &mut works[0].watched;
            watched.seen_kg[0][i] = m_kg;
            for (band, &kg) in watched.bands_kg.iter_mut().zip(&lane.st.bands) {
                band[i] = kg;
            }
        }
        if lane.axle == self.watch[1] {
            works[0].watched.seen_kg[1][i] = m_kg;
        }
        if self.keep_seen {
            works[0].wheel_seen[lane.axle * self.d_m.len() + i] = m_kg;
        }
    }

    /// One contact of `lane`'s wheel at point `i`, alone: at a special
    /// point the events before it first.
    fn step_line(
        &self,
        rail: usize,
        lane: &mut Lane,
        path: &mut LinePath<'_>,
        i: usize,
        states: &mut [TrackState],
        works: &mut [TrackWork],
    ) {
        let (wb, rb) = path.enter(lane, i);
        let m_kg = if self.special[rail * RAIL_BANDS][i] {
            self.line_special_contact(rail, states, works, lane, i, rb)
        } else {
            self.contact(lane, &mut states[rb], &mut works[rb], i)
        };
        self.leave_line(lane, wb, rb, i, m_kg, works);
    }

    /// Axle `a`'s wheel on `rail` of a line, ready to roll.
    fn line_lane(&self, record: &TrainRecord, rail: usize, a: usize) -> Lane {
        let mut lane = self.lane(record, rail * RAIL_BANDS, a, a);
        lane.roller.observe = self.observe_every_wheel || self.observers.contains(&a);
        lane
    }

    /// Steps `steps` of `lane`'s path (step k is its k-th point in its
    /// direction of travel) one contact at a time: at each point the
    /// contact on the row's bands.
    fn roll_wheel_line(
        &self,
        record: &TrainRecord,
        rail: usize,
        lane: &mut Lane,
        steps: std::ops::Range<usize>,
        states: &mut [TrackState],
        works: &mut [TrackWork],
    ) {
        let Some(layout) = self.line else {
            return;
        };
        let points = self.d_m.len();
        let up = enters_at_zero(record.passage.direction);
        let mut path = self.line_path(layout, record, rail, lane.axle);
        for step in steps {
            let i = point_of(up, points, step);
            self.step_line(rail, lane, &mut path, i, states, works);
        }
    }

    /// A wheel that has left the line: its totals for the ledger, what it
    /// carries off its three bands.
    fn finish_line_lane(
        &self,
        lane: &mut Lane,
        states: &mut [TrackState],
        works: &mut [TrackWork],
    ) {
        let [f, c, g] = lane.st.bands;
        lane.st.wheel_kg = f + c + g;
        self.finish_lane(lane, &mut states[0], &mut works[0], self.d_m.len());
        states[1].wheel_pass += 1;
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
            self.run_events_before(rail * RAIL_BANDS + band, state, work, lane, i, t);
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

/// A wheel's way along a line: the rows it takes (those of its rail and
/// bogie position) and its contact conditions per segment.
struct LinePath<'r> {
    /// Per point, the row: `wheel band * RAIL_BANDS + rail band`.
    rows: &'r [u8],
    /// Per point, its segment.
    segment_of: &'r [u32],
    /// Per segment, the wheel with its axle's load and creepage there.
    wheels: &'r [crate::WheelOnRail],
    /// The segment of the last point entered.
    segment: u32,
}

impl LinePath<'_> {
    /// Before the wheel's contact at point `i`: the segment's `fp fc`,
    /// the row's wheel band in `WheelRoll::wheel_kg`; returns the row's
    /// (wheel band, rail band).
    #[inline(always)]
    fn enter(&mut self, lane: &mut Lane, i: usize) -> (usize, usize) {
        let s = self.segment_of[i];
        if s != self.segment {
            self.segment = s;
            lane.roller.fp_fc = self.wheels[s as usize].fp_fc;
        }
        let code = usize::from(self.rows[i]);
        let (wb, rb) = (code / RAIL_BANDS, code % RAIL_BANDS);
        lane.st.wheel_kg = lane.st.bands[wb];
        (wb, rb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::EngineOptions;
    use tortwin_model::config::ModelConfig;
    use tortwin_recording::line::{CurveAt, Line, Segment, SegmentKind};
    use tortwin_recording::{
        Applicator, Axle, AxleSegment, Creepage, Direction, Event, EventKind, Passage, Pulse,
        Section, Site,
    };

    const S: u64 = 1_000_000_000;

    /// A sink that keeps nothing.
    struct Nothing;
    impl Sink for Nothing {}

    /// 300 m: tangent, transition, curve (right rail high, the applicator
    /// in it), transition, tangent.
    fn layout() -> (Section, Line) {
        let section = Section {
            section_id: "balance".into(),
            length_m: 300.0,
            rails: vec!["left".into(), "right".into()],
            curve_radius_m: None,
            rail_head_radius_m: 0.3,
            nominal_wheel_diameter_m: 0.92,
            applicators: vec![Applicator {
                id: "A".into(),
                position_m: 80.0,
                rails: vec![0, 1],
                nominal_pulse_kg: 2e-4,
            }],
            sites: vec![Site {
                id: "M".into(),
                position_m: 150.0,
            }],
        };
        let segment = |id: &str, kind, end_m| Segment {
            id: id.into(),
            kind,
            end_m,
            radius_m: None,
        };
        let line = Line {
            line_id: "balance".into(),
            segments: vec![
                segment("T0", SegmentKind::Tangent, 40.0),
                segment(
                    "X1",
                    SegmentKind::Transition {
                        high_rail: 1,
                        curve_at: CurveAt::End,
                    },
                    70.0,
                ),
                segment("C1", SegmentKind::Curve { high_rail: 1 }, 180.0),
                segment(
                    "X2",
                    SegmentKind::Transition {
                        high_rail: 1,
                        curve_at: CurveAt::Start,
                    },
                    210.0,
                ),
                segment("T1", SegmentKind::Tangent, 300.0),
            ],
        };
        (section, line)
    }

    fn ev(t_s: u64, kind: EventKind) -> Event {
        Event {
            log_time_ns: t_s * S,
            index_in_file: t_s,
            kind,
        }
    }

    /// Eight axles, leading and trailing in turn, heavier in the curve.
    fn passage(t_s: u64, seq: usize, direction: Direction) -> Event {
        let creepage = |cx| Creepage {
            cx,
            cy: 0.001,
            spin_per_m: 0.0,
        };
        ev(
            t_s,
            EventKind::Passage(Passage {
                train_id: format!("T{seq}"),
                train_seq: seq,
                direction,
                speed_mps: 10.0,
                axles: (0..8)
                    .map(|k| Axle {
                        offset_m: 2.5 * k as f64,
                        bogie_position: if k % 2 == 0 {
                            BogiePosition::Leading
                        } else {
                            BogiePosition::Trailing
                        },
                        wheel_diameter_m: 0.92,
                        wheel_load_n: vec![90e3, 95e3],
                        creepage: vec![creepage(0.002), creepage(0.003)],
                        segments: vec![AxleSegment {
                            segment: 2,
                            wheel_load_n: Some(vec![80e3, 120e3]),
                            creepage: Some(vec![creepage(0.004), creepage(0.008)]),
                        }],
                    })
                    .collect(),
            }),
        )
    }

    fn pulse(t_s: u64, rail: usize) -> Event {
        ev(
            t_s,
            EventKind::Pulse(Pulse {
                applicator: 0,
                rail,
                mass_kg: 2e-4,
            }),
        )
    }

    /// Check 4: `P = R + W + K + S + X` per rail after every contact of a
    /// train's wheels (mid-wheel, `W > 0`: the rolling wheel's three
    /// bands), to 1e-12 of `P`, on a line where wheels pick product up in
    /// the curve and carry it on their stored bands; and at the end.
    #[test]
    fn the_mass_balance_closes_after_every_contact() {
        let (section, line) = layout();
        let mut engine = Engine::on_line(
            section,
            Some(line),
            ModelConfig::default(),
            EngineOptions::default(),
            0,
        );
        let mut sink = Nothing;
        // A first train conditions the wheels' way; pulses before both.
        let events = [
            pulse(1, 0),
            pulse(1, 1),
            passage(10, 0, Direction::Down),
            pulse(100, 0),
            pulse(100, 1),
            pulse(101, 1),
            passage(200, 1, Direction::Up),
        ];
        for e in events {
            engine.push(e, &mut sink).unwrap();
        }
        // Train 1 is pending; every pulse has landed.
        let record = engine.pending.take().unwrap();
        let before = engine.totals;
        assert!(before.carried_out_kg > 0.0 && before.consumed_kg > 0.0);
        let points = engine.grid.d_m.len();
        let rails = engine.section.rails.len();
        let axles = record.passage.axles.len();
        let (ctx, states, works) = engine.split();
        let p_kg = before.applied_kg;
        let (mut k_kg, mut s_kg, mut x_kg) =
            (before.consumed_kg, before.capped_kg, before.carried_out_kg);
        let mut worst = 0.0f64;
        let mut mid_wheel = 0;
        // The rails roll one after the other: while one rolls, the other's
        // wheels are all on it or all gone.
        for rail in 0..rails {
            let tracks = rail * RAIL_BANDS..(rail + 1) * RAIL_BANDS;
            for a in 0..axles {
                let mut lane = ctx.line_lane(&record, rail, a);
                for step in 0..points {
                    let (st, wk) = (&mut states[tracks.clone()], &mut works[tracks.clone()]);
                    ctx.roll_wheel_line(&record, rail, &mut lane, step..step + 1, st, wk);
                    let r: f64 = states.iter().flat_map(|t| t.rail_mass_kg.iter()).sum();
                    let w: f64 = lane.st.bands.iter().sum();
                    let k = k_kg + lane.st.consumed_kg;
                    let s = s_kg + lane.st.capped_kg;
                    let error = (p_kg - (r + w + k + s + x_kg)).abs() / p_kg;
                    worst = worst.max(error);
                    mid_wheel += usize::from(w > 0.0);
                    assert!(
                        error <= 1e-12,
                        "rail {rail}, axle {a}, step {step}: P = {p_kg:e}, R + W + K + S + X = \
                         {:e} (relative {error:e})",
                        r + w + k + s + x_kg
                    );
                }
                ctx.finish_line_lane(
                    &mut lane,
                    &mut states[tracks.clone()],
                    &mut works[tracks.clone()],
                );
                k_kg += lane.st.consumed_kg;
                s_kg += lane.st.capped_kg;
                x_kg += lane.st.wheel_kg;
            }
        }
        // The wheels carried product most of the way (mid-wheel checks).
        assert!(
            mid_wheel > rails * axles * points / 2,
            "{mid_wheel} contacts with W > 0"
        );
        eprintln!("balance closes to {worst:e} of P over {mid_wheel} mid-wheel contacts");
    }
}
