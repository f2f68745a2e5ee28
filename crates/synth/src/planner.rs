//! Planning a day: trains at random times in the service hours (one in the
//! section at a time, a headway between them; on a line a train may enter
//! while another is on it, as long as it does not catch up with it, the
//! headway kept at both ends), the pulses the applicators' axle counter
//! triggers, the weather messages, and the measurements (every
//! axle of a share of the trains at every site and rail, adhesion at one
//! site for some of them, tribometer readings between trains). The typed
//! events are built from the values as they will be written, with the
//! reader's unit conversions, so a replay of the file sees the same numbers.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::climate::Climate;
use super::layout::Bend;
use super::params::SynthParams;
use super::traffic::{creepages, freight_consist, passenger_consist, TrainKind, TrainPlan};
use super::{round_dp, stream, uniform, Stream, DAY_NS, HOUR_NS, NS_PER_S};
use tortwin_recording::line::axle_at_ends_s;
use tortwin_recording::{
    Axle, AxleRef, AxleSegment, BogiePosition, Direction, EventKind, Measured, Measurement,
    Passage, Pulse, Quantity, Section,
};

/// Standard gravity, m/s², for the cant deficiency of a curve.
const G_MPS2: f64 = 9.81;
/// Distance between the rails' running circles, m (standard gauge).
const RAIL_SPACING_M: f64 = 1.5;
/// Tribometer readings are taken in working hours, at least this long after
/// a train has left and before the next one comes.
const TRIBOMETER_HOURS: (f64, f64) = (7.0, 18.0);
const TRIBOMETER_MARGIN_S: f64 = 60.0;

/// One message of a day, with its place in the replay.
#[derive(Debug, Clone)]
pub(super) struct Planned {
    pub(super) log_time_ns: u64,
    /// Written at the end of the file (after every in-order message).
    pub(super) at_end: bool,
    /// Planning order, the tie-break of equal times and topics.
    pub(super) seq: u64,
    pub(super) event: EventKind,
    /// A pulse's mass as written, g.
    pub(super) pulse_mass_g: Option<f64>,
}

pub(super) struct DayPlan {
    pub(super) items: Vec<Planned>,
    pub(super) trains: Vec<TrainPlan>,
    pub(super) dropped_trains: u64,
}

/// A calendar day of the recording: `[from_ns, to_ns)`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Day {
    midnight_ns: u64,
    from_ns: u64,
    to_ns: u64,
}

pub(super) struct Planner<'p> {
    p: &'p SynthParams,
    section: Section,
    /// A line's segments that are not tangent (none on a section).
    bends: Vec<Bend>,
    traffic: ChaCha8Rng,
    weather_rng: ChaCha8Rng,
    tribometer: ChaCha8Rng,
    pub(super) climate: Climate,
    next_train_seq: usize,
    axles_counted: u64,
    /// The last train's passage time and the end of its occupation, as the
    /// reader computes them (s from the origin).
    last_train_s: Option<(f64, f64)>,
    /// On a line: when the last train's last axle reaches `d = 0` and
    /// `d = L`, s from the origin (the reader's rule for sharing a line).
    last_axle_at_ends_s: Option<[f64; 2]>,
    next_weather: u64,
    seq: u64,
}

impl<'p> Planner<'p> {
    pub(super) fn new(p: &'p SynthParams, section: Section, bends: Vec<Bend>) -> Self {
        let mut weather_rng = stream(p.seed, Stream::Weather);
        let climate = Climate::new(p, &mut weather_rng);
        Planner {
            p,
            section,
            bends,
            traffic: stream(p.seed, Stream::Traffic),
            weather_rng,
            tribometer: stream(p.seed, Stream::Tribometer),
            climate,
            next_train_seq: 0,
            axles_counted: 0,
            last_train_s: None,
            last_axle_at_ends_s: None,
            next_weather: 0,
            seq: 0,
        }
    }

    pub(super) fn days(&self) -> Vec<Day> {
        let first = self.climate.first_midnight_ns;
        let end = self.p.end_ns();
        (0..)
            .map(|d| first + d * DAY_NS)
            .take_while(|&midnight| midnight < end)
            .map(|midnight_ns| Day {
                midnight_ns,
                from_ns: midnight_ns.max(self.p.start_ns),
                to_ns: (midnight_ns + DAY_NS).min(end),
            })
            .collect()
    }

    fn time_s(&self, log_time_ns: u64) -> f64 {
        (log_time_ns as i64 - self.p.start_ns as i64) as f64 * 1e-9
    }

    fn push(&mut self, items: &mut Vec<Planned>, log_time_ns: u64, event: EventKind) {
        self.seq += 1;
        items.push(Planned {
            log_time_ns,
            at_end: false,
            seq: self.seq,
            event,
            pulse_mass_g: None,
        });
    }

    /// When axle `offset_m` of a train reaches `d_m` (recording-format.md).
    fn axle_time_ns(&self, train: &TrainPlan, offset_m: f64, d_m: f64) -> u64 {
        let from_entry_m = match train.passage.direction {
            Direction::Up => d_m,
            Direction::Down => self.p.length_m - d_m,
        };
        let dt_s = (from_entry_m.abs() + offset_m) / train.passage.speed_mps;
        train.log_time_ns + (dt_s * NS_PER_S).round() as u64
    }

    pub(super) fn plan_day(&mut self, day: Day) -> DayPlan {
        let mut items = Vec::new();
        let p = self.p;

        let interval_ns = (p.weather_interval_s * NS_PER_S).round() as u64;
        loop {
            let t_ns = p.start_ns + self.next_weather * interval_ns;
            if t_ns >= day.to_ns {
                break;
            }
            self.next_weather += 1;
            let w = self.climate.weather(t_ns, &mut self.weather_rng);
            self.push(&mut items, t_ns, EventKind::Weather(w));
        }

        let service_from =
            (day.midnight_ns + (p.service_start_h * HOUR_NS as f64) as u64).max(day.from_ns);
        let service_to =
            (day.midnight_ns + (p.service_end_h * HOUR_NS as f64) as u64).min(day.to_ns);
        let mut trains = Vec::new();
        let mut dropped_trains = 0;
        if service_to > service_from {
            let full_ns = (p.service_end_h - p.service_start_h) * HOUR_NS as f64;
            let share = (service_to - service_from) as f64 / full_ns;
            let n = (f64::from(p.trains_per_day) * share).round() as usize;
            let mut times: Vec<u64> = (0..n)
                .map(|_| {
                    service_from
                        + (self.traffic.random::<f64>() * (service_to - service_from) as f64) as u64
                })
                .collect();
            times.sort_unstable();
            for drawn_ns in times {
                match self.plan_train(drawn_ns, service_to) {
                    Some(train) => trains.push(train),
                    None => dropped_trains += 1,
                }
            }
        }
        for train in &trains {
            self.plan_train_messages(train, &mut items);
        }
        if service_to > service_from {
            self.plan_tribometer(&trains, service_from, service_to, &mut items);
        }
        DayPlan {
            items,
            trains,
            dropped_trains,
        }
    }

    /// A train drawn for `drawn_ns`: it enters then, or once the previous
    /// train has left plus the headway; `None` if it would still be in the
    /// section at `service_to`.
    fn plan_train(&mut self, drawn_ns: u64, service_to: u64) -> Option<TrainPlan> {
        let p = self.p;
        let rng = &mut self.traffic;
        let kind = if rng.random_bool(p.passenger_share) {
            TrainKind::Passenger
        } else {
            TrainKind::Freight
        };
        let consist = match kind {
            TrainKind::Freight => freight_consist(rng),
            TrainKind::Passenger => passenger_consist(rng),
        };
        let speed_mps = round_dp(
            match kind {
                TrainKind::Freight => uniform(rng, 12.0, 22.0),
                TrainKind::Passenger => uniform(rng, 18.0, 30.0),
            },
            10.0,
        );
        let direction = if rng.random_bool(p.down_share) {
            Direction::Down
        } else {
            Direction::Up
        };
        let measured = rng.random_bool(p.measured_train_share);
        let adhesion = measured && rng.random_bool(p.adhesion_train_share);

        // Above the balance speed of the curve the high rail carries more.
        let load_shift = match p.curve_radius_m {
            Some(radius_m) => load_shift_at(speed_mps, radius_m, p.cant_m),
            None => 0.0,
        };
        let rails = p.rails.len();
        let mut axles = Vec::new();
        let mut load_kn = Vec::new();
        let mut segment_load_kn = Vec::new();
        let mut front_m = 0.0;
        for vehicle in &consist {
            let overhang_m =
                (vehicle.length_m - vehicle.bogie_centres_m - vehicle.wheelbase_m) / 2.0;
            let positions = [
                (0.0, BogiePosition::Leading),
                (vehicle.wheelbase_m, BogiePosition::Trailing),
                (vehicle.bogie_centres_m, BogiePosition::Leading),
                (
                    vehicle.bogie_centres_m + vehicle.wheelbase_m,
                    BogiePosition::Trailing,
                ),
            ];
            for (at_m, bogie_position) in positions {
                let axle_load_kn = vehicle.wheel_load_kn * (1.0 + uniform(rng, -0.03, 0.03));
                let creepage = creepages(rng, p.curve_radius_m, bogie_position);
                let wheel_diameter_m = round_dp(uniform(rng, 0.84, 0.96), 1e3);
                let loads = |rng: &mut ChaCha8Rng, shift_to_first: f64| {
                    (0..rails)
                        .map(|rail| {
                            let side = if rail == 0 { 1.0 } else { -1.0 };
                            round_dp(
                                axle_load_kn
                                    * (1.0 + side * shift_to_first)
                                    * (1.0 + uniform(rng, -0.01, 0.01)),
                                10.0,
                            )
                        })
                        .collect::<Vec<f64>>()
                };
                let kn = loads(rng, load_shift);
                // The reader's kN -> N conversion, exactly.
                let wheel_load_n = kn.iter().map(|kn| kn * 1e3).collect();
                load_kn.extend(kn);
                // A line's curves and transitions: the outer rail's load
                // and creepage first, as on the section's curve.
                let mut segments = Vec::with_capacity(self.bends.len());
                let mut kn_per_segment = Vec::with_capacity(self.bends.len());
                for bend in &self.bends {
                    let c = creepages(rng, Some(bend.radius_m), bogie_position);
                    let outer = bend.high_rail;
                    let shift = load_shift_at(speed_mps, bend.radius_m, bend.cant_m);
                    let kn = loads(rng, if outer == 0 { shift } else { -shift });
                    let creepage = if outer == 0 {
                        vec![c[0], c[1]]
                    } else {
                        vec![c[1], c[0]]
                    };
                    segments.push(AxleSegment {
                        segment: bend.segment,
                        wheel_load_n: Some(kn.iter().map(|kn| kn * 1e3).collect()),
                        creepage: Some(creepage),
                    });
                    kn_per_segment.push(kn);
                }
                segment_load_kn.push(kn_per_segment);
                axles.push(Axle {
                    offset_m: round_dp(front_m + overhang_m + at_m, 100.0),
                    bogie_position,
                    wheel_diameter_m,
                    wheel_load_n,
                    creepage: creepage[..rails.min(2)].to_vec(),
                    segments,
                });
            }
            front_m += vehicle.length_m;
        }
        let last_offset_m = axles.last().map_or(0.0, |a| a.offset_m);
        let occupation_s = (p.length_m + last_offset_m) / speed_mps;

        // Earliest entry: as drawn, or the previous train's exit plus the
        // headway (on a line: its last axle at either end plus the headway
        // before this one's first axle gets there), checked with the
        // reader's own arithmetic.
        let mut log_time_ns = drawn_ns;
        let up = direction == Direction::Up;
        let first_offset_m = axles.first().map_or(0.0, |a| a.offset_m);
        let front_at_ends =
            |t_s: f64| axle_at_ends_s(t_s, up, p.length_m, first_offset_m, speed_mps);
        if let (Some(before), true) = (self.last_axle_at_ends_s, p.line.is_some()) {
            let kept = |t_s: f64| {
                let front = front_at_ends(t_s);
                (0..2).all(|k| front[k] >= before[k] + p.min_headway_s)
            };
            let lead_s = (0..2)
                .map(|k| before[k] + p.min_headway_s - (front_at_ends(0.0)[k]))
                .fold(f64::NEG_INFINITY, f64::max);
            let earliest_ns = p.start_ns + (lead_s * NS_PER_S).ceil().max(0.0) as u64;
            log_time_ns = log_time_ns.max(earliest_ns);
            while !kept(self.time_s(log_time_ns)) {
                log_time_ns += 1;
            }
        } else if let Some((_, occupied_until_s)) = self.last_train_s {
            let earliest_s = occupied_until_s + p.min_headway_s;
            let earliest_ns = p.start_ns + (earliest_s * NS_PER_S).ceil().max(0.0) as u64;
            log_time_ns = log_time_ns.max(earliest_ns);
            while self.time_s(log_time_ns) < occupied_until_s {
                log_time_ns += 1;
            }
        }
        let end_ns = log_time_ns + (occupation_s * NS_PER_S).ceil() as u64 + 1;
        if end_ns > service_to {
            return None;
        }
        let t_s = self.time_s(log_time_ns);
        self.last_train_s = Some((t_s, t_s + occupation_s));
        self.last_axle_at_ends_s = Some(axle_at_ends_s(
            t_s,
            up,
            p.length_m,
            last_offset_m,
            speed_mps,
        ));

        let train_seq = self.next_train_seq;
        self.next_train_seq += 1;
        let prefix = match kind {
            TrainKind::Freight => "F",
            TrainKind::Passenger => "P",
        };
        Some(TrainPlan {
            kind,
            passage: Passage {
                train_id: format!("{prefix}-{:05}", train_seq + 1),
                train_seq,
                direction,
                speed_mps,
                axles,
            },
            load_kn,
            segment_load_kn,
            log_time_ns,
            measured,
            adhesion,
        })
    }

    /// The passage, the pulses its axles trigger and its measurements.
    fn plan_train_messages(&mut self, train: &TrainPlan, items: &mut Vec<Planned>) {
        let p = self.p;
        self.push(
            items,
            train.log_time_ns,
            EventKind::Passage(train.passage.clone()),
        );

        let delay_ns = (p.pulse_delay_s * NS_PER_S).round() as u64;
        for axle in &train.passage.axles {
            self.axles_counted += 1;
            if !self
                .axles_counted
                .is_multiple_of(u64::from(p.pulse_every_axles))
            {
                continue;
            }
            for applicator in 0..self.section.applicators.len() {
                let position_m = self.section.applicators[applicator].position_m;
                let at_ns = self.axle_time_ns(train, axle.offset_m, position_m) + delay_ns;
                let nominal_g = p.nominal_pulse_g(applicator);
                for r in 0..self.section.applicators[applicator].rails.len() {
                    let rail = self.section.applicators[applicator].rails[r];
                    let jitter =
                        uniform(&mut self.traffic, -p.pulse_mass_jitter, p.pulse_mass_jitter);
                    let mass_g = round_dp(nominal_g * (1.0 + jitter), 1e4);
                    self.push(
                        items,
                        at_ns,
                        EventKind::Pulse(Pulse {
                            applicator,
                            rail,
                            mass_kg: mass_g * 1e-3,
                        }),
                    );
                    if let Some(last) = items.last_mut() {
                        last.pulse_mass_g = Some(mass_g);
                    }
                }
            }
        }

        if !train.measured {
            return;
        }
        let adhesion_site = self
            .section
            .sites
            .iter()
            .position(|s| s.id == p.adhesion_site);
        for (site, s) in self.section.sites.clone().iter().enumerate() {
            let quantities: &[Quantity] = if train.adhesion && Some(site) == adhesion_site {
                &[Quantity::Mu, Quantity::Adhesion]
            } else {
                &[Quantity::Mu]
            };
            for (axle_index, axle) in train.passage.axles.iter().enumerate() {
                let at_ns = self.axle_time_ns(train, axle.offset_m, s.position_m);
                for &quantity in quantities {
                    for rail in 0..p.rails.len() {
                        self.push(
                            items,
                            at_ns,
                            EventKind::Measurement(Measurement {
                                site,
                                rail,
                                of: {
                                    let axle = AxleRef {
                                        train_id: train.passage.train_id.as_str().into(),
                                        train_seq: train.passage.train_seq,
                                        axle_index,
                                    };
                                    match quantity {
                                        Quantity::Adhesion => Measured::Adhesion(axle),
                                        _ => Measured::Mu(axle),
                                    }
                                },
                                value: 0.0,
                            }),
                        );
                    }
                }
            }
        }
    }

    /// Hand tribometer readings in working hours, in the gaps between trains.
    fn plan_tribometer(
        &mut self,
        trains: &[TrainPlan],
        service_from: u64,
        service_to: u64,
        items: &mut Vec<Planned>,
    ) {
        let p = self.p;
        let day_start = service_from - service_from % DAY_NS;
        let hours_from =
            (day_start + (TRIBOMETER_HOURS.0 * HOUR_NS as f64) as u64).max(service_from);
        let hours_to = (day_start + (TRIBOMETER_HOURS.1 * HOUR_NS as f64) as u64).min(service_to);
        if hours_to <= hours_from {
            return;
        }
        let margin_ns = (TRIBOMETER_MARGIN_S * NS_PER_S) as u64;
        // Free intervals: between the trains' occupations, with a margin.
        let mut free: Vec<(u64, u64)> = Vec::new();
        let mut cursor = hours_from;
        for train in trains {
            let last_offset_m = train.passage.axles.last().map_or(0.0, |a| a.offset_m);
            let end_ns = train.log_time_ns
                + ((p.length_m + last_offset_m) / train.passage.speed_mps * NS_PER_S).ceil() as u64;
            let busy_from = train.log_time_ns.saturating_sub(margin_ns);
            if busy_from > cursor {
                free.push((cursor, busy_from.min(hours_to)));
            }
            cursor = cursor.max(end_ns + margin_ns);
        }
        if cursor < hours_to {
            free.push((cursor, hours_to));
        }
        free.retain(|&(a, b)| b > a);
        let total_ns: u64 = free.iter().map(|&(a, b)| b - a).sum();
        if total_ns == 0 {
            return;
        }
        for _ in 0..p.tribometer_per_day {
            let rng = &mut self.tribometer;
            let mut u = (rng.random::<f64>() * total_ns as f64) as u64;
            let site = rng.random_range(0..self.section.sites.len().max(1));
            let rail = rng.random_range(0..p.rails.len());
            let Some(at_ns) = free.iter().find_map(|&(a, b)| {
                if u < b - a {
                    Some(a + u)
                } else {
                    u -= b - a;
                    None
                }
            }) else {
                continue;
            };
            if self.section.sites.is_empty() {
                continue;
            }
            self.push(
                items,
                at_ns,
                EventKind::Measurement(Measurement {
                    site,
                    rail,
                    of: Measured::RailMu,
                    value: 0.0,
                }),
            );
            if let Some(last) = items.last_mut() {
                last.at_end = p.rail_mu_at_end;
            }
        }
    }
}

/// The share of an axle's load moved to a curve's outer rail at
/// `speed_mps`: above the balance speed the high rail carries more, load
/// transfer ~ unbalanced lateral acceleration × centre of gravity height /
/// half the rail spacing, here 12 % per m/s².
fn load_shift_at(speed_mps: f64, radius_m: f64, cant_m: f64) -> f64 {
    let unbalanced_mps2 = speed_mps * speed_mps / radius_m - G_MPS2 * cant_m / RAIL_SPACING_M;
    (0.12 * unbalanced_mps2).clamp(-0.12, 0.25)
}
