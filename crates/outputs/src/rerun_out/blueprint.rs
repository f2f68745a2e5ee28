//! The default layout (see "Blueprint" in the module docs), logged by hand
//! into a blueprint store: the 0.36 Rust builder cannot set the view
//! properties it needs.

use crate::rerun_sdk;
use std::collections::{BTreeMap, BTreeSet};

use crate::rerun_sdk::blueprint::components::{
    ActiveTab, AutoLayout, AutoViews, ColumnShare, ContainerKind, Corner2D, Fps, IncludedContent,
    PanelState, PlayState, PlaybackSpeed, QueryExpression, RootContainer, RowShare, TimelineName,
    ViewClass,
};
use crate::rerun_sdk::components::Name;
use crate::rerun_sdk::datatypes::{TimeRange, VisibleTimeRange};
use crate::rerun_sdk::external::re_log_types::{LogMsg, RecordingId};
use crate::rerun_sdk::{
    ApplicationId, Archetype, AsComponents, EntityPath, RecordingStream, RecordingStreamBuilder,
    RecordingStreamError,
};
use re_sdk_types::blueprint::archetypes::{
    ContainerBlueprint, PanelBlueprint, PlotLegend, TimeAxis, TimePanelBlueprint, ViewBlueprint,
    ViewContents, ViewportBlueprint, VisibleTimeRanges, VisualBounds2D,
};
use re_sdk_types::external::uuid::Uuid;
use tortwin_recording::Quantity;

use super::curve::Bounds;
use super::entities::{entity, quantity_label, TrackEntities, TREAD_BANDS};
use super::{TIMELINE_TIME, TIMELINE_WHEEL_PASS};

/// Playback (should the user rewind and press play) covers the run in this.
const PLAYBACK_S: f64 = 60.0;

/// The section as the blueprint needs it, copied at the sink's `begin`.
pub(super) struct Layout {
    pub(super) rails: Vec<String>,
    /// What the curve views and the profile views show.
    pub(super) plan_bounds: Bounds,
    pub(super) profile_bounds: Bounds,
    /// `(id, position_m)`, in section order.
    pub(super) sites: Vec<(String, f64)>,
}

/// Per site index, per quantity (in [`super::entities::QUANTITIES`] order):
/// the quantity and the rails it was measured on.
pub(super) type Measured = BTreeMap<usize, BTreeMap<usize, (Quantity, BTreeSet<usize>)>>;

/// What the layout is made of, known when the run is over.
pub(super) struct Run<'a> {
    pub(super) application_id: &'a ApplicationId,
    pub(super) layout: &'a Layout,
    pub(super) tracks: Vec<&'a TrackEntities>,
    pub(super) measured: &'a Measured,
    /// Applicator entities that received a pulse.
    pub(super) pulsed: &'a BTreeSet<EntityPath>,
    /// `B`: trains per block of the mu history (0: none).
    pub(super) history_rows: usize,
    /// First and last log_time on `time`.
    pub(super) time_span_ns: Option<[u64; 2]>,
    /// Wheel passes of the whole run.
    pub(super) wheel_pass: u64,
    /// On a line: the watched axle and the rails its views show.
    pub(super) line_wheels: Option<&'a (usize, BTreeSet<usize>)>,
}

pub(super) fn blueprint(run: &Run<'_>) -> Result<Vec<LogMsg>, RecordingStreamError> {
    let layout = run.layout;
    let (rec, storage) = blueprint_store(run.application_id)?;
    let bp = BlueprintWriter::new(&rec);
    let whole_run = |bp: &BlueprintWriter<'_>, view: &BlueprintItem| {
        bp.whole_run(view, &[TIMELINE_TIME, TIMELINE_WHEEL_PASS])
    };

    // Left: the plan, coloured by mu or by product, above the profiles.
    let curve_mu = bp.view(
        "2D",
        "Curve: mu after the train at the cursor (blue: too much product, green: target band, yellow-red: dry)",
        ["+ /curve/mu/**"],
    )?;
    let curve_product = bp.view(
        "2D",
        "Curve: product on the rail (mg, grey: below 1e-4 mg)",
        ["+ /curve/product/**"],
    )?;
    for view in [&curve_mu, &curve_product] {
        bp.property(view, &bounds(layout.plan_bounds))?;
    }
    let curve = bp.container(
        ContainerKind::Tabs,
        "The section on its plan",
        vec![curve_mu, curve_product],
        |c| c,
    )?;
    // Which colour is which rail, for the views' titles.
    let rails = run
        .tracks
        .iter()
        .map(|t| format!("{}: {}", t.label, t.color_name))
        .collect::<Vec<_>>()
        .join(", ");
    let profile_mu = bp.view(
        "2D",
        &format!("mu ({rails}) and adhesion T/N (paler) along d [m], target band shaded"),
        ["+ /profiles/mu/**"],
    )?;
    let profile_product = bp.view(
        "2D",
        &format!(
            "Product on the rail ({rails}) and on the last wheel (paler), mg on decades, along d [m]"
        ),
        ["+ /profiles/product/**"],
    )?;
    for view in [&profile_mu, &profile_product] {
        bp.property(view, &bounds(layout.profile_bounds))?;
    }
    let mut along = vec![profile_mu, profile_product];
    // On a line the watched axles' tab opens: what the wheels carry from
    // curve to curve.
    let mut active = None;
    if let Some((axle, rails)) = run.line_wheels {
        let tab = line_wheel_views(&bp, layout, *axle, rails)?;
        active = Some(ActiveTab(tab.path.as_str().into()));
        along.push(tab);
    }
    let profiles = bp.container(
        ContainerKind::Tabs,
        "Along the section",
        along,
        |c| match active {
            Some(tab) => c.with_active_tab(tab),
            None => c,
        },
    )?;
    let left = bp.container(
        ContainerKind::Vertical,
        "Where on the section",
        vec![curve, profiles],
        |c| c.with_row_shares([0.55, 0.45].map(RowShare::from)),
    )?;

    // Right, top: a tab per site; in it a row per quantity measured
    // there and a plot per rail, like the profiles.
    let mut sites = Vec::new();
    for (&site, quantities) in run.measured {
        let Some((site_id, position_m)) = layout.sites.get(site) else {
            continue;
        };
        let mut rows = Vec::new();
        for (quantity, rails) in quantities.values() {
            let mut views = Vec::new();
            for &rail in rails {
                let Some(rail) = layout.rails.get(rail) else {
                    continue;
                };
                let view = bp.view(
                    "TimeSeries",
                    &format!("{site_id}, {rail} rail: {}", quantity_label(*quantity)),
                    [format!(
                        "+ {}/**",
                        entity(&["sites", site_id, rail, quantity.as_str()])
                    )],
                )?;
                whole_run(&bp, &view)?;
                views.push(view);
            }
            rows.push(bp.container(
                ContainerKind::Horizontal,
                &format!("site {site_id}: {}", quantity_label(*quantity)),
                views,
                |c| c,
            )?);
        }
        sites.push(bp.container(
            ContainerKind::Vertical,
            &format!("site {site_id} ({position_m:.1} m)"),
            rows,
            |c| c,
        )?);
    }

    // Right, bottom: the context.
    // The trains, and the alerts among them (WARN, ERROR).
    let trains = bp.view("TextLog", "Trains", ["+ /trains", "+ /alerts"])?;
    let pulses = bp.view(
        "TimeSeries",
        "Applicator pulses (g)",
        run.pulsed.iter().map(|p| format!("+ {p}")),
    )?;
    whole_run(&bp, &pulses)?;
    let section = bp.view("TextDocument", "Section", ["+ /section/description"])?;
    let summary = bp.view("TextDocument", "Run summary", ["+ /run/summary"])?;
    let mut context = Vec::new();
    if run.history_rows > 0 {
        for track in &run.tracks {
            context.push(bp.view(
                "2D",
                &format!(
                    "{}: mu history, a row per train (newest at the bottom), d in m across, colours as the curve's",
                    track.label
                ),
                [format!("+ {}/**", track.history)],
            )?);
        }
    }
    context.extend([trains, pulses, section, summary]);
    let context = bp.container(ContainerKind::Tabs, "Run", context, |c| c)?;

    let mut right = Vec::new();
    let mut shares = Vec::new();
    if !sites.is_empty() {
        right.push(bp.container(ContainerKind::Tabs, "Sites", sites, |c| c)?);
        shares.push(0.62);
    }
    right.push(context);
    shares.push(0.38);
    let right = bp.container(ContainerKind::Vertical, "Sites and run", right, |c| {
        c.with_row_shares(shares.iter().map(|&s| RowShare::from(s)))
    })?;
    let root = bp.container(
        ContainerKind::Horizontal,
        "tortwin",
        vec![left, right],
        |c| c.with_col_shares([0.55, 0.45].map(ColumnShare::from)),
    )?;

    bp.viewport(&root)?;
    // Follow the data: the viewer opens at the end of the run (0.36 has
    // no blueprint field for the time cursor itself).
    let span_s = run
        .time_span_ns
        .map_or(0.0, |[first, last]| (last - first) as f64 * 1e-9);
    bp.time_panel(
        &TimePanelBlueprint::new()
            .with_state(PanelState::Collapsed)
            .with_timeline(TimelineName::from(TIMELINE_TIME))
            .with_play_state(PlayState::Following)
            .with_playback_speed(PlaybackSpeed::from((span_s / PLAYBACK_S).max(1.0)))
            .with_fps(Fps::from((run.wheel_pass as f64 / PLAYBACK_S).max(30.0))),
    )?;
    Ok(storage.take())
}

/// On a line, a tab with a row per rail: the mu the watched axle and the
/// next saw along it with what `rail_mu` reads, and the axle's tread bands.
fn line_wheel_views(
    bp: &BlueprintWriter<'_>,
    layout: &Layout,
    axle: usize,
    rails: &BTreeSet<usize>,
) -> Result<BlueprintItem, RecordingStreamError> {
    let bands = TREAD_BANDS
        .iter()
        .map(|(band, _, colour)| format!("{band}: {colour}"))
        .collect::<Vec<_>>()
        .join(", ");
    let mut rows = Vec::new();
    for &rail in rails {
        let Some(name) = layout.rails.get(rail) else {
            continue;
        };
        let mu = bp.view(
            "2D",
            &format!(
                "{name} rail: mu seen by axle {axle} (solid), axle {} (paler), rail_mu on the crown (grey), along d [m]",
                axle + 1
            ),
            [
                format!("+ {}/**", entity(&["line", "mu", name])),
                "+ /profiles/mu/frame/**".to_owned(),
            ],
        )?;
        let tread = bp.view(
            "2D",
            &format!(
                "{name} rail: axle {axle}'s tread bands ({bands}), mg on decades, along d [m]"
            ),
            [
                format!("+ {}/**", entity(&["line", "tread", name])),
                "+ /profiles/product/frame/**".to_owned(),
            ],
        )?;
        for view in [&mu, &tread] {
            bp.property(view, &bounds(layout.profile_bounds))?;
        }
        rows.push(bp.container(
            ContainerKind::Horizontal,
            &format!("{name} rail"),
            vec![mu, tread],
            |c| c,
        )?);
    }
    bp.container(
        ContainerKind::Vertical,
        &format!("Along the line: axle {axle}"),
        rows,
        |c| c,
    )
}

/// A 2D view's visible range.
fn bounds([x, y]: Bounds) -> VisualBounds2D {
    VisualBounds2D::new(rerun_sdk::blueprint::components::VisualBounds2D(
        rerun_sdk::datatypes::Range2D {
            x_range: rerun_sdk::datatypes::Range1D(x),
            y_range: rerun_sdk::datatypes::Range1D(y),
        },
    ))
}

/// A blueprint store in memory for `application_id`, and the stream that
/// writes to it (on the `blueprint` timeline the viewer expects).
pub fn blueprint_store(
    application_id: &ApplicationId,
) -> Result<(RecordingStream, rerun_sdk::sink::MemorySinkStorage), RecordingStreamError> {
    let (rec, storage) = RecordingStreamBuilder::new(application_id.clone())
        .recording_id(RecordingId::random())
        .blueprint()
        .memory()?;
    rec.set_time_sequence("blueprint", 0);
    Ok((rec, storage))
}

/// Sends a finished blueprint store into `rec` (the same `.rrd`) and makes
/// it the active and default layout. `false` if the store is empty.
pub fn send_blueprint(rec: &RecordingStream, blueprint: Vec<LogMsg>) -> bool {
    let Some(blueprint_id) = blueprint.first().map(|msg| msg.store_id().clone()) else {
        return false;
    };
    rec.send_blueprint(
        blueprint,
        rerun_sdk::external::re_log_types::BlueprintActivationCommand {
            blueprint_id,
            make_active: true,
            make_default: true,
        },
    );
    true
}

/// A view or container logged to a blueprint store.
pub struct BlueprintItem {
    id: Uuid,
    path: String,
}

/// Logs containers, views and view properties as the viewer reads them.
pub struct BlueprintWriter<'r> {
    rec: &'r RecordingStream,
}

impl<'r> BlueprintWriter<'r> {
    /// Writes to a store from [`blueprint_store`].
    pub fn new(rec: &'r RecordingStream) -> Self {
        BlueprintWriter { rec }
    }

    /// A time series over the whole run on `timelines`, whatever the time
    /// cursor (the default x range of 0.36 is a window of +-30 s around the
    /// cursor once the data spans more), its legend top left.
    pub fn whole_run(
        &self,
        view: &BlueprintItem,
        timelines: &[&str],
    ) -> Result<(), RecordingStreamError> {
        let everything = timelines.iter().map(|&timeline| VisibleTimeRange {
            timeline: timeline.into(),
            range: TimeRange::EVERYTHING,
        });
        self.property(view, &VisibleTimeRanges::new(everything))?;
        self.property(
            view,
            &TimeAxis::update_fields().with_view_range(TimeRange::EVERYTHING),
        )?;
        self.property(
            view,
            &PlotLegend::update_fields().with_corner(Corner2D::LeftTop),
        )
    }

    /// The viewport's root and its panels: `root` the layout, no views
    /// added by the viewer, the blueprint and selection panels collapsed.
    pub fn viewport(&self, root: &BlueprintItem) -> Result<(), RecordingStreamError> {
        self.rec.log(
            "viewport",
            &ViewportBlueprint::new()
                .with_root_container(RootContainer::from(root.id))
                .with_auto_layout(AutoLayout::from(false))
                .with_auto_views(AutoViews::from(false)),
        )?;
        for panel in ["blueprint_panel", "selection_panel"] {
            self.rec.log(
                panel,
                &PanelBlueprint::new().with_state(PanelState::Collapsed),
            )?;
        }
        Ok(())
    }

    /// The time panel's own blueprint.
    pub fn time_panel(&self, panel: &TimePanelBlueprint) -> Result<(), RecordingStreamError> {
        self.rec.log("time_panel", panel)?;
        Ok(())
    }

    /// A view of `class` showing what the `+ /path` queries include.
    pub fn view(
        &self,
        class: &str,
        name: &str,
        queries: impl IntoIterator<Item = impl Into<String>>,
    ) -> Result<BlueprintItem, RecordingStreamError> {
        let id = Uuid::new_v4();
        let path = format!("view/{id}");
        self.rec.log(
            format!("{path}/ViewContents"),
            &ViewContents::new(queries.into_iter().map(|q| QueryExpression::from(q.into()))),
        )?;
        self.rec.log(
            path.as_str(),
            &ViewBlueprint::new(ViewClass::from(class))
                .with_display_name(Name::from(name))
                .with_space_origin("/"),
        )?;
        Ok(BlueprintItem { id, path })
    }

    /// A view property: `view/<id>/<Archetype>`, where the viewer looks.
    pub fn property<A: Archetype + AsComponents>(
        &self,
        view: &BlueprintItem,
        property: &A,
    ) -> Result<(), RecordingStreamError> {
        self.rec.log(
            format!("{}/{}", view.path, A::name().short_name()),
            property,
        )?;
        Ok(())
    }

    pub fn container(
        &self,
        kind: ContainerKind,
        name: &str,
        children: Vec<BlueprintItem>,
        extra: impl FnOnce(ContainerBlueprint) -> ContainerBlueprint,
    ) -> Result<BlueprintItem, RecordingStreamError> {
        let id = Uuid::new_v4();
        let path = format!("container/{id}");
        let contents: Vec<IncludedContent> = children
            .iter()
            .map(|child| IncludedContent::from(child.path.as_str()))
            .collect();
        self.rec.log(
            path.as_str(),
            &extra(
                ContainerBlueprint::new(kind)
                    .with_display_name(Name::from(name))
                    .with_contents(contents),
            ),
        )?;
        Ok(BlueprintItem { id, path })
    }
}
