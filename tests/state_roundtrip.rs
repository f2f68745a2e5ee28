//! State out and in (interfaces.md): a recording cut in two at a moment when
//! no train is in the section, the second part replayed from the first
//! part's state, gives the same outputs as the whole, bit for bit; and a
//! state from another section or format version is refused clearly.

use std::path::{Path, PathBuf};

use tortwin_jobs::replay::{replay, ReplayArgs};

mod common;
use common::recording::copy_recording;
use common::Recorder;

fn reference(name: &str) -> PathBuf {
    common::reference_recording(name)
}

fn args(recording: &Path) -> ReplayArgs {
    ReplayArgs::new(recording)
}

/// One field snapshot as bits: log_time, train, track, wheel_pass, mu,
/// adhesion, rail mass, wheel mass.
type FieldBits = (
    u64,
    String,
    String,
    u64,
    Vec<u64>,
    Vec<u64>,
    Vec<u64>,
    Vec<u64>,
);

/// Everything a replay publishes, as bits.
#[derive(Default, Debug, PartialEq)]
struct Outputs {
    measurements: Vec<(u64, String, String, String, u64, u64)>,
    fields: Vec<FieldBits>,
    trains: Vec<(u64, u64)>,
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

impl Outputs {
    /// What `replay` published, as bits (without the message indices, which
    /// differ between a recording and its parts).
    fn of(r: &Recorder) -> Self {
        Self {
            trains: r.trains.iter().map(|t| (t.log_time_ns, t.end_ns)).collect(),
            measurements: r
                .measurements
                .iter()
                .map(|m| {
                    (
                        m.log_time_ns,
                        m.site.clone(),
                        m.rail.clone(),
                        m.quantity.as_str().into(),
                        m.measured.to_bits(),
                        m.simulated.to_bits(),
                    )
                })
                .collect(),
            fields: r
                .fields
                .iter()
                .map(|f| {
                    (
                        f.log_time_ns,
                        f.train_id.clone(),
                        f.track.clone(),
                        f.wheel_pass,
                        bits(&f.mu),
                        bits(&f.adhesion),
                        bits(&f.rail_mass_kg),
                        bits(&f.wheel_mass_kg),
                    )
                })
                .collect(),
        }
    }
}

/// Replays with `a`, recording everything it publishes.
fn replay_outputs(a: &ReplayArgs) -> Outputs {
    let mut r = Recorder::with_fields();
    replay(a, None, &mut [&mut r], &tortwin_study::Silent).unwrap();
    Outputs::of(&r)
}

/// Copies the messages of `src` for which `keep(topic, log_time)` holds into
/// a new recording at `dst`, in file order; `/section` is always kept, at
/// `section_log_time` if given.
fn rewrite(
    src: &Path,
    dst: &Path,
    section_log_time: Option<u64>,
    keep: impl Fn(&str, u64) -> bool,
) {
    copy_recording(src, dst, |m| {
        if m.topic != "/section" {
            return keep(&m.topic, m.log_time);
        }
        if let Some(t) = section_log_time {
            m.log_time = t;
        }
        true
    });
}

#[test]
fn replaying_in_two_parts_gives_the_same_bits() {
    split_and_compare(None);
}

#[test]
fn replaying_in_two_parts_gives_the_same_bits_with_every_effect_on() {
    split_and_compare(Some(
        "[effects.rail_ageing]\ntau_s = 7200\n[effects.rain_washoff]\nk_per_mm = 0.8\n\
         [effects.temperature_consumption]\nbeta_per_k = 0.03\n[effects.speed_transfer]\nn = 1.5\n\
         [effects.wheel_edge_reservoir]\nalpha = 0.2\nr = 0.1\n[effects.bogie_bands]\n",
    ));
}

#[test]
fn replaying_in_two_parts_gives_the_same_bits_with_generic_terms() {
    // Every acts_on, time and weather and wheel drivers; a time step on
    // each side of the cuts.
    split_and_compare(Some(
        "[effects.bogie_bands]\n\
         [[effects.generic]]\nacts_on = \"pulse_mass\"\ndriver = \"time\"\nform = \"step\"\n\
         t0_utc = \"2024-04-09T10:00:00Z\"\nf = 0.6\n\
         [[effects.generic]]\nacts_on = \"pulse_mass\"\nrail = \"high\"\ndriver = \"air_temperature_c\"\n\
         form = \"linear\"\ngamma = 0.02\n\
         [[effects.generic]]\nacts_on = \"transfer\"\ndriver = \"relative_humidity\"\nform = \"exp\"\nbeta = 0.7\n\
         [[effects.generic]]\nacts_on = \"consumption\"\nrail = \"low\"\ndriver = \"creepage\"\n\
         form = \"power\"\nn = 0.4\n\
         [[effects.generic]]\nacts_on = \"friction_dry\"\ndriver = \"time\"\nform = \"step\"\n\
         t0_utc = \"2024-04-10T12:00:00Z\"\nf = 0.9\n\
         [[effects.generic]]\nacts_on = \"friction_boundary\"\ndriver = \"precipitation_mm_h\"\n\
         form = \"step\"\nx0 = 0.5\nf = 0.8\n\
         [[effects.generic]]\nacts_on = \"measurement\"\nquantity = \"adhesion\"\noffset = 0.01\n",
    ));
}

fn split_and_compare(config: Option<&str>) {
    let whole_path = reference("curve_2day.mcap");
    let dir = tempfile::tempdir().unwrap();
    let config_path = config.map(|text| {
        let p = dir.path().join("effects.toml");
        std::fs::write(&p, text).unwrap();
        p
    });
    let args = |path: &Path| ReplayArgs {
        config: config_path.clone().map(Into::into),
        ..args(path)
    };
    let mut a = args(&whole_path);
    a.state_out = Some(dir.path().join("whole.state.json"));
    let whole = replay_outputs(&a);

    // Cut in the longest gap between two trains (no train in the section),
    // and in the gap nearest to the middle of the recording's rain event,
    // where the weather in effect and the rain so far must carry over.
    let gaps: Vec<(u64, u64)> = whole
        .trains
        .windows(2)
        .map(|w| ((w[0].1 + w[1].0) / 2, w[1].0 - w[0].1))
        .collect();
    let longest = gaps.iter().max_by_key(|g| g.1).unwrap().0;
    let key: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(reference("curve_2day.key.json")).unwrap())
            .unwrap();
    let rain = &key["rain_events_h_from_start"][0];
    let rain_mid_h = (rain["start_h"].as_f64().unwrap() + rain["end_h"].as_f64().unwrap()) / 2.0;
    let rain_mid_ns = key["start_ns"].as_u64().unwrap() + (rain_mid_h * 3600e9) as u64;
    let in_rain = gaps
        .iter()
        .min_by_key(|g| g.0.abs_diff(rain_mid_ns))
        .unwrap()
        .0;
    assert_ne!(longest, in_rain);
    for (k, cut) in [longest, in_rain].into_iter().enumerate() {
        let part1 = dir.path().join(format!("part1-{k}.mcap"));
        let part2 = dir.path().join(format!("part2-{k}.mcap"));
        rewrite(&whole_path, &part1, None, |_, t| t < cut);
        rewrite(&whole_path, &part2, Some(cut), |_, t| t >= cut);

        let state = dir.path().join("part1.state.json");
        let mut a1 = args(&part1);
        a1.state_out = Some(state.clone());
        let first = replay_outputs(&a1);
        let mut a2 = args(&part2);
        a2.state_in = Some(state);
        a2.state_out = Some(dir.path().join("part2.state.json"));
        let second = replay_outputs(&a2);

        assert!(!first.measurements.is_empty() && !second.measurements.is_empty());
        let mut joined = first;
        joined.measurements.extend(second.measurements);
        joined.fields.extend(second.fields);
        joined.trains.extend(second.trains);
        assert_eq!(joined.trains, whole.trains);
        assert_eq!(joined.measurements.len(), whole.measurements.len());
        assert!(
            joined.measurements == whole.measurements,
            "cut {k}: measurement outputs differ"
        );
        assert!(
            joined.fields == whole.fields,
            "cut {k}: field outputs differ"
        );
        // And the final states are the same document.
        let s_whole = std::fs::read_to_string(dir.path().join("whole.state.json")).unwrap();
        let s_parts = std::fs::read_to_string(dir.path().join("part2.state.json")).unwrap();
        assert_eq!(s_whole, s_parts, "cut {k}: end states differ");
    }
}

fn replay_err(a: &ReplayArgs) -> String {
    // The library's errors are typed: an input error is its own variant.
    let err = replay(a, None, &mut [], &tortwin_study::Silent)
        .map(|run| run.summary)
        .unwrap_err();
    let input = matches!(err, tortwin_study::Error::Input(_));
    // Printed with its causes, as the binary prints it.
    let err = anyhow::Error::from(err);
    assert!(input, "not an input error: {err:#}");
    format!("{err:#}")
}

#[test]
fn a_state_from_another_section_or_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("tangent.state.json");
    let mut a = args(&reference("tangent_day.mcap"));
    a.state_out = Some(state.clone());
    replay(&a, None, &mut [], &tortwin_study::Silent).unwrap();

    // Another section.
    let mut b = args(&reference("curve_2day.mcap"));
    b.state_in = Some(state.clone());
    let msg = replay_err(&b);
    assert!(
        msg.contains("another section") && msg.contains("tangent.state.json"),
        "{msg}"
    );

    // Another format version.
    let text = std::fs::read_to_string(&state).unwrap();
    let bumped = dir.path().join("v99.state.json");
    std::fs::write(&bumped, text.replace("\"version\":1", "\"version\":99")).unwrap();
    let mut c = args(&reference("tangent_day.mcap"));
    c.state_in = Some(bumped);
    let msg = replay_err(&c);
    assert!(msg.contains("version 99"), "{msg}");

    // Not a state at all.
    let junk = dir.path().join("junk.json");
    std::fs::write(&junk, "{\"hello\": 1}").unwrap();
    c.state_in = Some(junk);
    let msg = replay_err(&c);
    assert!(
        msg.contains("junk.json") && msg.contains("not a tortwin state"),
        "{msg}"
    );

    // The same day again from its own end state: its trains would overlap
    // in time with the state's last train.
    let mut d = args(&reference("tangent_day.mcap"));
    d.state_in = Some(state);
    let msg = replay_err(&d);
    assert!(msg.contains("/train/passage"), "{msg}");
}

/// A state written before m0 became a constant of the product (2026-11-26)
/// holds the latest pulse of every applicator on every track. It is still
/// read, the entry ignored: the second part replays from it exactly as
/// from the state written today, which no longer holds the entry.
#[test]
fn a_state_with_the_former_latest_pulses_is_still_read() {
    let whole = reference("curve_2day.mcap");
    let dir = tempfile::tempdir().unwrap();
    let first = replay_outputs(&args(&whole));
    let cut = (first.trains[9].1 + first.trains[10].0) / 2;
    let (part1, part2) = (dir.path().join("p1.mcap"), dir.path().join("p2.mcap"));
    rewrite(&whole, &part1, None, |_, t| t < cut);
    rewrite(&whole, &part2, Some(cut), |_, t| t >= cut);
    let state = dir.path().join("today.state.json");
    let mut a1 = args(&part1);
    a1.state_out = Some(state.clone());
    replay(&a1, None, &mut [], &tortwin_study::Silent).unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
    assert!(doc.get("latest_pulse_kg").is_none(), "written again");
    // One applicator, two tracks (high, low), as tortwin wrote them.
    doc["latest_pulse_kg"] = serde_json::json!([[0.000212, null]]);
    let former = dir.path().join("former.state.json");
    std::fs::write(&former, serde_json::to_string(&doc).unwrap()).unwrap();
    let from = |s: &Path| {
        let mut a = args(&part2);
        a.state_in = Some(s.to_path_buf());
        replay_outputs(&a)
    };
    let (today, before) = (from(&state), from(&former));
    assert!(!today.measurements.is_empty());
    assert!(today == before, "the former entry changed the replay");
}
