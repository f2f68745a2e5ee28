//! Foxglove's well-known message types, JSON-encoded, for the MCAP output:
//! the coloured track as a `foxglove.SceneUpdate` and trains, pulses and
//! warnings as `foxglove.Log`, so that Foxglove's 3D and Log panels show
//! them without setup.
//!
//! The schemas are Foxglove's own JSON Schemas, copied from the
//! `@foxglove/schemas` npm package (see `schemas/foxglove/README.md`) and
//! written into the file as they are; the types below serialize to exactly
//! the fields those schemas require, and the tests validate every message
//! against the npm package's schemas.

use serde::Serialize;
use serde_json::value::RawValue;

use crate::geometry::Plan;
use crate::scale::{mu_class, mu_class_color, MU_CLASSES};

pub(crate) const SCENE_UPDATE_SCHEMA: &str = include_str!("../schemas/foxglove/SceneUpdate.json");
pub(crate) const LOG_SCHEMA: &str = include_str!("../schemas/foxglove/Log.json");

/// The frame every scene entity is drawn in: the section's plan
/// ([`crate::geometry`]), x and y in m, z up.
pub const FRAME_ID: &str = "section";

/// `foxglove.LogLevel`.
#[derive(Debug, Clone, Copy)]
pub(crate) enum LogLevel {
    Info = 2,
    Warning = 3,
    Error = 4,
}

#[derive(Serialize)]
pub(crate) struct Time {
    sec: u64,
    nsec: u32,
}

impl Time {
    pub(crate) fn from_ns(ns: u64) -> Time {
        Time {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `foxglove.Log`.
#[derive(Serialize)]
pub(crate) struct Log<'a> {
    timestamp: Time,
    level: u8,
    message: &'a str,
    name: &'a str,
    file: &'static str,
    line: u32,
}

impl<'a> Log<'a> {
    pub(crate) fn new(log_time_ns: u64, level: LogLevel, name: &'a str, message: &'a str) -> Self {
        Log {
            timestamp: Time::from_ns(log_time_ns),
            level: level as u8,
            message,
            name,
            file: "",
            line: 0,
        }
    }
}

#[derive(Serialize, Clone, Copy)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Serialize, Clone, Copy)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Serialize, Clone, Copy)]
struct Pose {
    position: Vector3,
    orientation: Quaternion,
}

const IDENTITY: Pose = Pose {
    position: Vector3 {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    },
    orientation: Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    },
};

/// `foxglove.Color`, each channel 0 to 1.
#[derive(Serialize, Clone, Copy)]
struct Color {
    r: f64,
    g: f64,
    b: f64,
    a: f64,
}

impl Color {
    fn rgb([r, g, b]: [u8; 3]) -> Color {
        // Four decimals: the 256 levels of a channel stay apart, and the
        // same colour is the same text in every message.
        let channel = |c: u8| (f64::from(c) / 255.0 * 1e4).round() / 1e4;
        Color {
            r: channel(r),
            g: channel(g),
            b: channel(b),
            a: 1.0,
        }
    }
}

#[derive(Serialize)]
struct KeyValuePair {
    key: &'static str,
    value: String,
}

/// `foxglove.LinePrimitive`.
#[derive(Serialize)]
struct LinePrimitive<'a> {
    #[serde(rename = "type")]
    kind: u8,
    pose: Pose,
    thickness: f64,
    scale_invariant: bool,
    points: Kept<'a>,
    color: Color,
    colors: Kept<'a>,
    indices: [u32; 0],
}

/// A JSON array of a track's kept points ([`TrackScene::kept`]): each
/// item's text, serialized once, written as it is (no parse of the whole
/// array every train, which a `RawValue` made of it would take).
struct Kept<'a> {
    scene: &'a TrackScene,
    track: usize,
    item: fn(&'a TrackScene, usize, usize) -> &'a RawValue,
}

impl Serialize for Kept<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq as _;
        let mut seq = serializer.serialize_seq(None)?;
        for i in self.scene.kept(self.track) {
            seq.serialize_element((self.item)(self.scene, self.track, i))?;
        }
        seq.end()
    }
}

/// `foxglove.TextPrimitive`.
#[derive(Serialize)]
struct TextPrimitive {
    pose: Pose,
    billboard: bool,
    font_size: f64,
    scale_invariant: bool,
    color: Color,
    text: String,
}

/// `foxglove.SceneEntity`.
#[derive(Serialize)]
struct SceneEntity<'a> {
    timestamp: Time,
    frame_id: &'static str,
    id: String,
    lifetime: Time,
    frame_locked: bool,
    metadata: Vec<KeyValuePair>,
    arrows: [u8; 0],
    cubes: [u8; 0],
    spheres: [u8; 0],
    cylinders: [u8; 0],
    lines: Vec<LinePrimitive<'a>>,
    triangles: [u8; 0],
    texts: Vec<TextPrimitive>,
    models: [u8; 0],
}

/// `foxglove.SceneUpdate`.
#[derive(Serialize)]
pub(crate) struct SceneUpdate<'a> {
    deletions: [u8; 0],
    entities: Vec<SceneEntity<'a>>,
}

/// Metres rounded to the millimetre (the plan is drawn, not surveyed).
fn mm(x: f64) -> f64 {
    (x * 1e3).round() / 1e3
}

/// What the scene needs of the section, computed once at `begin`.
pub(crate) struct TrackScene {
    /// Per track, the plan position of each grid point as JSON text,
    /// serialized once.
    points: Vec<Vec<Box<RawValue>>>,
    /// The longest step between two points of a line: where the class does
    /// not change, a line of this step strays from the arc by at most a
    /// fortieth of the drawn gauge.
    max_step: usize,
    /// Per mu class, its colour as JSON.
    palette: Vec<Box<RawValue>>,
    /// Per track, "track/<rail>/<band>".
    ids: Vec<String>,
    /// Per track, the mu class of each grid point at the last snapshot.
    classes: Vec<Vec<u16>>,
    /// Per track, the train and wheel pass of the last snapshot.
    last: Vec<Option<(String, u64)>>,
    /// Labels at the sites and applicators (and a line's segments), and
    /// the colour key, each with its font size in m.
    labels: Vec<(Vector3, String, f64)>,
    thickness_m: f64,
}

/// A site or applicator to label: `(position_m, text)`.
pub(crate) type Label = (f64, String);

impl TrackScene {
    pub(crate) fn new(
        plan: &Plan,
        grid_d_m: &[f64],
        tracks: &[(String, String)],
        labels: &[Label],
        segments: &[Label],
    ) -> TrackScene {
        let points = plan
            .track_offsets_m
            .iter()
            .map(|&offset| {
                let points: Vec<Vector3> = grid_d_m
                    .iter()
                    .map(|&d| {
                        let [x, y] = plan.xy(d, offset);
                        Vector3 {
                            x: mm(x),
                            y: mm(y),
                            z: 0.0,
                        }
                    })
                    .collect();
                points.iter().map(raw_json).collect()
            })
            .collect();
        // A chord of length s strays s²/(8R) from its arc.
        let spacing = match grid_d_m {
            [a, b, ..] => (b - a).max(1e-9),
            _ => 1.0,
        };
        let max_step = match plan.min_radius_m() {
            Some(radius) => ((8.0 * radius.abs() * plan.gauge_m / 40.0).sqrt() / spacing).floor(),
            None => f64::INFINITY,
        }
        .clamp(1.0, 1e9) as usize;
        let palette = (0..=MU_CLASSES)
            .map(|class| raw_json(&Color::rgb(mu_class_color(class))))
            .collect();
        let ids = tracks
            .iter()
            .map(|(rail, band)| format!("track/{rail}/{band}"))
            .collect();
        // Labels outside the leftmost rail (a line's segment names outside
        // the rightmost), the colour key centred below the plan, no wider
        // than it: a view that frames the plan frames the key
        // (scripts/foxglove_layout.py frames the labels too).
        let font_size_m = plan.gauge_m / 2.0;
        let outside = plan.rail_offsets_m.iter().copied().fold(0.0, f64::max) + plan.gauge_m;
        let at = |[x, y]: [f64; 2]| Vector3 {
            x: mm(x),
            y: mm(y),
            z: 0.0,
        };
        let mut placed: Vec<(Vector3, String, f64)> = labels
            .iter()
            .map(|(d, text)| (at(plan.xy(*d, outside)), text.clone(), font_size_m))
            .collect();
        placed.extend(
            segments
                .iter()
                .map(|(d, text)| (at(plan.xy(*d, -outside)), text.clone(), font_size_m)),
        );
        let (mut x, mut y) = ([f64::INFINITY, f64::NEG_INFINITY], f64::INFINITY);
        for &offset in &plan.rail_offsets_m {
            for &d in grid_d_m {
                let [px, py] = plan.xy(d, offset);
                x = [x[0].min(px), x[1].max(px)];
                y = y.min(py);
            }
        }
        let key = "mu: blue < 0.30 too much product | green 0.30-0.40 target band | yellow-red > 0.40 dry";
        // A character is about 0.6 of the font size wide.
        let width_m = (x[1] - x[0]).max(plan.gauge_m);
        let key_font_m = font_size_m.min(width_m / (0.6 * key.len() as f64));
        placed.push((
            at([(x[0] + x[1]) / 2.0, y - 2.0 * plan.gauge_m]),
            key.to_owned(),
            key_font_m,
        ));
        TrackScene {
            points,
            max_step,
            palette,
            ids,
            classes: vec![Vec::new(); tracks.len()],
            last: vec![None; tracks.len()],
            labels: placed,
            thickness_m: plan.gauge_m / 6.0,
        }
    }

    /// Records a track's snapshot.
    pub(crate) fn set(&mut self, track: usize, mu: &[f64], train_id: &str, wheel_pass: u64) {
        if let Some(classes) = self.classes.get_mut(track) {
            classes.clear();
            classes.extend(mu.iter().map(|&m| mu_class(m)));
            self.last[track] = Some((train_id.to_owned(), wheel_pass));
        }
    }

    /// The scene as it stands: every track that has had a snapshot, and the
    /// labels.
    pub(crate) fn update(&self, log_time_ns: u64) -> SceneUpdate<'_> {
        let mut entities = Vec::with_capacity(self.ids.len() + 1);
        for (track, id) in self.ids.iter().enumerate() {
            let Some((train_id, wheel_pass)) = &self.last[track] else {
                continue;
            };
            entities.push(SceneEntity {
                metadata: vec![
                    KeyValuePair {
                        key: "train_id",
                        value: train_id.clone(),
                    },
                    KeyValuePair {
                        key: "wheel_pass",
                        value: wheel_pass.to_string(),
                    },
                ],
                lines: vec![LinePrimitive {
                    kind: 0,
                    pose: IDENTITY,
                    thickness: self.thickness_m,
                    scale_invariant: false,
                    points: Kept {
                        scene: self,
                        track,
                        item: |scene, track, i| &scene.points[track][i],
                    },
                    color: Color::rgb([128, 128, 128]),
                    colors: Kept {
                        scene: self,
                        track,
                        item: |scene, track, i| {
                            &scene.palette[usize::from(scene.classes[track][i].min(MU_CLASSES))]
                        },
                    },
                    indices: [],
                }],
                texts: Vec::new(),
                ..entity(log_time_ns, id.clone())
            });
        }
        entities.push(SceneEntity {
            texts: self
                .labels
                .iter()
                .map(|(at, text, font_size)| TextPrimitive {
                    pose: Pose {
                        position: *at,
                        orientation: IDENTITY.orientation,
                    },
                    billboard: true,
                    font_size: *font_size,
                    scale_invariant: false,
                    color: Color::rgb([30, 30, 30]),
                    text: text.clone(),
                })
                .collect(),
            ..entity(log_time_ns, "labels".to_owned())
        });
        SceneUpdate {
            deletions: [],
            entities,
        }
    }
}

impl TrackScene {
    /// The points a track's line is drawn through: both ends, both sides of
    /// every change of class, and at least every `max_step` grid points.
    /// Between two of them the class does not change (or changes once, over
    /// one grid step): the line is coloured as per grid point with a
    /// fraction of the points.
    fn kept(&self, track: usize) -> impl Iterator<Item = usize> + '_ {
        let classes = &self.classes[track];
        let n = classes.len();
        let mut last = 0;
        (0..n).filter(move |&i| {
            let keep = i == 0
                || i + 1 == n
                || classes[i] != classes[i - 1]
                || classes[i] != classes[i + 1]
                || i - last >= self.max_step;
            if keep {
                last = i;
            }
            keep
        })
    }
}

/// `value` as JSON text kept as it is (serialized, not parsed again;
/// `null` if it cannot be, which a point or a colour of numbers never is).
fn raw_json(value: &impl Serialize) -> Box<RawValue> {
    serde_json::value::to_raw_value(value).unwrap_or_default()
}

/// An empty entity in the section frame that stays until replaced.
fn entity<'a>(log_time_ns: u64, id: String) -> SceneEntity<'a> {
    SceneEntity {
        timestamp: Time::from_ns(log_time_ns),
        frame_id: FRAME_ID,
        id,
        lifetime: Time { sec: 0, nsec: 0 },
        frame_locked: false,
        metadata: Vec::new(),
        arrows: [],
        cubes: [],
        spheres: [],
        cylinders: [],
        lines: Vec::new(),
        triangles: [],
        texts: Vec::new(),
        models: [],
    }
}

/// "high rail after train P-00012: mu below the target band (< 0.30) over
/// 10-95 m, lowest 0.21 at 12 m", or `None` when no point is below `low`.
pub(crate) fn below_band_warning(
    rail_label: &str,
    train_id: &str,
    d_m: &[f64],
    mu: &[f64],
    low: f64,
) -> Option<String> {
    let below: Vec<usize> = (0..mu.len().min(d_m.len()))
        .filter(|&i| mu[i] < low)
        .collect();
    let (&first, &last) = (below.first()?, below.last()?);
    let lowest = below
        .iter()
        .copied()
        .min_by(|&a, &b| mu[a].total_cmp(&mu[b]))
        .unwrap_or(first);
    let length_m = below.len() as f64
        * match d_m {
            [a, b, ..] => b - a,
            _ => 0.0,
        };
    Some(format!(
        "{rail_label} after train {train_id}: mu below the target band (< {low:.2}) on {length_m:.0} m between {:.0} and {:.0} m, lowest {:.3} at {:.0} m",
        d_m[first], d_m[last], mu[lowest], d_m[lowest]
    ))
}
