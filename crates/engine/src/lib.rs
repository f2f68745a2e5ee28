//! The engine: owns time and the section's state, and steps the product
//! model wheel pass by wheel pass (docs/spec/model.md, "One contact"
//! and "Order of events").
//!
//! Events arrive in replay order (log_time). A train occupies the section
//! from its passage's time until its last axle has left; trains never share
//! the section (the reader refuses recordings where they would; on a line
//! trains may share it while none catches up, docs/spec/line.md). So the
//! engine buffers the events of one occupation (pulses, tribometer readings,
//! weather, measurements) until the stream passes the train's end, then rolls
//! the train's wheels one after the other over every grid point. That order
//! is exact: wheel k+1 reaches every point after wheel k, and a pulse or a
//! reading at point p goes in just before the first wheel that reaches p
//! strictly after it.
//!
//! Everything that simulates (replay, paper scenarios, synthetic truth runs,
//! fits, strategies) drives this one engine with [`Engine::push`].

pub mod alerts;
pub mod line;
pub mod readout;
mod roll;
pub mod rows;
pub mod sink;
mod sink_thread;
mod state;
pub mod terms;
pub mod weather;

use std::collections::VecDeque;
use std::sync::Arc;

use crate::sink::{
    MassBalance, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink, SinkError,
    SnapshotKind, TrackInfo, TrainEvent,
};
use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_model::contact::{
    self, HertzContact, HertzShape, KalkerCoefficients, PolachContact, PolachInput, Steel,
};
use tortwin_model::effects::{Named, TimeEffects};
use tortwin_model::error::ConfigError;
use tortwin_model::generic::Driver;
use tortwin_model::product;
use tortwin_model::tangent::{self, Tangent};
use tortwin_recording::error::InputError;
use tortwin_recording::{
    Axle, AxleRef, BogiePosition, Creepage, Direction, Event, EventKind, Measured, Measurement,
    Passage, Quantity, Section, Weather,
};

pub use readout::{Readout, ReadoutModel};
pub use state::{EngineState, SavedTrack, StateError};
use terms::{GenericSet, WheelDrivers};
use weather::{WeatherState, WeatherTimeline};

/// How many past trains keep their contacts at the measurement sites, for
/// measurements logged after their train has left.
const RECENT_TRAINS: usize = 16;

/// Why the engine stopped.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// A sink failed: an output could not be written.
    #[error("writing the outputs")]
    Sink(#[source] SinkError),
    /// A `mu`/`adhesion` measurement logged so long after its train that the
    /// engine no longer keeps that train's contacts at the sites.
    #[error(
        "measurement at log_time {log_time_ns} ns (message index {index_in_file}) of train \
         {train_id} arrives more than {RECENT_TRAINS} trains after its passage; tortwin keeps \
         the site contacts of the last {RECENT_TRAINS} trains"
    )]
    MeasurementTooLate {
        train_id: String,
        log_time_ns: u64,
        index_in_file: u64,
    },
    /// A generic term's factor has no finite value at what the recording
    /// gives its driver.
    #[error(
        "effects.generic[{}]: g({} = {}) = {} is not a finite number of at most 1e12 (the \
         {topic} message at log_time {log_time_ns} ns, message index {index_in_file}); choose \
         a form and parameter defined over the values the recording shows (a power needs x > \
         0) that changes the quantity by no more than a factor 1e12",
        .factor.term, .factor.driver.name(), .factor.x, .factor.g
    )]
    UndefinedFactor {
        factor: terms::UndefinedFactor,
        topic: &'static str,
        log_time_ns: u64,
        index_in_file: u64,
    },
    /// The model gave a value that is not a finite number (the invariant
    /// that no NaN or infinity reaches an output): the recording's or the
    /// configuration's numbers, each within its range, combine to one the
    /// arithmetic cannot hold.
    #[error(
        "{what} is {value}, not a finite number ({topic} message at log_time {log_time_ns} ns, \
         message index {index_in_file}{about}); the recording's and the configuration's values \
         are each within their ranges but together beyond what the model can compute: check \
         them against docs/spec/recording-format.md \"Limits\" and the configuration's ranges"
    )]
    NotFinite {
        what: String,
        value: f64,
        topic: &'static str,
        log_time_ns: u64,
        index_in_file: u64,
        /// The train, rail and point, where there are.
        about: String,
    },
}

impl EngineError {
    /// Whether the recording or configuration is at fault (exit status 2),
    /// not the machine or an output. A sink's error is opaque to the engine:
    /// it is bad input only where its causes hold one of the input errors
    /// (an output folder that cannot be made is a `UsageError` under the
    /// sink's file error) or an I/O error the user has to fix (a full disk,
    /// a read-only folder: `tortwin_files::usage::is_environment`).
    pub fn is_input(&self) -> bool {
        match self {
            EngineError::Sink(e) => std::iter::successors(
                Some(e.as_ref() as &(dyn std::error::Error + 'static)),
                |e| e.source(),
            )
            .any(|e| {
                e.is::<InputError>()
                    || e.is::<ConfigError>()
                    || e.is::<UsageError>()
                    || e.downcast_ref::<std::io::Error>()
                        .is_some_and(tortwin_files::usage::is_environment)
            }),
            EngineError::MeasurementTooLate { .. }
            | EngineError::UndefinedFactor { .. }
            | EngineError::NotFinite { .. } => true,
        }
    }
}

impl From<SinkError> for EngineError {
    fn from(e: SinkError) -> Self {
        EngineError::Sink(e)
    }
}

/// Marks "no applicator at this point" in [`Engine::applicator_at`].
const NO_APPLICATOR: u32 = u32::MAX;

/// Options that change what the engine reports, not what it computes.
#[derive(Debug, Clone, Copy, Default)]
pub struct EngineOptions {
    /// Also emit a [`SnapshotKind::Wheel`] field snapshot after every wheel.
    pub snapshot_every_wheel: bool,
    /// Give every wheel's contacts to [`Sink::wheel_contacts`] (what strategy
    /// statistics over every contact need; far cheaper than a snapshot).
    pub every_wheel_contacts: bool,
    /// Carry every mass's derivatives with respect to the state constants
    /// (`tortwin_model::tangent`) and give each measurement's with its
    /// [`Readout`] (`mass_tangent`). The contacts run one by one (not four
    /// wheels at once); the masses are the same. A replay from a saved
    /// state starts with zero tangents: the saved masses are taken as given.
    pub tangents: bool,
    /// With `tangents`: the effect parameters the tangents' effect slots
    /// follow (`tortwin_model::tangent::EffectParam`), slot by slot; a
    /// slot that follows none stays zero. A parameter of an effect or term
    /// that the configuration does not switch on has a zero slot.
    pub effect_tangents: [Option<tortwin_model::tangent::EffectParam>; tangent::EFFECT_SLOTS],
    /// Let values that are not finite numbers through to the sink instead
    /// of stopping with [`EngineError::NotFinite`]: for a study's own
    /// replays, where a candidate whose arithmetic overflows is a worst
    /// cost to be ranked last, not an output.
    pub non_finite_allowed: bool,
    /// Step with the portable kernel (`f64::exp` lane by lane, plain
    /// division) even on a CPU with AVX2 and FMA, where the vector kernel
    /// is the default. The two give the same bits (crates/engine/tests/
    /// kernel.rs checks it); this is for checking that, and for timing it.
    pub portable_kernel: bool,
    /// Where the CPU has AVX-512, still roll a track's wheels in
    /// wavefronts of four (AVX2 registers) rather than two consecutive
    /// groups as one wavefront of eight (AVX-512 registers). The two give
    /// the same bits (crates/engine/tests/kernel.rs checks it); this is for
    /// checking that, and for timing it.
    pub narrow_kernel: bool,
    /// On a line: after each train, give [`Sink::line_wheels`] what axle
    /// `K` and the next saw along each rail and axle `K`'s tread bands
    /// (the train's last two axles when it has no axle `K + 1`). Ignored
    /// on a section.
    pub line_axle: Option<usize>,
    /// The replay writes output files on threads of its own, which take
    /// the second core: a train's tracks (a line's rails) then roll in
    /// parallel only when each has at least 2^17 (131 072) contacts, else
    /// one after the other on the engine's thread. A
    /// parallel roll costs the rayon worker's wake-up and its spinning
    /// after each train, which the output threads would have used: 3 days
    /// of the 600 m curve with MCAP out (15.6 k contacts a track and train)
    /// took 80 ms and 138 ms of CPU with the rails in parallel, 77 ms and
    /// 127 ms one after the other; the year on the 1.5 km curve with MCAP
    /// and .rrd out (41 k) 15.2 against 14.6 s. A day of the 10 km example
    /// line with MCAP out (276 k a rail) took 314 ms in parallel, 411 ms one
    /// after the other. Without output files the tracks roll in parallel
    /// from a few thousand contacts (the 3-day curve: 62 ms against 75).
    /// The results are the same either way.
    pub beside_output_threads: bool,
}

/// The calculation grid: `d_i = i * C`, `C = pi * nominal wheel diameter`,
/// `i = 0 ..= floor(L / C)` (model.md).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    pub spacing_m: f64,
    pub d_m: Vec<f64>,
}

impl Grid {
    pub fn new(length_m: f64, nominal_wheel_diameter_m: f64) -> Self {
        let spacing_m = std::f64::consts::PI * nominal_wheel_diameter_m;
        let i_last = (length_m / spacing_m).floor() as usize;
        let d_m = (0..=i_last).map(|i| i as f64 * spacing_m).collect();
        Self { spacing_m, d_m }
    }

    pub(crate) fn i_last(&self) -> usize {
        self.d_m.len() - 1
    }

    /// The grid point a position snaps to: `min(floor(x / C + 0.5), i_last)`.
    pub fn snap(&self, position_m: f64) -> usize {
        ((position_m / self.spacing_m + 0.5).floor() as usize).min(self.i_last())
    }
}

/// One surface of one rail: its product mass and touch history per point.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackState {
    pub rail_mass_kg: Vec<f64>,
    /// time_s of the last contact or pulse; NaN where never touched.
    pub last_touch_s: Vec<f64>,
    /// P (mm, effects.md) at the last touch; meaningless where never touched.
    pub precip_at_touch_mm: Vec<f64>,
    /// Wheels that have rolled over this track.
    pub wheel_pass: u64,
}

impl TrackState {
    fn new(points: usize) -> Self {
        Self {
            rail_mass_kg: vec![0.0; points],
            last_touch_s: vec![f64::NAN; points],
            precip_at_touch_mm: vec![0.0; points],
            wheel_pass: 0,
        }
    }
}

/// One wheel on one rail: what depends on the wheel and not on the point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct WheelOnRail {
    pub(crate) track: usize,
    pub(crate) q_n: f64,
    pub(crate) hertz: HertzContact,
    pub(crate) kalker: KalkerCoefficients,
    pub(crate) creepage: Creepage,
    /// fp · fc, eq. (2) and (3).
    pub(crate) fp_fc: f64,
    /// What generic terms driven by the wheel see.
    pub(crate) drivers: WheelDrivers,
}

/// A train being rolled, or kept for late measurements.
#[derive(Debug, Clone)]
struct TrainRecord {
    passage: Passage,
    log_time_ns: u64,
    /// The passage's message index in the file (for errors).
    index_in_file: u64,
    /// When the last axle leaves the section, time_s (the occupation's end).
    end_s: f64,
    end_ns: u64,
    /// [axle][rail]
    wheels: Vec<WheelOnRail>,
    /// Total mass at step 2 of each contact at a measurement site:
    /// [(axle * rails + rail) * sites + site].
    site_mass_kg: Vec<f64>,
    /// muD and muC of eq. (4) at those contacts, where friction terms make
    /// them differ from the configuration's (else empty).
    site_levels: Vec<(f64, f64)>,
    /// The time_s and weather of those contacts (for read-outs).
    site_at: Vec<(f64, Weather)>,
    /// With tangents: the tangents of `site_mass_kg` (else empty).
    site_tan: Vec<Tangent>,
    /// On a line: every wheel per segment, [(axle * rails + rail) *
    /// segments + segment], its load and creepage there (line.md, the
    /// axle field `segments`); empty on a section.
    seg_wheels: Vec<WheelOnRail>,
}

/// An event inside a train's occupation, waiting for the train to be rolled.
#[derive(Debug, Clone)]
struct Buffered {
    event: Event,
    time_s: f64,
    /// The simulated value of a tribometer reading and the rail mass it
    /// read, filled while rolling.
    reading: Option<roll::Reading>,
    /// A pulse that has landed: on a line, a train's roll lands the pulses
    /// that come before its wheels, and the next train's roll (which shares
    /// the rest of the window) must not land them again.
    landed: bool,
}

/// A train that entered a line while the trains before it were still on it
/// (line.md: trains share a line while none catches up with another). It
/// starts once those before it have been rolled.
#[derive(Debug, Clone)]
struct Following {
    log_time_ns: u64,
    index_in_file: u64,
    passage: Passage,
    /// The window's length when its passage came: the window's events from
    /// here on come after it in replay order.
    at: usize,
}

/// A pulse or tribometer reading at one point of one track, inside a window.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PointEvent {
    pub(crate) point: usize,
    pub(crate) time_s: f64,
    /// Index into the window's buffered events.
    pub(crate) buffered: usize,
    pub(crate) kind: PointEventKind,
    pub(crate) done: bool,
}

#[derive(Debug, Clone, Copy)]
pub(crate) enum PointEventKind {
    Pulse {
        applicator: usize,
        /// The mass that lands on this track (half the pulse on each band).
        mass_kg: f64,
    },
    Reading,
}

/// Running totals for the run summary.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Totals {
    pub(crate) trains: u64,
    pub(crate) wheels: u64,
    pub(crate) contacts: u64,
    pub(crate) pulses: u64,
    pub(crate) measurements: u64,
    pub(crate) weather_messages: u64,
    pub(crate) applied_kg: f64,
    pub(crate) carried_out_kg: f64,
    pub(crate) consumed_kg: f64,
    pub(crate) capped_kg: f64,
    pub(crate) effects_lost_kg: f64,
    /// Sum of squared residuals and counts per quantity (mu, adhesion, rail_mu).
    pub(crate) sq_residual: [f64; 3],
    pub(crate) residual_n: [u64; 3],
}

/// The replay engine of one section. A clone is a checkpoint: pushing the
/// same events into it continues the replay exactly
/// ([`Engine::resume_with`]).
#[derive(Clone)]
pub struct Engine {
    cfg: ModelConfig,
    opts: EngineOptions,
    section: Section,
    /// The section's site ids and rail names, shared with the measurements'
    /// outputs (a sink thread's copy of an output is then a count, not an
    /// allocation per name).
    site_ids: Vec<Arc<str>>,
    rail_names: Vec<Arc<str>>,
    grid: Grid,
    steel: Steel,
    tracks: Vec<TrackState>,
    track_info: Vec<TrackInfo>,
    /// Per rail: the track of a leading and of a trailing axle.
    rail_tracks: Vec<[usize; 2]>,
    /// Per rail: the track a tribometer reads (the top band).
    reading_track: Vec<usize>,
    /// Per applicator and rail: the tracks its pulse lands on, in equal
    /// shares.
    pulse_tracks: Vec<Vec<Vec<usize>>>,
    /// On a line (line.md): its layout on the grid; `None` on a section.
    line: Option<line::LineLayout>,
    applicator_points: Vec<usize>,
    site_points: Vec<usize>,
    /// Per track, per point: the applicator a wheel passes there, or NO_APPLICATOR.
    applicator_at: Vec<Vec<u32>>,
    /// Per point: the sites there (usually none).
    sites_at: Vec<Vec<usize>>,
    /// `exp(-(N - 1) / cN)` for N - 1 = 0 ..= i_last.
    revolution: Vec<f64>,
    time_effects: TimeEffects,
    /// The generic terms, compiled for this section (shared with the
    /// rolling wheel).
    generic: Arc<GenericSet>,
    weather: WeatherState,
    occupied_until_s: f64,
    /// The time_s of the last event pushed: nothing has been computed at a
    /// later time.
    last_event_s: f64,
    origin_ns: i64,
    on_rail_start_kg: f64,
    totals: Totals,
    begun: bool,
    // The occupation being buffered.
    pending: Option<TrainRecord>,
    window: Vec<Buffered>,
    /// On a line: the trains that entered while `pending` was on it, in
    /// order.
    following: VecDeque<Following>,
    /// Pulses and measurements outside an occupation, held until the replay
    /// moves past their log_time: a weather message with the same log_time
    /// comes after them in replay order (topic order) yet is the weather in
    /// effect at their time (model.md: the last message with time <= t,
    /// whatever the replay position), as it is for events inside a window.
    deferred: Vec<Event>,
    recent: VecDeque<TrainRecord>,
    // Scratch, reused from train to train.
    timeline: WeatherTimeline,
    /// Per track: its point events, latest pulses and what its roll reports.
    work: Vec<roll::TrackWork>,
    /// The totals of a train's roll, sorted into the serial order.
    ledger: Vec<roll::Addend>,
    /// Per track: the axle that rolled over it last in the current train.
    last_axle: Vec<usize>,
    /// Per track: the next row of its wheels' contacts to hand out.
    last_row: Vec<usize>,
    /// Per track and point: whether an applicator or a measurement site is
    /// there. Pulses land and readings are taken only there.
    special: Vec<Vec<bool>>,
    snapshot: roll::SnapshotBuffers,
    /// Hertz shapes by wheel diameter (bits).
    hertz_shapes: Vec<(u64, HertzShape)>,
}

impl Engine {
    /// A fresh section: clean rails, no weather yet, time origin `origin_ns`
    /// (the log_time of the first recording's `/section`).
    pub fn new(section: Section, cfg: ModelConfig, opts: EngineOptions, origin_ns: i64) -> Self {
        Self::on_line(section, None, cfg, opts, origin_ns)
    }

    /// A fresh line (line.md) when `line` is given, else [`Engine::new`]'s
    /// section. A line's tracks are its rails' crown and gauge corner
    /// (bands `C` and `G`, in that order per rail); its configuration must
    /// switch no effect on ([`line::check_config`]).
    pub fn on_line(
        section: Section,
        line: Option<tortwin_recording::line::Line>,
        cfg: ModelConfig,
        opts: EngineOptions,
        origin_ns: i64,
    ) -> Self {
        let grid = Grid::new(section.length_m, section.nominal_wheel_diameter_m);
        let points = grid.d_m.len();

        let bands = cfg.effects.is_on(Named::BogieBands);
        let mut track_info = Vec::new();
        let mut rail_tracks = Vec::new();
        let mut reading_track = Vec::new();
        let mut rail_pulse_tracks = Vec::new();
        for (rail, name) in section.rails.iter().enumerate() {
            let mut track = |band: &str| {
                track_info.push(TrackInfo {
                    rail,
                    rail_name: name.clone(),
                    band: band.into(),
                });
                track_info.len() - 1
            };
            if line.is_some() {
                let (crown, gauge) = (track(line::CROWN), track(line::GAUGE_CORNER));
                rail_tracks.push([crown, crown]);
                reading_track.push(crown);
                rail_pulse_tracks.push(vec![crown, gauge]);
            } else if bands && name == "high" {
                let (gauge, top) = (track("gauge_corner"), track("top"));
                rail_tracks.push([gauge, top]);
                reading_track.push(top);
                rail_pulse_tracks.push(vec![gauge, top]);
            } else {
                let t = track("top");
                rail_tracks.push([t, t]);
                reading_track.push(t);
                rail_pulse_tracks.push(vec![t]);
            }
        }

        let applicator_points: Vec<usize> = section
            .applicators
            .iter()
            .map(|a| grid.snap(a.position_m))
            .collect();
        let site_points: Vec<usize> = section
            .sites
            .iter()
            .map(|s| grid.snap(s.position_m))
            .collect();
        let line = line.map(|line| line::LineLayout::new(line, &grid, section.rails.len()));
        let pulse_tracks: Vec<Vec<Vec<usize>>> = applicator_points
            .iter()
            .map(|&p| match &line {
                Some(layout) => layout.pulse_tracks(&grid, p, section.rails.len()),
                None => rail_pulse_tracks.clone(),
            })
            .collect();
        let mut applicator_at = vec![vec![NO_APPLICATOR; points]; track_info.len()];
        for (a, app) in section.applicators.iter().enumerate() {
            for &rail in &app.rails {
                // A wheel passes the applicator on whatever band it runs:
                // on a line, every track of the rail.
                for &track in &rail_pulse_tracks[rail] {
                    let slot = &mut applicator_at[track][applicator_points[a]];
                    // Of several applicators at one point, the first listed counts.
                    if *slot == NO_APPLICATOR {
                        *slot = a as u32;
                    }
                }
            }
        }
        let mut sites_at = vec![Vec::new(); points];
        for (s, &p) in site_points.iter().enumerate() {
            sites_at[p].push(s);
        }
        let revolution = (0..points)
            .map(|n| product::revolution_factor(&cfg.product, n as u32 + 1))
            .collect();
        let time_effects = TimeEffects {
            ageing_tau_s: cfg.effects.param(Named::RailAgeing, 0),
            rain_k_per_mm: cfg.effects.param(Named::RainWashoff, 0),
        };
        let n_tracks = track_info.len();
        let generic = Arc::new(GenericSet::compile(
            &cfg.effects.generic,
            &section,
            origin_ns,
        ));
        Self {
            site_ids: section
                .sites
                .iter()
                .map(|s| Arc::from(s.id.as_str()))
                .collect(),
            rail_names: section
                .rails
                .iter()
                .map(|r| Arc::from(r.as_str()))
                .collect(),
            steel: Steel {
                e_pa: cfg.contact.e_pa,
                nu: cfg.contact.nu,
            },
            tracks: (0..n_tracks).map(|_| TrackState::new(points)).collect(),
            work: vec![
                {
                    let mut work = roll::TrackWork::new(points);
                    if opts.tangents {
                        work.rail_tan = vec![[0.0; tangent::SLOTS]; points];
                    }
                    work
                };
                n_tracks
            ],
            ledger: Vec::new(),
            last_axle: vec![usize::MAX; n_tracks],
            last_row: vec![0; n_tracks],
            special: (0..n_tracks)
                .map(|t| {
                    (0..points)
                        .map(|i| applicator_at[t][i] != NO_APPLICATOR || !sites_at[i].is_empty())
                        .collect()
                })
                .collect(),
            snapshot: roll::SnapshotBuffers::default(),
            hertz_shapes: Vec::new(),
            cfg,
            opts,
            grid,
            track_info,
            rail_tracks,
            reading_track,
            pulse_tracks,
            line,
            applicator_points,
            site_points,
            applicator_at,
            sites_at,
            revolution,
            time_effects,
            generic,
            weather: WeatherState::default(),
            occupied_until_s: f64::NEG_INFINITY,
            last_event_s: f64::NEG_INFINITY,
            origin_ns,
            on_rail_start_kg: 0.0,
            totals: Totals::default(),
            begun: false,
            pending: None,
            window: Vec::new(),
            following: VecDeque::new(),
            deferred: Vec::new(),
            recent: VecDeque::new(),
            timeline: WeatherTimeline::default(),
            section,
        }
    }

    pub fn section(&self) -> &Section {
        &self.section
    }

    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    pub fn tracks(&self) -> &[TrackState] {
        &self.tracks
    }

    /// `time_s = (log_time_ns - origin_ns) * 1e-9`, the difference in 64-bit
    /// integers (model.md).
    pub(crate) fn time_s(&self, log_time_ns: u64) -> f64 {
        (log_time_ns as i64).wrapping_sub(self.origin_ns) as f64 * 1e-9
    }

    fn rail_mass_total_kg(&self) -> f64 {
        self.tracks.iter().flat_map(|t| t.rail_mass_kg.iter()).sum()
    }

    fn begin(&mut self, sink: &mut dyn Sink) -> Result<(), EngineError> {
        if !self.begun {
            self.begun = true;
            self.on_rail_start_kg = self.rail_mass_total_kg();
            sink.begin(&SectionInfo {
                section: std::borrow::Cow::Borrowed(&self.section),
                grid_d_m: self.grid.d_m.as_slice().into(),
                tracks: self.track_info.as_slice().into(),
                applicator_points: self.applicator_points.as_slice().into(),
                site_points: self.site_points.as_slice().into(),
                origin_ns: self.origin_ns,
                line: self
                    .line
                    .as_ref()
                    .map(|l| std::borrow::Cow::Borrowed(&l.line)),
            })?;
        }
        Ok(())
    }

    /// Takes the next event in replay order.
    pub fn push(&mut self, event: Event, sink: &mut dyn Sink) -> Result<(), EngineError> {
        self.begin(sink)?;
        self.check_factors(&event)?;
        let same_instant = self
            .deferred
            .first()
            .is_some_and(|d| d.log_time_ns == event.log_time_ns);
        if !same_instant {
            self.flush_deferred(sink)?;
        }
        let time_s = self.time_s(event.log_time_ns);
        self.last_event_s = self.last_event_s.max(time_s);
        let passage = matches!(event.kind, EventKind::Passage(_));
        while let Some(train) = &self.pending {
            // On a section a passage ends the window; on a line a train may
            // enter while others are on it (the reader checks that none
            // catches up), and a train rolls once the replay is past its end.
            let ends = time_s > train.end_s || (passage && self.line.is_none());
            if !ends {
                break;
            }
            self.roll_pending(sink)?;
        }
        if self.pending.is_some() {
            if let EventKind::Passage(passage) = event.kind {
                self.following.push_back(Following {
                    log_time_ns: event.log_time_ns,
                    index_in_file: event.index_in_file,
                    passage,
                    at: self.window.len(),
                });
                return Ok(());
            }
            self.window.push(Buffered {
                event,
                time_s,
                reading: None,
                landed: false,
            });
            return Ok(());
        }
        match event.kind {
            EventKind::Passage(passage) => {
                self.start_train(event.log_time_ns, event.index_in_file, passage, sink)
            }
            EventKind::Weather(w) => {
                self.totals.weather_messages += 1;
                self.weather = self.weather.after_message(time_s, w);
                Ok(sink.weather(event.log_time_ns)?)
            }
            EventKind::Pulse(_) | EventKind::Measurement(_) => {
                self.deferred.push(event);
                Ok(())
            }
        }
    }

    /// Tells the engine that no event earlier than `log_time_ns` is to come
    /// (a followed recording: a message at that time has been read): the
    /// trains whose occupation ended before it are rolled, and the pulses
    /// and readings held at an earlier instant are taken, now rather than
    /// when the next event is pushed. The same operations in the same
    /// order as that push would do first: the outputs and the state are
    /// the same, only sooner.
    pub fn advance_to(&mut self, log_time_ns: u64, sink: &mut dyn Sink) -> Result<(), EngineError> {
        self.begin(sink)?;
        if self
            .deferred
            .first()
            .is_some_and(|d| d.log_time_ns < log_time_ns)
        {
            self.flush_deferred(sink)?;
        }
        let time_s = self.time_s(log_time_ns);
        self.last_event_s = self.last_event_s.max(time_s);
        while let Some(train) = &self.pending {
            if time_s <= train.end_s {
                break;
            }
            self.roll_pending(sink)?;
        }
        Ok(())
    }

    /// Refuses an event at which a generic term's factor has no finite value.
    fn check_factors(&self, event: &Event) -> Result<(), EngineError> {
        if self.cfg.effects.generic.is_empty() {
            return Ok(());
        }
        let undefined = match &event.kind {
            EventKind::Weather(w) => self.generic.undefined(|d| match d {
                Driver::AirTemperatureC => Some(w.air_temperature_c),
                Driver::RelativeHumidity => Some(w.relative_humidity),
                Driver::PrecipitationMmH => Some(w.precipitation_mm_h),
                _ => None,
            }),
            EventKind::Passage(p) => p.axles.iter().find_map(|axle| {
                (0..self.section.rails.len()).find_map(|rail| {
                    let drivers = wheel_drivers(p.speed_mps, axle, rail);
                    self.generic.undefined(|d| match d {
                        Driver::SpeedMps => Some(drivers.speed_mps),
                        Driver::WheelLoadKn => Some(drivers.wheel_load_kn),
                        Driver::Creepage => Some(drivers.creepage),
                        _ => None,
                    })
                })
            }),
            _ => None,
        };
        match undefined {
            None => Ok(()),
            Some(factor) => Err(EngineError::UndefinedFactor {
                factor,
                topic: match event.kind {
                    EventKind::Weather(_) => "/environment/weather",
                    _ => "/train/passage",
                },
                log_time_ns: event.log_time_ns,
                index_in_file: event.index_in_file,
            }),
        }
    }

    /// Lands the deferred pulses and takes the deferred readings, in replay
    /// order, with the weather in effect at their time.
    fn flush_deferred(&mut self, sink: &mut dyn Sink) -> Result<(), EngineError> {
        if self.deferred.is_empty() {
            return Ok(());
        }
        let mut deferred = std::mem::take(&mut self.deferred);
        let result = deferred
            .iter()
            .try_for_each(|event| self.apply_outside_occupation(event, sink));
        deferred.clear();
        self.deferred = deferred;
        result
    }

    /// A pulse or measurement between trains.
    fn apply_outside_occupation(
        &mut self,
        event: &Event,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let time_s = self.time_s(event.log_time_ns);
        match &event.kind {
            EventKind::Pulse(pulse) => {
                let tracks = self.pulse_tracks[pulse.applicator][pulse.rail].len();
                for k in 0..tracks {
                    let track = self.pulse_tracks[pulse.applicator][pulse.rail][k];
                    let share = pulse.mass_kg / tracks as f64;
                    let point = self.applicator_points[pulse.applicator];
                    let weather = self.weather;
                    let (ctx, states, works) = self.split();
                    let added = ctx.land_pulse(
                        track,
                        &mut states[track],
                        &mut works[track].rail_tan,
                        point,
                        time_s,
                        pulse.applicator,
                        share,
                        &weather,
                    );
                    self.totals.add_pulse(&added);
                }
                self.emit_pulse(event.log_time_ns, pulse, sink)
            }
            EventKind::Measurement(m) => {
                let (simulated, readout) = match &m.of {
                    Measured::RailMu => {
                        let track = self.reading_track[m.rail];
                        let point = self.site_points[m.site];
                        let weather = self.weather;
                        let (ctx, states, works) = self.split();
                        let reading = ctx.read_rail(
                            track,
                            &states[track],
                            &works[track].rail_tan,
                            point,
                            time_s,
                            &weather,
                        );
                        let readout = sink
                            .wants_readouts()
                            .then(|| self.reading_readout(&reading, time_s, &weather.current));
                        (reading.value, readout)
                    }
                    Measured::Mu(axle) | Measured::Adhesion(axle) => {
                        let record = self.record_of(event, axle)?;
                        let readout = sink
                            .wants_readouts()
                            .then(|| self.readout_from(record, m, axle));
                        (self.value_from(record, m, axle), readout)
                    }
                };
                self.emit_measurement(event, m, simulated, readout, sink)
            }
            EventKind::Passage(_) | EventKind::Weather(_) => Ok(()),
        }
    }

    /// Rolls the train still buffered, if any, and reports the run's figures.
    /// The engine stays usable: [`Engine::state`] gives what the next day needs.
    pub fn finish(
        &mut self,
        sink: &mut dyn Sink,
        unknown_topic_messages: u64,
    ) -> Result<RunSummary, EngineError> {
        self.begin(sink)?;
        self.flush_deferred(sink)?;
        while self.pending.is_some() {
            self.roll_pending(sink)?;
        }
        let summary = self.summary(unknown_topic_messages);
        sink.finish(&summary)?;
        Ok(summary)
    }

    /// The figures so far.
    pub fn summary(&self, unknown_topic_messages: u64) -> RunSummary {
        let t = &self.totals;
        let rmse = [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu]
            .iter()
            .enumerate()
            .filter(|(q, _)| t.residual_n[*q] > 0)
            .map(|(q, quantity)| {
                let n = t.residual_n[q];
                (
                    quantity.as_str().to_string(),
                    n,
                    (t.sq_residual[q] / n as f64).sqrt(),
                )
            })
            .collect();
        RunSummary {
            trains: t.trains,
            wheels: t.wheels,
            contacts: t.contacts,
            pulses: t.pulses,
            measurements: t.measurements,
            weather_messages: t.weather_messages,
            unknown_topic_messages,
            rmse,
            mass_balance: MassBalance {
                on_rail_start_kg: self.on_rail_start_kg,
                applied_kg: t.applied_kg,
                on_rail_end_kg: self.rail_mass_total_kg(),
                carried_out_kg: t.carried_out_kg,
                consumed_kg: t.consumed_kg,
                capped_kg: t.capped_kg,
                effects_lost_kg: t.effects_lost_kg,
            },
        }
    }

    fn start_train(
        &mut self,
        log_time_ns: u64,
        index_in_file: u64,
        passage: Passage,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let time_s = self.time_s(log_time_ns);
        let last_offset_m = passage.axles.last().map_or(0.0, |a| a.offset_m);
        let occupation_s = (self.section.length_m + last_offset_m) / passage.speed_mps;
        let end_s = time_s + occupation_s;
        // The end as a log_time for the outputs: the passage's log_time plus
        // the occupation in integer nanoseconds, rounded up (through a double
        // of nanoseconds since the epoch it would be off by up to 128 ns).
        let end_ns = log_time_ns.saturating_add((occupation_s * 1e9).ceil() as u64);
        // The oldest record's buffers are reused once the window is full.
        let oldest = match self.recent.len() >= RECENT_TRAINS {
            true => self.recent.pop_front(),
            false => None,
        };
        let mut record = match oldest {
            Some(mut r) => {
                r.passage = passage;
                r
            }
            None => TrainRecord {
                passage,
                log_time_ns,
                index_in_file,
                end_s,
                end_ns,
                wheels: Vec::new(),
                site_mass_kg: Vec::new(),
                site_levels: Vec::new(),
                site_at: Vec::new(),
                site_tan: Vec::new(),
                seg_wheels: Vec::new(),
            },
        };
        record.log_time_ns = log_time_ns;
        record.index_in_file = index_in_file;
        record.end_s = end_s;
        record.end_ns = end_ns;
        record.wheels.clear();
        let rails = self.section.rails.len();
        for axle in &record.passage.axles {
            for rail in 0..rails {
                let q_n = axle.wheel_load_n.get(rail).copied().unwrap_or(0.0);
                let creepage = axle.creepage.get(rail).copied().unwrap_or(Creepage {
                    cx: 0.0,
                    cy: 0.0,
                    spin_per_m: 0.0,
                });
                let wheel = self.wheel_on_rail(axle, rail, q_n, creepage, record.passage.speed_mps);
                record.wheels.push(wheel);
            }
        }
        self.line_wheels(&mut record);
        record.site_mass_kg.clear();
        record.site_mass_kg.resize(
            record.passage.axles.len() * rails * self.section.sites.len(),
            f64::NAN,
        );
        record.site_at.clear();
        record
            .site_at
            .resize(record.site_mass_kg.len(), (f64::NAN, Weather::default()));
        record.site_tan.clear();
        if self.opts.tangents {
            record
                .site_tan
                .resize(record.site_mass_kg.len(), [f64::NAN; tangent::SLOTS]);
        }
        record.site_levels.clear();
        if self.generic.any_friction() {
            record
                .site_levels
                .resize(record.site_mass_kg.len(), (f64::NAN, f64::NAN));
        }
        sink.train(&TrainEvent {
            log_time_ns,
            end_ns,
            train_id: record.passage.train_id.as_str().into(),
            direction: record.passage.direction,
            speed_mps: record.passage.speed_mps,
            axles: record.passage.axles.len(),
        })?;
        self.totals.trains += 1;
        self.pending = Some(record);
        self.window.clear();
        Ok(())
    }

    /// Axle `axle`'s wheel on `rail` under load `q_n` and `creepage`:
    /// Hertz, Kalker and eq. (2)-(3)'s `fp fc`.
    fn wheel_on_rail(
        &mut self,
        axle: &Axle,
        rail: usize,
        q_n: f64,
        creepage: Creepage,
        speed_mps: f64,
    ) -> WheelOnRail {
        let hertz = self.hertz_shape(axle.wheel_diameter_m).contact(q_n);
        let kalker = contact::kalker(self.cfg.contact.nu, hertz.a_m, hertz.b_m);
        let fp_fc = product::pressure_factor(&self.cfg.product, hertz.pm_pa)
            * product::creepage_factor(&self.cfg.product, creepage.cx, creepage.cy);
        let bogie = usize::from(axle.bogie_position == BogiePosition::Trailing);
        WheelOnRail {
            track: self.rail_tracks[rail][bogie],
            q_n,
            hertz,
            kalker,
            creepage,
            fp_fc,
            drivers: wheel_drivers(speed_mps, axle, rail),
        }
    }

    /// The Hertz shape of a wheel of this diameter on this section's rails,
    /// solved once per diameter (the load only scales it).
    fn hertz_shape(&mut self, wheel_diameter_m: f64) -> HertzShape {
        let key = wheel_diameter_m.to_bits();
        if let Some((_, shape)) = self.hertz_shapes.iter().find(|(k, _)| *k == key) {
            return *shape;
        }
        let shape = HertzShape::new(
            wheel_diameter_m / 2.0,
            self.cfg.contact.wheel_profile_radius_m,
            self.section.rail_head_radius_m,
            &self.steel,
        );
        // Recordings carry a handful of wheel diameters; a recording with
        // every wheel different keeps the cache small all the same.
        if self.hertz_shapes.len() >= 256 {
            self.hertz_shapes.clear();
        }
        self.hertz_shapes.push((key, shape));
        shape
    }

    /// Rolls the buffered train and publishes its window.
    fn roll_pending(&mut self, sink: &mut dyn Sink) -> Result<(), EngineError> {
        let Some(mut record) = self.pending.take() else {
            return Ok(());
        };
        // The weather over the occupation, and the point events per track.
        self.timeline.reset(self.weather);
        for work in &mut self.work {
            work.clear_events();
        }
        for (b, buffered) in self.window.iter().enumerate() {
            match &buffered.event.kind {
                EventKind::Weather(w) => self.timeline.push(buffered.time_s, *w),
                // Run in the roll of a train before this one on the line.
                EventKind::Pulse(_) if buffered.landed => {}
                EventKind::Measurement(_) if buffered.reading.is_some() => {}
                EventKind::Pulse(p) => {
                    let tracks = &self.pulse_tracks[p.applicator][p.rail];
                    for &track in tracks {
                        let point = self.applicator_points[p.applicator];
                        self.work[track].push_event(PointEvent {
                            point,
                            time_s: buffered.time_s,
                            buffered: b,
                            kind: PointEventKind::Pulse {
                                applicator: p.applicator,
                                mass_kg: p.mass_kg / tracks.len() as f64,
                            },
                            done: false,
                        });
                    }
                }
                EventKind::Measurement(m) if m.of == Measured::RailMu => {
                    let track = self.reading_track[m.rail];
                    let point = self.site_points[m.site];
                    self.work[track].push_event(PointEvent {
                        point,
                        time_s: buffered.time_s,
                        buffered: b,
                        kind: PointEventKind::Reading,
                        done: false,
                    });
                }
                _ => {}
            }
        }

        self.roll_train(&mut record, sink)?;

        // The window's events before the next train's passage (all of them
        // without one) are this train's to publish; the rest is the next
        // train's window.
        let split = self.following.front().map_or(self.window.len(), |f| f.at);
        // Point events after the last wheel at their point, in replay order;
        // after the next train's passage they wait for its wheels.
        for track in 0..self.tracks.len() {
            for k in 0..self.work[track].events.len() {
                let ev = self.work[track].events[k];
                if ev.done {
                    if let PointEventKind::Pulse { .. } = ev.kind {
                        self.window[ev.buffered].landed = true;
                    }
                }
                if !ev.done && ev.buffered < split {
                    let (ctx, states, works) = self.split();
                    let weather = *ctx.timeline.at(ev.time_s);
                    if let roll::Ran::Pulse(added) = ctx.run_point_event(
                        track,
                        &mut states[track],
                        &mut works[track],
                        k,
                        &weather,
                    ) {
                        self.totals.add_pulse(&added);
                    }
                }
            }
        }
        self.settle(&mut record);
        self.weather = match split < self.window.len() {
            // The weather at the next train's passage: where its window's
            // weather carries on from.
            true => self.window[..split]
                .iter()
                .fold(self.timeline.first(), |w, b| match &b.event.kind {
                    EventKind::Weather(m) => w.after_message(b.time_s, *m),
                    _ => w,
                }),
            false => self.timeline.last(),
        };
        self.occupied_until_s = record.end_s.max(self.occupied_until_s);

        // Publish the window in replay order, then the field.
        let mut window = std::mem::take(&mut self.window);
        let rest = window.split_off(split);
        for buffered in &window {
            match &buffered.event.kind {
                EventKind::Pulse(p) => self.emit_pulse(buffered.event.log_time_ns, p, sink)?,
                EventKind::Measurement(m) => {
                    let wants = sink.wants_readouts();
                    let (simulated, readout) = match (&m.of, buffered.reading) {
                        (Measured::RailMu, Some(reading)) => {
                            let readout = wants.then(|| {
                                let weather = self.timeline.at(buffered.time_s).current;
                                self.reading_readout(&reading, buffered.time_s, &weather)
                            });
                            (reading.value, readout)
                        }
                        (Measured::RailMu, None) => {
                            unreachable!("every reading in a window is run while rolling or after")
                        }
                        (Measured::Mu(axle) | Measured::Adhesion(axle), _) => {
                            let from = if axle.train_seq == record.passage.train_seq {
                                &record
                            } else {
                                self.record_of(&buffered.event, axle)?
                            };
                            let readout = wants.then(|| self.readout_from(from, m, axle));
                            (self.value_from(from, m, axle), readout)
                        }
                    };
                    self.emit_measurement(&buffered.event, m, simulated, readout, sink)?;
                }
                EventKind::Weather(_) => {
                    self.totals.weather_messages += 1;
                    sink.weather(buffered.event.log_time_ns)?;
                }
                EventKind::Passage(_) => unreachable!("a passage ends the window"),
            }
        }
        self.window = window;
        self.window.clear();
        self.emit_fields(&record, SnapshotKind::Train, sink)?;
        self.recent.push_back(record);
        // The next train on the line starts, with the rest of the window.
        if let Some(next) = self.following.pop_front() {
            self.start_train(next.log_time_ns, next.index_in_file, next.passage, sink)?;
            self.window = rest;
            for f in &mut self.following {
                f.at -= split;
            }
        }
        Ok(())
    }

    /// The record of the measured train among those kept in
    /// [`Engine::recent`].
    fn record_of(&self, event: &Event, axle: &AxleRef) -> Result<&TrainRecord, EngineError> {
        match self
            .recent
            .iter()
            .rev()
            .find(|r| r.passage.train_seq == axle.train_seq)
        {
            Some(record) => Ok(record),
            None => Err(EngineError::MeasurementTooLate {
                train_id: axle.train_id.to_string(),
                log_time_ns: event.log_time_ns,
                index_in_file: event.index_in_file,
            }),
        }
    }

    /// The simulated `mu` or `adhesion` of `axle`'s contact at `m`'s site
    /// and rail, from the train's record.
    fn value_from(&self, record: &TrainRecord, m: &Measurement, axle: &AxleRef) -> f64 {
        let rails = self.section.rails.len();
        let sites = self.section.sites.len();
        let k = (axle.axle_index * rails + m.rail) * sites + m.site;
        let mass = record.site_mass_kg[k];
        let mu = match record.site_levels.get(k) {
            Some(&levels) => self.friction_at(levels, mass),
            None => product::friction(&self.cfg.product, mass),
        };
        match m.of {
            Measured::Adhesion(_) => {
                let wheel = self.wheel_at_site(record, axle.axle_index, m.rail, m.site);
                self.adhesion(wheel, record.passage.speed_mps, mu)
            }
            _ => mu,
        }
    }

    /// What [`Engine::value_from`] reads, for a read-out.
    fn readout_from(&self, record: &TrainRecord, m: &Measurement, axle: &AxleRef) -> Readout {
        let rails = self.section.rails.len();
        let sites = self.section.sites.len();
        let k = (axle.axle_index * rails + m.rail) * sites + m.site;
        let wheel = self.wheel_at_site(record, axle.axle_index, m.rail, m.site);
        let (time_s, weather) = record.site_at[k];
        Readout {
            mass_kg: record.site_mass_kg[k],
            time_s,
            weather,
            wheel: Some(wheel.drivers),
            contact: matches!(m.of, Measured::Adhesion(_))
                .then(|| self.adhesion_contact(wheel, record.passage.speed_mps)),
            mass_tangent: record.site_tan.get(k).copied(),
        }
    }

    /// What a tribometer reading read, for a read-out.
    fn reading_readout(&self, reading: &roll::Reading, time_s: f64, weather: &Weather) -> Readout {
        Readout {
            mass_kg: reading.mass_kg,
            time_s,
            weather: *weather,
            wheel: None,
            contact: None,
            mass_tangent: self.opts.tangents.then_some(reading.tangent),
        }
    }

    /// Eq. (4) with muD and muC as the friction terms make them.
    pub(crate) fn friction_at(&self, levels: (f64, f64), mass_kg: f64) -> f64 {
        friction_at(&self.cfg.product, levels, mass_kg)
    }

    /// T/N by Polach with mu0 = mu (contact.md).
    pub(crate) fn adhesion(&self, wheel: &WheelOnRail, speed_mps: f64, mu: f64) -> f64 {
        self.adhesion_contact(wheel, speed_mps).forces(mu).t_over_q
    }

    /// The wheel's contact for Polach, to take T/N at many mu.
    pub(crate) fn adhesion_contact(&self, wheel: &WheelOnRail, speed_mps: f64) -> PolachContact {
        PolachContact::new(
            &PolachInput {
                q_n: wheel.q_n,
                a_m: wheel.hertz.a_m,
                b_m: wheel.hertz.b_m,
                g_pa: self.steel.g_pa(),
                kalker: wheel.kalker,
                sx: wheel.creepage.cx,
                sy: wheel.creepage.cy,
                psi_per_m: wheel.creepage.spin_per_m,
                speed_mps,
                mu0: f64::NAN,
            },
            &self.cfg.polach.params(),
        )
    }

    fn emit_pulse(
        &mut self,
        log_time_ns: u64,
        pulse: &tortwin_recording::Pulse,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        self.totals.pulses += 1;
        sink.pulse(&PulseEvent {
            log_time_ns,
            applicator: pulse.applicator,
            applicator_id: self.section.applicators[pulse.applicator]
                .id
                .as_str()
                .into(),
            rail: pulse.rail,
            rail_name: self.section.rails[pulse.rail].as_str().into(),
            mass_kg: pulse.mass_kg,
        })?;
        Ok(())
    }

    fn emit_measurement(
        &mut self,
        event: &Event,
        m: &Measurement,
        simulated: f64,
        readout: Option<Readout>,
        sink: &mut dyn Sink,
    ) -> Result<(), EngineError> {
        let simulated = self
            .generic
            .measured(simulated, m.site, m.rail, m.quantity());
        let q = match m.quantity() {
            Quantity::Mu => 0,
            Quantity::Adhesion => 1,
            Quantity::RailMu => 2,
        };
        // Its square too: it sums into the run's RMSE.
        if !self.opts.non_finite_allowed && !(m.value - simulated).powi(2).is_finite() {
            return Err(EngineError::NotFinite {
                what: format!("the simulated {}", m.quantity().as_str()),
                value: simulated,
                topic: "/measurement/friction",
                log_time_ns: event.log_time_ns,
                index_in_file: event.index_in_file,
                about: format!(
                    "; site `{}`, rail `{}`",
                    self.section.sites[m.site].id, self.section.rails[m.rail]
                ),
            });
        }
        self.totals.measurements += 1;
        self.totals.sq_residual[q] += (m.value - simulated).powi(2);
        self.totals.residual_n[q] += 1;
        sink.measurement(&MeasurementOutput {
            log_time_ns: event.log_time_ns,
            index_in_file: event.index_in_file,
            site_id: Arc::clone(&self.site_ids[m.site]),
            site: m.site,
            rail_name: Arc::clone(&self.rail_names[m.rail]),
            rail: m.rail,
            quantity: m.quantity(),
            train_id: m.axle().map(|a| Arc::clone(&a.train_id)),
            axle_index: m.axle().map(|a| a.axle_index),
            measured: m.value,
            simulated,
            readout: readout.map(Box::new),
        })?;
        Ok(())
    }

    /// This engine as a checkpoint for `cfg`: a copy that continues as a
    /// replay of `cfg` from the start would, when `cfg` is this engine's
    /// configuration with generic terms appended that have not acted yet
    /// (time steps whose `t0` lies after every event pushed so far: before
    /// it their factor is 1, exactly); `None` otherwise. Every contact,
    /// pulse, reading and time effect so far happened at or before the last
    /// event pushed (a train is rolled when an event after its occupation
    /// arrives), so the state is the one a replay of `cfg` has here, bit for
    /// bit.
    pub fn resume_with(&self, cfg: &ModelConfig) -> Option<Engine> {
        let own = &self.cfg.effects.generic;
        let extra = cfg.effects.generic.get(own.len()..)?;
        if extra.is_empty() || cfg.effects.generic[..own.len()] != own[..] {
            return None;
        }
        let mut same = cfg.clone();
        same.effects.generic.truncate(own.len());
        if same != self.cfg || terms::acts_from_s(extra, self.origin_ns) <= self.last_event_s {
            return None;
        }
        let mut engine = self.clone();
        engine.generic = Arc::new(GenericSet::compile(
            &cfg.effects.generic,
            &engine.section,
            engine.origin_ns,
        ));
        engine.cfg = cfg.clone();
        Some(engine)
    }

    /// The state the next recording starts from, taken after
    /// [`Engine::finish`] (which lands what is still held back).
    pub fn state(&self) -> EngineState {
        state::capture(self)
    }

    /// Continues from a state saved by [`Engine::state`] after an earlier
    /// recording of the same section.
    pub fn from_state(
        section: Section,
        line: Option<tortwin_recording::line::Line>,
        cfg: ModelConfig,
        opts: EngineOptions,
        saved: &EngineState,
    ) -> Result<Self, state::StateError> {
        state::restore(section, line, cfg, opts, saved)
    }
}

/// What generic terms driven by the wheel see of axle `axle` on `rail`.
fn wheel_drivers(speed_mps: f64, axle: &Axle, rail: usize) -> WheelDrivers {
    let q_n = axle.wheel_load_n.get(rail).copied().unwrap_or(0.0);
    let c = axle.creepage.get(rail).copied().unwrap_or(Creepage {
        cx: 0.0,
        cy: 0.0,
        spin_per_m: 0.0,
    });
    WheelDrivers {
        speed_mps,
        wheel_load_kn: q_n / 1000.0,
        creepage: (c.cx * c.cx + c.cy * c.cy).sqrt(),
    }
}

/// Whether a direction enters at d = 0.
/// Eq. (4) with muD and muC as the friction terms make them.
pub(crate) fn friction_at(
    product: &product::ProductParams,
    (mu_d, mu_c): (f64, f64),
    mass_kg: f64,
) -> f64 {
    let params = product::ProductParams {
        mu_d,
        mu_c,
        ..*product
    };
    product::friction(&params, mass_kg)
}

pub(crate) fn enters_at_zero(direction: Direction) -> bool {
    direction == Direction::Up
}
