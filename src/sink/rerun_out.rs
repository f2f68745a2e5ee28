//! rerun output sink: the twin's results as an `.rrd` a railway engineer
//! opens in the rerun viewer (rerun 0.36).
//!
//! # Timelines
//! - `wheel_pass` (sequence): wheels that have rolled over the section so far,
//!   the largest [`FieldSnapshot::wheel_pass`] seen. Scrubbing it steps
//!   through the run train by train (or wheel by wheel).
//! - `time` (timestamp): the event's log_time.
//!
//! Every event is logged on both. The SDK's automatic `log_time` / `log_tick`
//! timelines are switched off: they would record when the twin ran, not when
//! the trains did.
//!
//! # Entity layout
//! Rail and band names are taken verbatim (escaped by [`EntityPath`]).
//!
//! | entity                                  | archetype                 | logged        |
//! |-----------------------------------------|---------------------------|---------------|
//! | `section/description`                   | `TextDocument` (markdown) | static        |
//! | `section/map/rails`                     | `LineStrips2D`            | static        |
//! | `section/map/applicators`, `…/sites`    | `Points2D` with labels    | static        |
//! | `field/<rail>/<band>/mu`                | `BarChart`                | every snapshot|
//! | `field/<rail>/<band>/adhesion`          | `BarChart` (T/N)          | every snapshot|
//! | `field/<rail>/<band>/rail_mass_mg`      | `BarChart`                | every snapshot|
//! | `field/<rail>/<band>/wheel_mass_mg`     | `BarChart`                | every snapshot|
//! | `field/<rail>/<band>/mu_history`        | `Tensor` (heatmap)        | train snapshot|
//! | `sites/<site>/<rail>/<quantity>/measured`  | `Scalars` + `SeriesPoints` | measurement |
//! | `sites/<site>/<rail>/<quantity>/simulated` | `Scalars` + `SeriesLines`  | measurement |
//! | `applicator/<id>/<rail>`                | `Scalars` in g + `SeriesPoints` | pulse   |
//! | `trains`                                | `TextLog`                 | train         |
//! | `run/summary`                           | `TextDocument` (markdown) | static, at finish |
//!
//! A profile is a `BarChart` whose abscissa is the grid `d_i` in m and whose
//! bar widths are the grid spacing `C`, so the plot's x axis is distance
//! along the section (the viewer draws bin `i` over `[d_i, d_i + C)`). The
//! abscissa, widths and colour are logged once, statically, and only the
//! values at each snapshot: rerun joins the two per component, and a long run
//! does not store the grid once per wheel.
//!
//! The heatmap `mu_history` of a track is its `mu` after each of the last
//! [`RerunOptions::history_rows`] trains: row 0 is the oldest, the last row
//! the newest, one column per grid point. It is rewritten whole at every
//! train (rerun has no "append a row"), so it is stored as f16 (three
//! significant digits, plenty for a colour; the exact values are in the
//! profiles): a run stores up to `trains * K * N * 2` bytes per track before
//! compression, e.g. 0.28 GB for 300 trains, K = 256, N = 600 and 3 tracks
//! (40 MB on disk with the smooth profiles of `tests/rerun_out.rs`). Lower
//! `K` for long runs.
//!
//! # Blueprint
//! The rerun 0.36 Rust SDK can send a blueprint ([`rerun::blueprint`], marked
//! experimental): [`Blueprint::send`] logs it as a separate blueprint store
//! through the recording's sink, so it lands in the same `.rrd`, followed by
//! an activation command. It is sent at [`Sink::begin`], when the tracks and
//! sites are known, so that every view can name its entities exactly (view
//! queries only know `/**` subtree wildcards).
//!
//! # Files
//! The recording is written to `.NAME.partial-<pid>` next to the target;
//! [`Sink::finish`] flushes the stream, closes it (which writes the rrd
//! footer) and renames the file into place. A sink dropped without `finish`
//! closes the stream and deletes the temporary file.

use std::collections::{HashSet, VecDeque};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};
use rerun::blueprint::{
    BarChartView, Blueprint, BlueprintActivation, ContainerLike, Horizontal, Spatial2DView, Tabs,
    TensorView, TextDocumentView, TextLogView, TimePanel, TimeSeriesView, Vertical,
};
use rerun::components::{Color, Radius, TextLogLevel, ValueRange};
use rerun::datatypes::{TensorBuffer, TensorData};
use rerun::external::arrow::datatypes::{ArrowPrimitiveType, Float16Type};
use rerun::{EntityPath, EntityPathPart, RecordingStream, RecordingStreamBuilder, TimeCell};

use super::{
    FieldSnapshot, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink, SnapshotKind,
    TrainEvent,
};
use crate::recording::Direction;

/// Name of the sequence timeline: wheel passes so far.
pub const TIMELINE_WHEEL_PASS: &str = "wheel_pass";
/// Name of the timestamp timeline: the events' log_time.
pub const TIMELINE_TIME: &str = "time";

/// `half::f16`, named through arrow so the crate needs no `half` dependency.
type F16 = <Float16Type as ArrowPrimitiveType>::Native;

const MG_PER_KG: f64 = 1e6;
const G_PER_KG: f64 = 1e3;

/// What the rerun recording holds beyond the fixed layout.
#[derive(Debug, Clone)]
pub struct RerunOptions {
    /// The viewer groups recordings (and remembers layouts) by application id.
    pub application_id: String,
    /// Shown in the viewer's recording list; `None` for the file name.
    pub recording_name: Option<String>,
    /// `K`: trains kept in each track's `mu_history` heatmap; 0 logs none.
    pub history_rows: usize,
    /// The heatmap colour scale for mu, fixed so a colour means the same mu
    /// at every train.
    pub mu_color_range: [f64; 2],
    /// Send the default layout (see the module docs).
    pub blueprint: bool,
}

impl Default for RerunOptions {
    fn default() -> Self {
        RerunOptions {
            application_id: "tortwin".to_owned(),
            recording_name: None,
            history_rows: 256,
            mu_color_range: [0.0, 0.6],
            blueprint: true,
        }
    }
}

/// Writes the twin's results to a rerun `.rrd` (see the module docs).
pub struct RerunSink {
    /// `None` once [`Sink::finish`] has closed the stream.
    rec: Option<RecordingStream>,
    temp_path: PathBuf,
    final_path: PathBuf,
    finished: bool,
    options: RerunOptions,
    tracks: Vec<TrackState>,
    grid_len: usize,
    /// Largest wheel_pass of any track so far: the `wheel_pass` timeline.
    wheel_pass: u64,
    /// Series entities whose static style has been logged.
    styled: HashSet<EntityPath>,
}

struct TrackState {
    label: String,
    mu: EntityPath,
    adhesion: EntityPath,
    rail_mass: EntityPath,
    wheel_mass: EntityPath,
    mu_history: EntityPath,
    /// mu after each of the last K trains, oldest first.
    history: VecDeque<Vec<F16>>,
}

impl RerunSink {
    /// Opens `.NAME.partial-<pid>` next to `path` as the recording's file.
    pub fn create(path: &Path, options: RerunOptions) -> anyhow::Result<RerunSink> {
        let file_name = path
            .file_name()
            .ok_or_else(|| anyhow!("rerun output {}: not a file name", path.display()))?;
        let dir = match path.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(file_name);
        temp_name.push(format!(".partial-{}", std::process::id()));
        let temp_path = dir.join(temp_name);

        let recording_name = options
            .recording_name
            .clone()
            .unwrap_or_else(|| file_name.to_string_lossy().into_owned());
        // `enabled(true)`: the user asked for this file, so the `RERUN=off`
        // environment switch must not silently drop it.
        let application_id = rerun::ApplicationId::try_new(options.application_id.as_str())
            .map_err(|err| anyhow!("rerun output {}: {err}", path.display()))?;
        let rec = RecordingStreamBuilder::new(application_id)
            .recording_name(recording_name)
            .enabled(true)
            .save(&temp_path)
            .with_context(|| format!("creating rerun output {}", temp_path.display()))?;
        rec.set_log_time_enabled(false);
        rec.set_log_tick_enabled(false);

        Ok(RerunSink {
            rec: Some(rec),
            temp_path,
            final_path: path.to_path_buf(),
            finished: false,
            options,
            tracks: Vec::new(),
            grid_len: 0,
            wheel_pass: 0,
            styled: HashSet::new(),
        })
    }

    fn rec(&self) -> anyhow::Result<&RecordingStream> {
        self.rec.as_ref().ok_or_else(|| {
            anyhow!(
                "rerun output {}: already finished",
                self.final_path.display()
            )
        })
    }

    /// Sets both timelines for the calling thread: the next logs land there.
    fn set_time(&self, log_time_ns: u64) -> anyhow::Result<()> {
        let rec = self.rec()?;
        let wheel_pass = i64::try_from(self.wheel_pass)
            .with_context(|| format!("wheel_pass {} out of range", self.wheel_pass))?;
        let time_ns = i64::try_from(log_time_ns)
            .with_context(|| format!("log_time {log_time_ns} ns out of range"))?;
        rec.set_time(TIMELINE_WHEEL_PASS, TimeCell::from_sequence(wheel_pass));
        rec.set_time(
            TIMELINE_TIME,
            TimeCell::from_timestamp_nanos_since_epoch(time_ns),
        );
        Ok(())
    }

    /// Logs a time series style once per entity, statically.
    fn style_once(
        &mut self,
        path: &EntityPath,
        style: &dyn rerun::AsComponents,
    ) -> anyhow::Result<()> {
        if self.styled.contains(path) {
            return Ok(());
        }
        self.rec()?.log_static(path.clone(), style)?;
        self.styled.insert(path.clone());
        Ok(())
    }

    fn log_context(&self, info: &SectionInfo<'_>) -> anyhow::Result<()> {
        let rec = self.rec()?;
        let section = info.section;
        rec.log_static(
            "section/description",
            &rerun::TextDocument::from_markdown(describe(info)),
        )?;

        // A schematic plan of the section: d along x, the rails drawn apart
        // so the labels do not collide (the gap is not to scale).
        let rail_gap = (section.length_m / 25.0).max(1.0) as f32;
        let rail_y = |rail: usize| rail as f32 * rail_gap;
        let length = section.length_m as f32;
        rec.log_static(
            "section/map/rails",
            &rerun::LineStrips2D::new(
                (0..section.rails.len()).map(|r| vec![[0.0, rail_y(r)], [length, rail_y(r)]]),
            )
            .with_labels(section.rails.iter().map(String::as_str))
            .with_colors((0..section.rails.len()).map(rail_color))
            .with_radii([Radius::new_ui_points(2.0)]),
        )?;
        let mut positions = Vec::new();
        let mut labels = Vec::new();
        for applicator in &section.applicators {
            for &rail in &applicator.rails {
                positions.push([applicator.position_m as f32, rail_y(rail)]);
                labels.push(format!(
                    "{} ({:.1} m)",
                    applicator.id, applicator.position_m
                ));
            }
        }
        rec.log_static(
            "section/map/applicators",
            &rerun::Points2D::new(positions)
                .with_labels(labels)
                .with_show_labels(true)
                .with_colors([Color::from_rgb(230, 160, 30)])
                .with_radii([Radius::new_ui_points(6.0)]),
        )?;
        let mut positions = Vec::new();
        let mut labels = Vec::new();
        for site in &section.sites {
            positions.push([site.position_m as f32, -0.5 * rail_gap]);
            labels.push(format!("site {} ({:.1} m)", site.id, site.position_m));
        }
        rec.log_static(
            "section/map/sites",
            &rerun::Points2D::new(positions)
                .with_labels(labels)
                .with_show_labels(true)
                .with_colors([Color::from_rgb(90, 200, 120)])
                .with_radii([Radius::new_ui_points(6.0)]),
        )?;

        // The parts of every profile that never change: d, the bar width C
        // and the track's colour.
        let spacing_m = match info.grid_d_m {
            [first, second, ..] => (second - first) as f32,
            _ => 1.0,
        };
        let abscissa = TensorData::from(info.grid_d_m);
        for (index, track) in self.tracks.iter().enumerate() {
            let color = track_color(index);
            for path in [
                &track.mu,
                &track.adhesion,
                &track.rail_mass,
                &track.wheel_mass,
            ] {
                rec.log_static(
                    path.clone(),
                    &rerun::BarChart::update_fields()
                        .with_abscissa(abscissa.clone())
                        .with_widths(vec![spacing_m; info.grid_d_m.len()])
                        .with_color(color),
                )?;
            }
            let [low, high] = self.options.mu_color_range;
            rec.log_static(
                track.mu_history.clone(),
                &rerun::Tensor::update_fields().with_value_range(ValueRange::new(low, high)),
            )?;
        }
        Ok(())
    }

    fn blueprint(&self, info: &SectionInfo<'_>) -> Blueprint {
        fn include<'p>(paths: impl IntoIterator<Item = &'p EntityPath>) -> Vec<String> {
            paths.into_iter().map(|p| format!("+ {p}")).collect()
        }
        let profile = |name: &str, pick: fn(&TrackState) -> &EntityPath| -> ContainerLike {
            BarChartView::new(name)
                .with_contents(include(self.tracks.iter().map(pick)))
                .into()
        };
        let profiles = Vertical::new([
            profile("mu along d (m)", |t| &t.mu),
            profile("adhesion T/N along d (m)", |t| &t.adhesion),
            profile("rail product (mg) along d (m)", |t| &t.rail_mass),
            profile("wheel product (mg) along d (m)", |t| &t.wheel_mass),
        ])
        .with_name("Profiles");

        let heatmaps = Tabs::new(
            self.tracks
                .iter()
                .map(|t| {
                    TensorView::new(format!("mu history {}", t.label))
                        .with_contents(include([&t.mu_history]))
                        .into()
                })
                .collect::<Vec<ContainerLike>>(),
        )
        .with_name("mu history (train x grid point)");

        let sites = Tabs::new(
            info.section
                .sites
                .iter()
                .map(|site| {
                    let origin = entity(&["sites", &site.id]);
                    TimeSeriesView::new(format!("site {}: measured vs simulated", site.id))
                        .with_origin(origin)
                        .into()
                })
                .collect::<Vec<ContainerLike>>(),
        )
        .with_name("Sites");

        let context = Tabs::new([
            TextLogView::new("Trains")
                .with_contents(["+ /trains"])
                .into(),
            TimeSeriesView::new("Pulses (g)")
                .with_origin("applicator")
                .into(),
            TextDocumentView::new("Section")
                .with_contents(["+ /section/description"])
                .into(),
            Spatial2DView::new("Section map")
                .with_origin("section/map")
                .into(),
            TextDocumentView::new("Run summary")
                .with_contents(["+ /run/summary"])
                .into(),
        ]);

        let right = Vertical::new([heatmaps.into(), sites.into(), context.into()])
            .with_row_shares([0.4, 0.35, 0.25]);
        Blueprint::new(
            Horizontal::new([profiles.into(), right.into()]).with_column_shares([0.55, 0.45]),
        )
        .with_time_panel(TimePanel::new().with_timeline(TIMELINE_WHEEL_PASS))
    }
}

impl Sink for RerunSink {
    fn begin(&mut self, info: &SectionInfo<'_>) -> anyhow::Result<()> {
        self.grid_len = info.grid_d_m.len();
        self.tracks = info
            .tracks
            .iter()
            .map(|t| {
                let path = |leaf: &str| entity(&["field", &t.rail_name, &t.band, leaf]);
                TrackState {
                    label: format!("{}/{}", t.rail_name, t.band),
                    mu: path("mu"),
                    adhesion: path("adhesion"),
                    rail_mass: path("rail_mass_mg"),
                    wheel_mass: path("wheel_mass_mg"),
                    mu_history: path("mu_history"),
                    history: VecDeque::new(),
                }
            })
            .collect();
        self.log_context(info)
            .with_context(|| format!("rerun output {}", self.temp_path.display()))?;
        if self.options.blueprint {
            self.blueprint(info)
                .send(
                    self.rec()?,
                    BlueprintActivation {
                        make_active: true,
                        make_default: true,
                    },
                )
                .with_context(|| format!("rerun output {}: blueprint", self.temp_path.display()))?;
        }
        Ok(())
    }

    fn train(&mut self, train: &TrainEvent<'_>) -> anyhow::Result<()> {
        self.set_time(train.log_time_ns)?;
        let direction = match train.direction {
            Direction::Up => "up (d increasing)",
            Direction::Down => "down (d decreasing)",
        };
        let text = format!(
            "train {} {direction}, {:.1} m/s ({:.0} km/h), {} axles",
            train.train_id,
            train.speed_mps,
            train.speed_mps * 3.6,
            train.axles
        );
        self.rec()?
            .log(
                "trains",
                &rerun::TextLog::new(text).with_level(TextLogLevel::INFO),
            )
            .with_context(|| format!("rerun output: train {}", train.train_id))?;
        Ok(())
    }

    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> anyhow::Result<()> {
        let path = entity(&["applicator", pulse.applicator_id, pulse.rail_name]);
        let name = format!("{} {} (g)", pulse.applicator_id, pulse.rail_name);
        self.style_once(
            &path,
            &rerun::SeriesPoints::new()
                .with_names([name])
                .with_colors([rail_color(pulse.rail)]),
        )?;
        self.set_time(pulse.log_time_ns)?;
        self.rec()?
            .log(path, &rerun::Scalars::single(pulse.mass_kg * G_PER_KG))
            .with_context(|| format!("rerun output: pulse of {}", pulse.applicator_id))?;
        Ok(())
    }

    fn measurement(&mut self, m: &MeasurementOutput<'_>) -> anyhow::Result<()> {
        let quantity = m.quantity.as_str();
        let base = ["sites", m.site_id, m.rail_name, quantity];
        let measured = entity(&[&base[..], &["measured"]].concat());
        let simulated = entity(&[&base[..], &["simulated"]].concat());
        let color = rail_color(m.rail);
        self.style_once(
            &measured,
            &rerun::SeriesPoints::new()
                .with_names([format!("{} {quantity} measured", m.rail_name)])
                .with_colors([color]),
        )?;
        self.style_once(
            &simulated,
            &rerun::SeriesLines::new()
                .with_names([format!("{} {quantity} simulated", m.rail_name)])
                .with_colors([color]),
        )?;
        self.set_time(m.log_time_ns)?;
        let rec = self.rec()?;
        rec.log(measured, &rerun::Scalars::single(m.measured))
            .and_then(|()| rec.log(simulated, &rerun::Scalars::single(m.simulated)))
            .with_context(|| {
                format!(
                    "rerun output: measurement {} at site {}",
                    m.index_in_file, m.site_id
                )
            })?;
        Ok(())
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> anyhow::Result<()> {
        let grid_len = self.grid_len;
        let lengths = [
            ("d_m", f.d_m.len()),
            ("mu", f.mu.len()),
            ("adhesion", f.adhesion.len()),
            ("rail_mass_kg", f.rail_mass_kg.len()),
            ("wheel_mass_kg", f.wheel_mass_kg.len()),
        ];
        if let Some((name, len)) = lengths.iter().find(|(_, len)| *len != grid_len) {
            bail!(
                "rerun output: field snapshot of train {} on {}/{}: {name} has {len} points, the grid {grid_len}",
                f.train_id,
                f.rail_name,
                f.band
            );
        }
        if f.track >= self.tracks.len() {
            bail!(
                "rerun output: field snapshot for track {} but the section has {} tracks",
                f.track,
                self.tracks.len()
            );
        }

        self.wheel_pass = self.wheel_pass.max(f.wheel_pass);
        self.set_time(f.log_time_ns)?;
        let history_rows = self.options.history_rows;
        let Some(rec) = self.rec.as_ref() else {
            bail!(
                "rerun output {}: already finished",
                self.final_path.display()
            );
        };
        let Some(track) = self.tracks.get_mut(f.track) else {
            bail!("rerun output: no track {}", f.track);
        };
        let label = track.label.clone();
        let context = || format!("rerun output: field of train {} on {label}", f.train_id);
        let in_mg = |kg: &[f64]| kg.iter().map(|m| m * MG_PER_KG).collect::<Vec<f64>>();
        rec.log(track.mu.clone(), &rerun::BarChart::new(f.mu))
            .and_then(|()| rec.log(track.adhesion.clone(), &rerun::BarChart::new(f.adhesion)))
            .and_then(|()| {
                rec.log(
                    track.rail_mass.clone(),
                    &rerun::BarChart::new(in_mg(f.rail_mass_kg)),
                )
            })
            .and_then(|()| {
                rec.log(
                    track.wheel_mass.clone(),
                    &rerun::BarChart::new(in_mg(f.wheel_mass_kg)),
                )
            })
            .with_context(context)?;

        if f.kind == SnapshotKind::Train && history_rows > 0 {
            while track.history.len() >= history_rows {
                track.history.pop_front();
            }
            track
                .history
                .push_back(f.mu.iter().map(|&mu| F16::from_f64(mu)).collect());
            let rows = track.history.len();
            let flat: Vec<F16> = track.history.iter().flatten().copied().collect();
            let heatmap = TensorData::new(
                vec![rows as u64, grid_len as u64],
                TensorBuffer::F16(flat.into()),
            )
            .with_dim_names(["train (oldest first)", "grid point i (d = i*C)"]);
            rec.log(track.mu_history.clone(), &rerun::Tensor::new(heatmap))
                .with_context(context)?;
        }
        Ok(())
    }

    fn finish(&mut self, summary: &RunSummary) -> anyhow::Result<()> {
        self.rec()?
            .log_static(
                "run/summary",
                &rerun::TextDocument::from_markdown(summarize(summary)),
            )
            .with_context(|| format!("rerun output {}: summary", self.temp_path.display()))?;
        let rec = self.rec.take().ok_or_else(|| {
            anyhow!(
                "rerun output {}: already finished",
                self.final_path.display()
            )
        })?;
        rec.flush_blocking()
            .with_context(|| format!("flushing rerun output {}", self.temp_path.display()))?;
        // Dropping the only handle joins the SDK's threads; the file sink
        // writes the rrd footer and closes the file before this returns.
        drop(rec);
        std::fs::rename(&self.temp_path, &self.final_path).with_context(|| {
            format!(
                "renaming rerun output {} to {}",
                self.temp_path.display(),
                self.final_path.display()
            )
        })?;
        self.finished = true;
        Ok(())
    }
}

impl Drop for RerunSink {
    fn drop(&mut self) {
        // Close the stream first so no writer thread still holds the file.
        drop(self.rec.take());
        if !self.finished {
            // Nothing to report to: the run already failed (or was abandoned).
            let _ = std::fs::remove_file(&self.temp_path);
        }
    }
}

/// An entity path from verbatim names (rail names may hold any character).
fn entity(parts: &[&str]) -> EntityPath {
    EntityPath::new(parts.iter().map(|p| EntityPathPart::new(*p)).collect())
}

fn rail_color(rail: usize) -> Color {
    const RAILS: [(u8, u8, u8); 4] = [
        (66, 135, 245),
        (235, 87, 70),
        (160, 100, 220),
        (240, 200, 60),
    ];
    let (r, g, b) = RAILS[rail % RAILS.len()];
    Color::from_rgb(r, g, b)
}

fn track_color(track: usize) -> Color {
    const TRACKS: [(u8, u8, u8); 6] = [
        (66, 135, 245),
        (235, 87, 70),
        (60, 190, 120),
        (160, 100, 220),
        (240, 200, 60),
        (90, 200, 220),
    ];
    let (r, g, b) = TRACKS[track % TRACKS.len()];
    Color::from_rgb(r, g, b)
}

/// The section as a markdown page.
fn describe(info: &SectionInfo<'_>) -> String {
    let section = info.section;
    let mut md = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(md, "# Section {}\n", section.section_id);
    let _ = writeln!(md, "- length: {:.1} m", section.length_m);
    let _ = writeln!(md, "- rails: {}", section.rails.join(", "));
    match section.curve_radius_m {
        Some(radius) => {
            let _ = writeln!(md, "- curve radius: {radius:.0} m");
        }
        None => {
            let _ = writeln!(md, "- tangent track");
        }
    }
    let _ = writeln!(
        md,
        "- rail head radius: {:.3} m, nominal wheel diameter: {:.3} m",
        section.rail_head_radius_m, section.nominal_wheel_diameter_m
    );
    let spacing = match info.grid_d_m {
        [first, second, ..] => format!(", spacing C = {:.3} m", second - first),
        _ => String::new(),
    };
    let _ = writeln!(md, "- grid: {} points{spacing}", info.grid_d_m.len());
    let tracks: Vec<String> = info
        .tracks
        .iter()
        .map(|t| format!("{}/{}", t.rail_name, t.band))
        .collect();
    let _ = writeln!(md, "- tracks (rail/band): {}", tracks.join(", "));

    let _ = writeln!(md, "\n## Applicators\n");
    let _ = writeln!(
        md,
        "| id | position (m) | grid point | rails | nominal pulse (g) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|");
    for (index, applicator) in section.applicators.iter().enumerate() {
        let rails: Vec<&str> = applicator
            .rails
            .iter()
            .map(|&r| section.rails.get(r).map_or("?", String::as_str))
            .collect();
        let point = info
            .applicator_points
            .get(index)
            .map_or_else(|| "?".to_owned(), usize::to_string);
        let _ = writeln!(
            md,
            "| {} | {:.1} | {point} | {} | {:.2} |",
            applicator.id,
            applicator.position_m,
            rails.join(", "),
            applicator.nominal_pulse_kg * G_PER_KG
        );
    }

    let _ = writeln!(md, "\n## Measurement sites\n");
    let _ = writeln!(md, "| id | position (m) | grid point |");
    let _ = writeln!(md, "|---|---|---|");
    for (index, site) in section.sites.iter().enumerate() {
        let point = info
            .site_points
            .get(index)
            .map_or_else(|| "?".to_owned(), usize::to_string);
        let _ = writeln!(md, "| {} | {:.1} | {point} |", site.id, site.position_m);
    }
    md
}

/// The end-of-run figures as a markdown page.
fn summarize(summary: &RunSummary) -> String {
    let mut md = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(md, "# Run summary\n");
    let _ = writeln!(
        md,
        "- {} trains, {} wheels, {} contacts, {} pulses, {} measurements",
        summary.trains, summary.wheels, summary.contacts, summary.pulses, summary.measurements
    );
    let _ = writeln!(
        md,
        "- {} weather messages, {} messages on unknown topics",
        summary.weather_messages, summary.unknown_topic_messages
    );
    if !summary.rmse.is_empty() {
        let _ = writeln!(md, "\n## Measured vs simulated\n");
        let _ = writeln!(md, "| quantity | measurements | RMSE |");
        let _ = writeln!(md, "|---|---|---|");
        for (quantity, count, rmse) in &summary.rmse {
            let _ = writeln!(md, "| {quantity} | {count} | {rmse:.4} |");
        }
    }
    let balance = &summary.mass_balance;
    let _ = writeln!(md, "\n## Product mass balance (g)\n");
    let _ = writeln!(md, "| term | mass (g) |");
    let _ = writeln!(md, "|---|---|");
    for (term, kg) in [
        ("on rail at start", balance.on_rail_start_kg),
        ("applied", balance.applied_kg),
        ("on rail at end", balance.on_rail_end_kg),
        ("carried out on wheels", balance.carried_out_kg),
        ("consumed", balance.consumed_kg),
        ("capped at m_max", balance.capped_kg),
        ("lost to time effects", balance.effects_lost_kg),
    ] {
        let _ = writeln!(md, "| {term} | {:.3} |", kg * G_PER_KG);
    }
    let _ = writeln!(
        md,
        "\nrelative closing error: {:.2e}",
        balance.closing_error()
    );
    md
}
