//! Sinks: listeners that publish what the engine produces.
//!
//! A sink sees a stream of borrowed snapshots and measurements in replay
//! order; it never reaches into the engine. Adding a sink touches no model
//! code. Every method may fail (I/O); the engine stops at the first error.
//!
//! Output files are written under a temporary name and renamed only by
//! [`Sink::finish`], so a failed run never leaves a file that looks complete.
//!
//! Each call's data is one struct, borrowed from the engine while it steps
//! (`Cow::Borrowed`, no copy) and owned where a call must outlive the step:
//! [`Event`] is every call as one value, [`Event::into_owned`] what
//! [`SinkThread`] hands to the output thread, [`Event::send_to`] the call
//! made again there.

use std::borrow::Cow;
use std::sync::Arc;

use tortwin_recording::{Direction, Quantity, Section};

pub use crate::alerts::Alert;
pub use crate::sink_thread::SinkThread;

/// What a sink learns before the first event.
#[derive(Debug, Clone)]
pub struct SectionInfo<'a> {
    pub section: Cow<'a, Section>,
    /// The calculation grid `d_i = i * C` in m.
    pub grid_d_m: Cow<'a, [f64]>,
    /// Every surface the engine keeps: one per rail, two on the rail named
    /// `high` when the `bogie_bands` effect is on.
    pub tracks: Cow<'a, [TrackInfo]>,
    /// Grid index of every applicator (as in `section.applicators`).
    pub applicator_points: Cow<'a, [usize]>,
    /// Grid index of every measurement site (as in `section.sites`).
    pub site_points: Cow<'a, [usize]>,
    /// log_time of the first recording's `/section`: time_s = 0.
    pub origin_ns: i64,
    /// The recording's `/line` (docs/spec/line.md), when it is a line.
    pub line: Option<Cow<'a, tortwin_recording::line::Line>>,
}

/// One surface of one rail.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrackInfo {
    pub rail: usize,
    pub rail_name: String,
    /// `top` for a single-band rail; `gauge_corner` or `top` with `bogie_bands`.
    pub band: String,
}

/// A train that entered the section.
#[derive(Debug, Clone)]
pub struct TrainEvent<'a> {
    /// When the front crossed the entry end.
    pub log_time_ns: u64,
    /// When the last axle left the section.
    pub end_ns: u64,
    pub train_id: Cow<'a, str>,
    pub direction: Direction,
    pub speed_mps: f64,
    pub axles: usize,
}

/// A pulse that landed.
#[derive(Debug, Clone)]
pub struct PulseEvent<'a> {
    pub log_time_ns: u64,
    /// Index in `section.applicators`.
    pub applicator: usize,
    pub applicator_id: Cow<'a, str>,
    pub rail: usize,
    pub rail_name: Cow<'a, str>,
    pub mass_kg: f64,
}

/// The simulated value for one input measurement.
#[derive(Debug, Clone)]
///
/// Its names are shared (`Arc`), not borrowed: measurements are most of a
/// recording's events, and a copy of each that outlives the call would
/// otherwise allocate three strings. (A [`SinkThread`] does not copy them:
/// its thread keeps names of its own, given once.)
pub struct MeasurementOutput {
    pub log_time_ns: u64,
    pub index_in_file: u64,
    pub site_id: Arc<str>,
    pub site: usize,
    pub rail_name: Arc<str>,
    pub rail: usize,
    pub quantity: Quantity,
    /// `None` for `rail_mu`.
    pub train_id: Option<Arc<str>>,
    pub axle_index: Option<usize>,
    pub measured: f64,
    pub simulated: f64,
    /// What the value was read from, when the sink asked
    /// ([`Sink::wants_readouts`]). Boxed: inline, it was two thirds of the
    /// bytes of every measurement (and of every event a [`SinkThread`]
    /// queues, the size of its largest kind), copied as it crosses to the
    /// output thread whether asked for or not.
    pub readout: Option<Box<crate::Readout>>,
}

/// Whether a field snapshot closes a train or a single wheel pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SnapshotKind {
    /// After the train's last wheel: the `/twin/field` message.
    Train,
    /// After one wheel (only when asked for every wheel pass).
    Wheel,
}

/// The friction field of one track after a train (or a wheel).
#[derive(Debug, Clone)]
pub struct FieldSnapshot<'a> {
    pub kind: SnapshotKind,
    /// Time the snapshot's last wheel left the section.
    pub log_time_ns: u64,
    pub train_id: Cow<'a, str>,
    pub track: usize,
    pub rail_name: Cow<'a, str>,
    pub band: Cow<'a, str>,
    /// Wheels that have rolled over this track so far.
    pub wheel_pass: u64,
    pub d_m: Cow<'a, [f64]>,
    /// Seen by the last wheel, at step 2 of each contact.
    pub mu: Cow<'a, [f64]>,
    pub adhesion: Cow<'a, [f64]>,
    /// Rail mass after the wheel passed.
    pub rail_mass_kg: Cow<'a, [f64]>,
    /// The last wheel's mass after each contact.
    pub wheel_mass_kg: Cow<'a, [f64]>,
}

/// What one wheel saw at every grid point of its track, given to
/// [`Sink::wheel_contacts`] after the wheel has rolled (only when
/// `EngineOptions::every_wheel_contacts` is set).
#[derive(Debug, Clone)]
pub struct WheelContacts<'a> {
    pub track: usize,
    pub rail: usize,
    pub direction: Direction,
    pub train_seq: usize,
    /// 0-based axle index in its train.
    pub axle: usize,
    /// The total mass `m = m_w + m_r` of step 2 at each grid point, in grid
    /// order (d ascending): mu of the contact is eq. (4) of it.
    pub seen_mass_kg: Cow<'a, [f64]>,
    /// mu of each contact, given where generic friction terms make it more
    /// than eq. (4) of the mass (`None`: eq. (4) of `seen_mass_kg`).
    pub mu: Option<Cow<'a, [f64]>>,
}

/// On a line, after each train, per rail: what the chosen axle and the
/// next one saw along the line, and the chosen axle's tread, given to
/// [`Sink::line_wheels`] when `EngineOptions::line_axle` is set.
#[derive(Debug, Clone)]
pub struct LineWheels<'a> {
    /// When the train's last wheel left the line.
    pub log_time_ns: u64,
    pub train_id: Cow<'a, str>,
    pub rail: usize,
    pub rail_name: Cow<'a, str>,
    /// The two axles (0-based, in the train): the chosen one and the next,
    /// or the train's last two when it has fewer axles; one twice for a
    /// train of one axle.
    pub axles: [usize; 2],
    pub bogie_positions: [tortwin_recording::BogiePosition; 2],
    /// mu of each axle's contact at every grid point (eq. (4) of its step-2
    /// mass), whichever bands met there.
    pub mu: [Cow<'a, [f64]>; 2],
    /// What `rail_mu` reads after the train: eq. (4) of the crown's (`C`)
    /// rail mass at every point.
    pub rail_mu: Cow<'a, [f64]>,
    /// The first axle's tread bands F, C, G after its contact at every
    /// point (kg).
    pub bands_kg: [Cow<'a, [f64]>; 3],
}

/// The end-of-run figures.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct RunSummary {
    pub trains: u64,
    pub wheels: u64,
    pub contacts: u64,
    pub pulses: u64,
    pub measurements: u64,
    pub weather_messages: u64,
    pub unknown_topic_messages: u64,
    /// RMSE measured vs simulated, per quantity (`mu`, `adhesion`, `rail_mu`).
    pub rmse: Vec<(String, u64, f64)>,
    pub mass_balance: MassBalance,
}

/// Where the applied product went, in kg. `applied = on_rail_end -
/// on_rail_start + carried_out + consumed + capped + effects_lost`.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct MassBalance {
    pub on_rail_start_kg: f64,
    pub applied_kg: f64,
    pub on_rail_end_kg: f64,
    /// Left the section on wheels (including any wheel edge reservoir).
    pub carried_out_kg: f64,
    pub consumed_kg: f64,
    /// Squeezed out by the cap at m_max (contacts and pulses).
    pub capped_kg: f64,
    /// Removed by time effects (ageing, rain).
    pub effects_lost_kg: f64,
}

impl MassBalance {
    /// Relative closing error of the balance.
    pub fn closing_error(&self) -> f64 {
        let inflow = self.on_rail_start_kg + self.applied_kg;
        let outflow = self.on_rail_end_kg
            + self.carried_out_kg
            + self.consumed_kg
            + self.capped_kg
            + self.effects_lost_kg;
        let scale = inflow.abs().max(outflow.abs());
        if scale == 0.0 {
            0.0
        } else {
            (inflow - outflow).abs() / scale
        }
    }
}

/// Why a sink failed (an output that could not be written): any error,
/// with its causes, which the engine passes on as [`crate::EngineError::Sink`].
pub type SinkError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// What every [`Sink`] method returns.
pub type SinkResult = Result<(), SinkError>;

/// One call to a [`Sink`], its data borrowed or owned.
#[derive(Debug, Clone)]
pub enum Event<'a> {
    Begin(SectionInfo<'a>),
    Train(TrainEvent<'a>),
    Pulse(PulseEvent<'a>),
    Measurement(MeasurementOutput),
    Field(FieldSnapshot<'a>),
    WheelContacts(WheelContacts<'a>),
    LineWheels(LineWheels<'a>),
    Weather(u64),
    Alert(Alert),
    Finish(RunSummary),
}

/// `Cow::Owned` of a borrowed value (an owned one is kept).
fn owned<T: ToOwned + ?Sized>(c: Cow<'_, T>) -> Cow<'static, T> {
    Cow::Owned(c.into_owned())
}

impl Event<'_> {
    /// The same call owning its data, to outlive the engine's step.
    pub fn into_owned(self) -> Event<'static> {
        match self {
            Event::Begin(i) => Event::Begin(SectionInfo {
                section: owned(i.section),
                grid_d_m: owned(i.grid_d_m),
                tracks: owned(i.tracks),
                applicator_points: owned(i.applicator_points),
                site_points: owned(i.site_points),
                origin_ns: i.origin_ns,
                line: i.line.map(owned),
            }),
            Event::Train(t) => Event::Train(TrainEvent {
                log_time_ns: t.log_time_ns,
                end_ns: t.end_ns,
                train_id: owned(t.train_id),
                direction: t.direction,
                speed_mps: t.speed_mps,
                axles: t.axles,
            }),
            Event::Pulse(p) => Event::Pulse(PulseEvent {
                log_time_ns: p.log_time_ns,
                applicator: p.applicator,
                applicator_id: owned(p.applicator_id),
                rail: p.rail,
                rail_name: owned(p.rail_name),
                mass_kg: p.mass_kg,
            }),
            Event::Measurement(m) => Event::Measurement(m),
            Event::Field(f) => Event::Field(FieldSnapshot {
                kind: f.kind,
                log_time_ns: f.log_time_ns,
                train_id: owned(f.train_id),
                track: f.track,
                rail_name: owned(f.rail_name),
                band: owned(f.band),
                wheel_pass: f.wheel_pass,
                d_m: owned(f.d_m),
                mu: owned(f.mu),
                adhesion: owned(f.adhesion),
                rail_mass_kg: owned(f.rail_mass_kg),
                wheel_mass_kg: owned(f.wheel_mass_kg),
            }),
            Event::WheelContacts(w) => Event::WheelContacts(WheelContacts {
                track: w.track,
                rail: w.rail,
                direction: w.direction,
                train_seq: w.train_seq,
                axle: w.axle,
                seen_mass_kg: owned(w.seen_mass_kg),
                mu: w.mu.map(owned),
            }),
            Event::LineWheels(w) => Event::LineWheels(LineWheels {
                log_time_ns: w.log_time_ns,
                train_id: owned(w.train_id),
                rail: w.rail,
                rail_name: owned(w.rail_name),
                axles: w.axles,
                bogie_positions: w.bogie_positions,
                mu: w.mu.map(owned),
                rail_mu: owned(w.rail_mu),
                bands_kg: w.bands_kg.map(owned),
            }),
            Event::Weather(t) => Event::Weather(t),
            Event::Alert(a) => Event::Alert(a),
            Event::Finish(summary) => Event::Finish(summary),
        }
    }

    /// Makes the call on `sink`.
    pub fn send_to<S: Sink + ?Sized>(&self, sink: &mut S) -> SinkResult {
        match self {
            Event::Begin(i) => sink.begin(i),
            Event::Train(t) => sink.train(t),
            Event::Pulse(p) => sink.pulse(p),
            Event::Measurement(m) => sink.measurement(m),
            Event::Field(f) => sink.field(f),
            Event::WheelContacts(w) => sink.wheel_contacts(w),
            Event::LineWheels(w) => sink.line_wheels(w),
            Event::Weather(t) => sink.weather(*t),
            Event::Alert(a) => sink.alert(a),
            Event::Finish(summary) => sink.finish(summary),
        }
    }

    /// The bytes of the arrays the call holds (what grows with the grid).
    pub fn array_bytes(&self) -> usize {
        let f64s = match self {
            Event::Begin(i) => i.grid_d_m.len(),
            Event::Field(f) => {
                f.d_m.len()
                    + f.mu.len()
                    + f.adhesion.len()
                    + f.rail_mass_kg.len()
                    + f.wheel_mass_kg.len()
            }
            Event::WheelContacts(w) => w.seen_mass_kg.len() + w.mu.as_ref().map_or(0, |m| m.len()),
            Event::LineWheels(w) => {
                w.mu.iter()
                    .chain(&w.bands_kg)
                    .map(|v| v.len())
                    .sum::<usize>()
                    + w.rail_mu.len()
            }
            Event::Train(_)
            | Event::Pulse(_)
            | Event::Measurement(_)
            | Event::Weather(_)
            | Event::Alert(_)
            | Event::Finish(_) => 0,
        };
        f64s * std::mem::size_of::<f64>()
    }
}

/// A listener of the engine.
pub trait Sink {
    fn begin(&mut self, _info: &SectionInfo<'_>) -> SinkResult {
        Ok(())
    }
    fn train(&mut self, _train: &TrainEvent<'_>) -> SinkResult {
        Ok(())
    }
    fn pulse(&mut self, _pulse: &PulseEvent<'_>) -> SinkResult {
        Ok(())
    }
    fn measurement(&mut self, _m: &MeasurementOutput) -> SinkResult {
        Ok(())
    }
    /// Whether [`MeasurementOutput::readout`] is wanted (it costs a Polach
    /// contact per adhesion measurement).
    fn wants_readouts(&self) -> bool {
        false
    }
    fn field(&mut self, _f: &FieldSnapshot<'_>) -> SinkResult {
        Ok(())
    }
    fn wheel_contacts(&mut self, _w: &WheelContacts<'_>) -> SinkResult {
        Ok(())
    }
    /// On a line, after each train's fields (only when
    /// `EngineOptions::line_axle` is set).
    fn line_wheels(&mut self, _w: &LineWheels<'_>) -> SinkResult {
        Ok(())
    }
    /// A `/environment/weather` message taken, at its log_time.
    fn weather(&mut self, _log_time_ns: u64) -> SinkResult {
        Ok(())
    }
    /// An alert raised or cleared ([`crate::alerts::Alerting`]).
    fn alert(&mut self, _alert: &Alert) -> SinkResult {
        Ok(())
    }
    /// Completes the output (e.g. renames the temporary file into place).
    fn finish(&mut self, _summary: &RunSummary) -> SinkResult {
        Ok(())
    }
}

/// Forwards every call to several sinks in turn: borrowed
/// (`Fanout<&mut dyn Sink>`, the engine's caller's) or owned
/// (`Fanout<Box<dyn Sink + Send>>`, the output files on their thread).
pub struct Fanout<S> {
    pub sinks: Vec<S>,
}

impl<S> Default for Fanout<S> {
    fn default() -> Self {
        Fanout { sinks: Vec::new() }
    }
}

impl<S, T> Sink for Fanout<S>
where
    S: std::ops::DerefMut<Target = T>,
    T: Sink + ?Sized,
{
    fn begin(&mut self, info: &SectionInfo<'_>) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.begin(info))
    }
    fn train(&mut self, train: &TrainEvent<'_>) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.train(train))
    }
    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.pulse(pulse))
    }
    fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.measurement(m))
    }
    fn wants_readouts(&self) -> bool {
        self.sinks.iter().any(|s| s.wants_readouts())
    }
    fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.field(f))
    }
    fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.wheel_contacts(w))
    }
    fn line_wheels(&mut self, w: &LineWheels<'_>) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.line_wheels(w))
    }
    fn weather(&mut self, log_time_ns: u64) -> SinkResult {
        self.sinks
            .iter_mut()
            .try_for_each(|s| s.weather(log_time_ns))
    }
    fn alert(&mut self, alert: &Alert) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.alert(alert))
    }
    fn finish(&mut self, summary: &RunSummary) -> SinkResult {
        self.sinks.iter_mut().try_for_each(|s| s.finish(summary))
    }
}
