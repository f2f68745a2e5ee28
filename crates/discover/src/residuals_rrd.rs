//! `residuals.rrd`: the finding as a rerun recording that opens on it.
//!
//! | entity | what |
//! |---|---|
//! | `finding` | the verdict, RMSE before and after, each effect found with its sentence (markdown) |
//! | `report` | report.md |
//! | `versus/<site>/<rail>/before`, `…/after` | the residual (measured - simulated) of each measurement against the covariate it followed most closely at the start, as points on a plot of its own (x: the covariate across, y: the residual up), before (orange) and after (blue) |
//! | `versus/<site>/<rail>/mean_before`, `…/mean_after` | the residual's mean per bin of the covariate, as lines |
//! | `versus/<site>/<rail>/frame` | zero line, tick labels of the covariate and the residual |
//! | `residuals/<site>/<rail>/<quantity>` | the residual before and after of every measurement, on the `time` timeline |
//!
//! The layout (sent in the file): left, the finding above a tab per site
//! and rail with the residual against the covariate; right, a tab per site,
//! rail and quantity with the residuals over the whole recording, and the
//! report. The time panel is on `time`, paused (the 0.36 viewer then opens
//! at the start of the data: a blueprint cannot place the cursor itself).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use tortwin_outputs::rerun_sdk;

use tortwin_outputs::rerun_sdk::blueprint::components::TimelineName;
use tortwin_outputs::rerun_sdk::blueprint::components::{
    ColumnShare, ContainerKind, PanelState, PlayState, RowShare,
};
use tortwin_outputs::rerun_sdk::components::{Color, Radius};
use tortwin_outputs::rerun_sdk::re_sdk_types::blueprint::archetypes::TimePanelBlueprint;
use tortwin_outputs::rerun_sdk::{
    EntityPath, EntityPathPart, RecordingStream, RecordingStreamBuilder, TimeColumn,
};

use super::data::{Dataset, Values};
use super::diagnose;
use super::Discovery;
use tortwin_outputs::files::PartialFile;
use tortwin_outputs::rerun_out::{blueprint_store, send_blueprint, BlueprintWriter, RerunError};
use tortwin_study::Result;

const BEFORE: [u8; 3] = [255, 127, 14];
const AFTER: [u8; 3] = [31, 119, 180];
const CALIBRATED: [u8; 3] = [44, 160, 44];
/// Width of a residual-against-covariate plot, and the height of the
/// largest residual above (and below) its zero line, in scene units.
const PLOT_WIDTH: f64 = 100.0;
const PLOT_HALF_HEIGHT: f64 = 40.0;
/// Points per plot at most (every k-th beyond).
const MAX_POINTS: usize = 4000;

fn entity(parts: &[&str]) -> EntityPath {
    EntityPath::new(parts.iter().map(|p| EntityPathPart::new(*p)).collect())
}

fn color([r, g, b]: [u8; 3]) -> Color {
    Color::from_rgb(r, g, b)
}

/// Writes the recording (under a temporary name, renamed when complete).
pub(super) fn write_rrd(path: &Path, data: &Dataset, d: &Discovery, md: &str) -> Result<()> {
    let sdk = |what: &str| {
        let what = what.to_owned();
        move |source: rerun_sdk::RecordingStreamError| RerunError::Sdk {
            path: path.to_path_buf(),
            what,
            source: Box::new(source),
        }
    };
    let mut file = PartialFile::beside(path)?;
    let application_id = rerun_sdk::ApplicationId::try_new("tortwin").map_err(|source| {
        RerunError::ApplicationId {
            path: path.to_path_buf(),
            id: "tortwin".to_owned(),
            source,
        }
    })?;
    // Declared after `file`: dropped first on an error, the stream closes
    // the temporary file before `file` deletes it.
    let builder = RecordingStreamBuilder::new(application_id.clone())
        .recording_name("discover residuals")
        .enabled(true);
    let rec = file
        .open_with(|temp| builder.save(temp))
        .map_err(sdk("starting the recording"))?;
    rec.set_log_time_enabled(false);
    rec.set_log_tick_enabled(false);
    if let Some(provenance) = &d.provenance {
        tortwin_outputs::rerun_out::send_provenance(&rec, provenance)
            .map_err(sdk("writing the provenance"))?;
    }
    rec.log_static(
        "finding",
        &rerun_sdk::TextDocument::from_markdown(finding(d)),
    )
    .map_err(sdk("the finding"))?;
    rec.log_static("report", &rerun_sdk::TextDocument::from_markdown(md))
        .map_err(sdk("the report"))?;

    let series = log_series(&rec, data, d).map_err(sdk("the residuals over time"))?;
    let versus = log_versus(&rec, data, d).map_err(sdk("the residual against its covariate"))?;

    let (bp_rec, storage) = blueprint_store(&application_id).map_err(sdk("the layout"))?;
    layout(&bp_rec, &series, &versus).map_err(sdk("the layout"))?;
    drop(bp_rec);
    send_blueprint(&rec, storage.take());

    rec.flush_blocking().map_err(|source| RerunError::Flush {
        path: path.to_path_buf(),
        source,
    })?;
    // Dropping the only handle joins the SDK's threads: the file is closed
    // before it is renamed.
    drop(rec);
    file.commit()?;
    Ok(())
}

/// The finding as a short page: verdict, RMSE, the effects' sentences.
fn finding(d: &Discovery) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# What the model missed\n\n{}\n", d.verdict);
    let noise = d
        .noise_estimate
        .map_or_else(|| "unknown".to_owned(), |s| format!("{s:.4}"));
    let _ = writeln!(
        md,
        "RMSE {:.4} before, {:.4} after; the measurements' noise is about {noise}.\n",
        d.rmse_before, d.rmse_after
    );
    if let Some(c) = &d.calibration {
        let _ = writeln!(md, "## Site constants\n\n{}\n", c.summary);
        for k in d.site_constants.iter().filter(|k| c.moved.contains(&k.key)) {
            let _ = writeln!(
                md,
                "- `{}` = {}: {}",
                k.key,
                super::fmt_param(k.value),
                k.description
            );
        }
        let _ = writeln!(md);
    }
    if d.effects_found.is_empty() {
        let _ = writeln!(
            md,
            "Nothing added: no effect explains the residual better than noise.\n"
        );
    } else {
        let _ = writeln!(md, "## Added to the model\n");
        for e in &d.effects_found {
            let _ = write!(md, "- `{}`", e.text());
            if let Some(description) = &e.description {
                let _ = write!(md, ": {description}");
            }
            let _ = writeln!(md);
        }
        let _ = writeln!(md);
    }
    if let Some(top) = d.covariates_before.first() {
        let _ = writeln!(
            md,
            "The plots below: the residual (measured - simulated) of each measurement against \
             **{}** ({}), the covariate it followed most closely at the start (eta² {:.3}), \
             before (orange) and after (blue), with the mean per bin as lines. Right: the \
             residuals over the whole recording.",
            top.name, top.description, top.eta2
        );
    }
    md
}

/// The residuals over time per site, rail and quantity; the entities, with
/// their titles, in order.
fn log_series(
    rec: &RecordingStream,
    data: &Dataset,
    d: &Discovery,
) -> rerun_sdk::RecordingStreamResult<Vec<(EntityPath, String)>> {
    let mut rows: BTreeMap<(usize, usize, &str), Vec<usize>> = BTreeMap::new();
    for (i, row) in data.rows.iter().enumerate() {
        rows.entry((row.site, row.rail, row.quantity.as_str()))
            .or_default()
            .push(i);
    }
    let mut entities = Vec::new();
    for ((site, rail, quantity), indices) in rows {
        let (site, rail) = (data.site_name(site), data.rail_name(rail));
        let path = entity(&["residuals", site, rail, quantity]);
        // With the site's constants calibrated: before, after the
        // calibration, after (the effects found added).
        let calibrated = d.calibration_start.is_some();
        let (names, colors): (Vec<&str>, Vec<Color>) = if calibrated {
            (
                vec!["before", "constants calibrated", "after"],
                vec![color(BEFORE), color(CALIBRATED), color(AFTER)],
            )
        } else {
            (vec!["before", "after"], vec![color(BEFORE), color(AFTER)])
        };
        let per_row = names.len();
        rec.log_static(
            path.clone(),
            &rerun_sdk::SeriesPoints::new()
                .with_names(names)
                .with_colors(colors)
                .with_marker_sizes(vec![2.0; per_row]),
        )?;
        let times: Vec<i64> = indices
            .iter()
            .map(|&i| i64::try_from(data.rows[i].log_time_ns).unwrap_or(i64::MAX))
            .collect();
        let values: Vec<f64> = indices
            .iter()
            .flat_map(|&i| {
                let middle = calibrated.then(|| d.residual_calibrated[i]);
                std::iter::once(d.residual_before[i])
                    .chain(middle)
                    .chain(std::iter::once(d.residual_after[i]))
            })
            .collect();
        let n = times.len();
        rec.send_columns(
            path.clone(),
            [TimeColumn::new_timestamp_nanos_since_epoch("time", times)],
            rerun_sdk::Scalars::new(values).columns(std::iter::repeat_n(per_row, n))?,
        )?;
        entities.push((
            path,
            format!("{site}, {rail} rail, {quantity}: residual over time"),
        ));
    }
    Ok(entities)
}

/// The residual against the strongest covariate per site and rail; the
/// plots' roots, with their titles.
fn log_versus(
    rec: &RecordingStream,
    data: &Dataset,
    d: &Discovery,
) -> rerun_sdk::RecordingStreamResult<Vec<(EntityPath, String)>> {
    let Some(top) = d.covariates_before.first() else {
        return Ok(Vec::new());
    };
    let Some(cov) = data.covariate(&top.name) else {
        return Ok(Vec::new());
    };
    let x: Vec<f64> = match &cov.values {
        Values::Continuous(v) => v.clone(),
        Values::Categorical { codes, .. } => codes.iter().map(|&c| f64::from(c)).collect(),
    };
    let finite: Vec<usize> = (0..x.len()).filter(|&i| x[i].is_finite()).collect();
    let (Some(low), Some(high)) = (
        finite.iter().map(|&i| x[i]).min_by(f64::total_cmp),
        finite.iter().map(|&i| x[i]).max_by(f64::total_cmp),
    ) else {
        return Ok(Vec::new());
    };
    let span = (high - low).max(f64::MIN_POSITIVE);
    let largest = finite
        .iter()
        .map(|&i| d.residual_before[i].abs().max(d.residual_after[i].abs()))
        .fold(1e-9, f64::max);
    let px = |v: f64| ((v - low) / span * PLOT_WIDTH) as f32;
    let py = |r: f64| (-r / largest * PLOT_HALF_HEIGHT) as f32;
    let bins = diagnose::bins(cov);
    let nbins = bins.labels.len();

    let mut groups: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
    for &i in &finite {
        let row = &data.rows[i];
        groups.entry((row.site, row.rail)).or_default().push(i);
    }
    let mut plots = Vec::new();
    for ((site, rail), indices) in groups {
        let (site, rail) = (data.site_name(site), data.rail_name(rail));
        let root = entity(&["versus", site, rail]);
        let stride = indices.len().div_ceil(MAX_POINTS).max(1);
        for (which, residual, rgb) in [
            ("before", &d.residual_before, BEFORE),
            ("after", &d.residual_after, AFTER),
        ] {
            let points: Vec<[f32; 2]> = indices
                .iter()
                .step_by(stride)
                .map(|&i| [px(x[i]), py(residual[i])])
                .collect();
            rec.log_static(
                root.join(&EntityPath::from_single_string(which)),
                &rerun_sdk::Points2D::new(points)
                    .with_colors([Color::from_unmultiplied_rgba(rgb[0], rgb[1], rgb[2], 110)])
                    .with_radii([Radius::new_ui_points(1.5)]),
            )?;
            // Mean per bin of this site and rail.
            let mut sums = vec![(0.0, 0.0, 0usize); nbins];
            for &i in &indices {
                let s = &mut sums[bins.index[i]];
                s.0 += x[i];
                s.1 += residual[i];
                s.2 += 1;
            }
            let mut means: Vec<[f32; 2]> = sums
                .iter()
                .filter(|s| s.2 > 0)
                .map(|s| [px(s.0 / s.2 as f64), py(s.1 / s.2 as f64)])
                .collect();
            means.sort_by(|a, b| a[0].total_cmp(&b[0]));
            rec.log_static(
                root.join(&EntityPath::from_single_string(format!("mean_{which}"))),
                &rerun_sdk::LineStrips2D::new([means])
                    .with_colors([color(rgb)])
                    .with_radii([Radius::new_ui_points(2.5)])
                    .with_labels([format!("mean per bin, {which}")]),
            )?;
        }
        log_frame(rec, &root, low, high, largest, &top.name)?;
        plots.push((
            root,
            format!("{site}, {rail} rail: residual against {}", top.name),
        ));
    }
    Ok(plots)
}

/// A plot's zero line and tick labels (the covariate's values across, the
/// residual's up).
fn log_frame(
    rec: &RecordingStream,
    root: &EntityPath,
    low: f64,
    high: f64,
    largest: f64,
    name: &str,
) -> rerun_sdk::RecordingStreamResult<()> {
    let grey = Color::from_rgb(130, 130, 130);
    let (w, h) = (PLOT_WIDTH as f32, PLOT_HALF_HEIGHT as f32);
    rec.log_static(
        root.join(&EntityPath::from_single_string("frame/lines")),
        &rerun_sdk::LineStrips2D::new([vec![[0.0, 0.0], [w, 0.0]], vec![[0.0, -h], [0.0, h]]])
            .with_colors([grey])
            .with_radii([Radius::new_ui_points(0.75)]),
    )?;
    let mut positions = Vec::new();
    let mut labels = Vec::new();
    for k in 0..=4 {
        let v = low + (high - low) * f64::from(k) / 4.0;
        positions.push([w * k as f32 / 4.0, h + 4.0]);
        labels.push(short(v));
    }
    positions.push([w / 2.0, h + 10.0]);
    labels.push(name.to_owned());
    for k in [-2, -1, 1, 2] {
        let r = largest * f64::from(k) / 2.0;
        positions.push([-4.0, -h * k as f32 / 2.0]);
        labels.push(format!("{r:+.3}"));
    }
    positions.push([-4.0, -h - 6.0]);
    labels.push("residual".to_owned());
    rec.log_static(
        root.join(&EntityPath::from_single_string("frame/labels")),
        &rerun_sdk::Points2D::new(positions)
            .with_labels(labels)
            .with_show_labels(true)
            .with_colors([grey])
            .with_radii([Radius::new_ui_points(0.5)]),
    )
}

/// Three significant digits.
fn short(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-2) {
        format!("{v:.2e}")
    } else {
        let digits = (2 - v.abs().max(1e-300).log10().floor() as i32).clamp(0, 3) as usize;
        format!("{v:.digits$}")
    }
}

/// The layout: the finding and the residual against its covariate on the
/// left, the residuals over time and the report on the right.
fn layout(
    rec: &RecordingStream,
    series: &[(EntityPath, String)],
    versus: &[(EntityPath, String)],
) -> rerun_sdk::RecordingStreamResult<()> {
    let bp = BlueprintWriter::new(rec);
    let finding = bp.view("TextDocument", "The finding", ["+ /finding"])?;
    let mut left = vec![finding];
    let mut shares = vec![0.35];
    if !versus.is_empty() {
        let mut tabs = Vec::new();
        for (root, title) in versus {
            tabs.push(bp.view("2D", title, [format!("+ {root}/**")])?);
        }
        left.push(bp.container(ContainerKind::Tabs, "Against the covariate", tabs, |c| c)?);
        shares.push(0.65);
    }
    let left = bp.container(ContainerKind::Vertical, "The finding", left, |c| {
        c.with_row_shares(shares.iter().map(|&s| RowShare::from(s)))
    })?;
    let mut right = Vec::new();
    for (path, title) in series {
        let view = bp.view("TimeSeries", title, [format!("+ {path}")])?;
        bp.whole_run(&view, &["time"])?;
        right.push(view);
    }
    right.push(bp.view("TextDocument", "Report", ["+ /report"])?);
    let right = bp.container(ContainerKind::Tabs, "Over time", right, |c| c)?;
    let root = bp.container(
        ContainerKind::Horizontal,
        "discover",
        vec![left, right],
        |c| c.with_col_shares([0.5, 0.5].map(ColumnShare::from)),
    )?;
    bp.viewport(&root)?;
    bp.time_panel(
        &TimePanelBlueprint::new()
            .with_state(PanelState::Collapsed)
            .with_timeline(TimelineName::from("time"))
            .with_play_state(PlayState::Paused),
    )
}
