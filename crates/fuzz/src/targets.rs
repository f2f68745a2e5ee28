//! The targets: what a mutant goes through, exactly as the commands take
//! it (a file on disk, read by the library's own entry points), to the end
//! of the replay it feeds.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result};
use rand::Rng;
use tortwin_jobs::replay::{self as job, ReplayArgs, Replayed};
use tortwin_jobs::tables::{import, ImportArgs};
use tortwin_jobs::ConfigSource;
use tortwin_study::Silent;

use crate::mutate;
use crate::seeds::Seeds;
use crate::values;

/// What tortwin reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Kind {
    /// MCAP recordings, mutated byte by byte (the framing, chunk headers,
    /// compression, records), in four layouts: zstd chunks, uncompressed
    /// chunks without CRCs (so that mutations reach the records), lz4 in
    /// small chunks, unchunked.
    Mcap,
    /// The recordings' JSON messages, mutated as text (fields, numbers,
    /// structure) or in time, written back as valid MCAP: the message
    /// parser and the rules of the format.
    Messages,
    /// Model configurations (TOML overlays, generic terms included).
    Config,
    /// State files (`--state-in`).
    State,
    /// CSV tables and section.toml (`tortwin import`).
    Csv,
    /// Well-formed inputs of every kind with one value at the edge of its
    /// type or range (0, -0, subnormals, 1e308, 2^53, 2^63, u64::MAX, NaN
    /// and infinities however spelled): replayed with finite results or
    /// refused naming the field ([`crate::values`]).
    Values,
}

impl Kind {
    pub const ALL: [Kind; 6] = [
        Kind::Mcap,
        Kind::Messages,
        Kind::Config,
        Kind::State,
        Kind::Csv,
        Kind::Values,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Kind::Mcap => "mcap",
            Kind::Messages => "messages",
            Kind::Config => "config",
            Kind::State => "state",
            Kind::Csv => "csv",
            Kind::Values => "values",
        }
    }

    /// The target that replays a saved input of this kind (a `messages`
    /// mutant is saved as the MCAP file it became).
    pub fn runner(self) -> Kind {
        match self {
            Kind::Messages => Kind::Mcap,
            k => k,
        }
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Accepted and replayed, with finite results.
    Accepted,
    /// Refused as bad input (exit status 2), with the message.
    Rejected(String),
    /// Failed with an error that is not the input's (exit status 1): a
    /// finding.
    NotInput(String),
}

/// A message of a seed recording, to be mutated and written back.
#[derive(Clone)]
struct SeedMessage {
    channel: u16,
    sequence: u32,
    log_time: u64,
    data: Vec<u8>,
}

struct SeedRecording {
    /// Channel id -> (topic, message encoding, schema name, schema data).
    channels: BTreeMap<u16, (String, String, String, Vec<u8>)>,
    messages: Vec<SeedMessage>,
}

/// A target with its seeds and a scratch folder for the files a run
/// writes.
pub struct Target {
    pub kind: Kind,
    fixtures: Arc<Seeds>,
    seeds: Vec<Vec<u8>>,
    recording: Option<SeedRecording>,
    scratch: tempfile::TempDir,
}

impl Target {
    pub fn new(kind: Kind, fixtures: Arc<Seeds>) -> Result<Self> {
        let day1 = std::fs::read(&fixtures.day1)?;
        let mut recording = None;
        let seeds = match kind {
            Kind::Mcap => {
                let parsed = read_recording(&day1)?;
                vec![
                    day1.clone(),
                    write_recording(&parsed, Layout::Uncompressed)?,
                    write_recording(&parsed, Layout::Lz4Small)?,
                    write_recording(&parsed, Layout::Unchunked)?,
                ]
            }
            Kind::Messages | Kind::Values => {
                recording = Some(read_recording(&day1)?);
                vec![Vec::new()]
            }
            Kind::Config => fixtures.configs.clone(),
            Kind::State => vec![fixtures.state1.clone()],
            Kind::Csv => fixtures
                .table_files()?
                .into_iter()
                .map(|(name, content)| {
                    let mut input = format!("{name}\n").into_bytes();
                    input.extend(content);
                    input
                })
                .collect(),
        };
        Ok(Self {
            kind,
            fixtures,
            seeds,
            recording,
            scratch: tempfile::tempdir()?,
        })
    }

    /// A mutant of one of the seeds.
    pub fn mutant(&self, rng: &mut impl Rng) -> Result<Vec<u8>> {
        let seed = &self.seeds[rng.random_range(0..self.seeds.len())];
        let other = &self.seeds[rng.random_range(0..self.seeds.len())];
        Ok(match self.kind {
            Kind::Mcap => {
                let mut v = seed.clone();
                mutate::bytes(rng, &mut v, other);
                v
            }
            Kind::Messages => {
                let recording = self.recording.as_ref().context("no seed recording")?;
                let mutated = mutate_messages(rng, recording);
                let layout = [Layout::Uncompressed, Layout::Unchunked][rng.random_range(0..2)];
                write_recording(&mutated, layout)?
            }
            Kind::Config | Kind::State => {
                let mut v = seed.clone();
                mutate::text(rng, &mut v, other);
                v
            }
            Kind::Values => self.value_mutant(rng)?,
            Kind::Csv => {
                // The first line names the file; only its content mutates.
                let split = seed.iter().position(|&b| b == b'\n').map_or(0, |i| i + 1);
                let mut content = seed[split..].to_vec();
                mutate::text(rng, &mut content, &other[split.min(other.len())..]);
                let mut v = seed[..split].to_vec();
                v.extend(content);
                v
            }
        })
    }

    /// Runs one input through the target.
    pub fn run(&self, input: &[u8]) -> Result<Outcome> {
        let scratch = self.scratch.path();
        let result = match self.kind.runner() {
            Kind::Mcap | Kind::Messages => {
                let path = scratch.join("input.mcap");
                std::fs::write(&path, input)?;
                replay(ReplayArgs::new(&path))
            }
            Kind::Config => {
                let path = scratch.join("fuzz.toml");
                std::fs::write(&path, input)?;
                let mut args = ReplayArgs::new(&self.fixtures.day1);
                args.config = Some(ConfigSource::File(path));
                replay(args)
            }
            Kind::State => {
                let path = scratch.join("state.json");
                std::fs::write(&path, input)?;
                let mut args = ReplayArgs::new(&self.fixtures.day2);
                args.state_in = Some(path);
                replay(args)
            }
            Kind::Csv => self.run_csv(input)?,
            Kind::Values => self.run_value(input)?,
        };
        Ok(result)
    }

    /// A `values` mutant: one number of one seed (a message of day 1, a
    /// configuration, the state after day 1, a table) at an edge.
    fn value_mutant(&self, rng: &mut impl Rng) -> Result<Vec<u8>> {
        loop {
            let choice = rng.random_range(0..20);
            let made = match choice {
                0..=9 => self.message_value(rng)?,
                10..=12 => {
                    let config =
                        &self.fixtures.configs[rng.random_range(0..self.fixtures.configs.len())];
                    values::toml_edge(rng, config).map(|e| values::saved("config", e))
                }
                13..=15 => {
                    values::json_edge(rng, &self.fixtures.state1).map(|e| values::saved("state", e))
                }
                _ => {
                    let files = self.fixtures.table_files()?;
                    let (name, content) = &files[rng.random_range(0..files.len())];
                    let place = format!("csv:{name}");
                    if name.ends_with(".toml") {
                        values::toml_edge(rng, content).map(|e| values::saved(&place, e))
                    } else {
                        values::csv_with(rng, content).map(|(text, column)| {
                            values::encode(&place, std::slice::from_ref(&column), &column, &text)
                        })
                    }
                }
            };
            if let Some(m) = made {
                return Ok(m);
            }
        }
    }

    /// One message of day 1 with a number of its JSON, or its `log_time`,
    /// at an edge; written back as MCAP.
    fn message_value(&self, rng: &mut impl Rng) -> Result<Option<Vec<u8>>> {
        let recording = self.recording.as_ref().context("no seed recording")?;
        let mut messages = recording.messages.clone();
        let i = rng.random_range(0..messages.len());
        let topic = recording
            .channels
            .get(&messages[i].channel)
            .map_or("?", |c| c.0.as_str())
            .to_string();
        let (names, path) = if rng.random_range(0..8) == 0 {
            messages[i].log_time =
                values::TIME_EDGES[rng.random_range(0..values::TIME_EDGES.len())];
            (vec!["log_time".to_string()], format!("{topic} log_time"))
        } else {
            let Some((text, path)) = values::json_edge(rng, &messages[i].data) else {
                return Ok(None);
            };
            messages[i].data = text.into_bytes();
            (
                values::names(&path),
                format!("{topic} {}", values::describe(&path)),
            )
        };
        let layout = [Layout::Uncompressed, Layout::Unchunked][rng.random_range(0..2)];
        let mcap = write_recording(
            &SeedRecording {
                channels: recording.channels.clone(),
                messages,
            },
            layout,
        )?;
        Ok(Some(values::encode("mcap", &names, &path, &mcap)))
    }

    /// Runs a `values` mutant where its header says it belongs.
    fn run_value(&self, input: &[u8]) -> Result<Outcome> {
        let (place, _, content) =
            values::decode(input).context("a values input without its header line")?;
        let scratch = self.scratch.path();
        Ok(match place.as_str() {
            "mcap" => {
                let path = scratch.join("input.mcap");
                std::fs::write(&path, content)?;
                replay(ReplayArgs::new(&path))
            }
            "config" => {
                let path = scratch.join("fuzz.toml");
                std::fs::write(&path, content)?;
                let mut args = ReplayArgs::new(&self.fixtures.day1);
                args.config = Some(ConfigSource::File(path));
                replay(args)
            }
            "state" => {
                let path = scratch.join("state.json");
                std::fs::write(&path, content)?;
                let mut args = ReplayArgs::new(&self.fixtures.day2);
                args.state_in = Some(path);
                replay(args)
            }
            other => {
                let name = other
                    .strip_prefix("csv:")
                    .context("an unknown place in a values header")?;
                let mut csv_input = format!("{name}\n").into_bytes();
                csv_input.extend_from_slice(content);
                self.run_csv(&csv_input)?
            }
        })
    }

    /// For a `values` mutant, the names a refusal may give for the field
    /// it changed (empty for the other kinds).
    pub fn field_names(&self, input: &[u8]) -> Vec<String> {
        if self.kind != Kind::Values {
            return Vec::new();
        }
        values::decode(input)
            .map(|(_, names, _)| names)
            .unwrap_or_default()
    }

    fn run_csv(&self, input: &[u8]) -> Result<Outcome> {
        let split = input
            .iter()
            .position(|&b| b == b'\n')
            .unwrap_or(input.len());
        let name = String::from_utf8_lossy(&input[..split]).into_owned();
        let content = input.get(split + 1..).unwrap_or_default();
        let tables = self.scratch.path().join("tables");
        if tables.exists() {
            std::fs::remove_dir_all(&tables)?;
        }
        std::fs::create_dir(&tables)?;
        for (file, seed) in self.fixtures.table_files()? {
            std::fs::write(tables.join(&file), seed)?;
        }
        if !name.is_empty() && !name.contains(['/', '\\']) && name != "." && name != ".." {
            std::fs::write(tables.join(&name), content)?;
        }
        let out = self.scratch.path().join("imported.mcap");
        let args = ImportArgs {
            tables: tables.clone(),
            out: out.clone(),
            quiet: true,
        };
        Ok(match import(&args, &Silent) {
            Ok(_) => replay(ReplayArgs::new(&out)),
            Err(e) => classify(&e),
        })
    }

    /// Whether an error message names the file it is about: the input
    /// (or a file made from it) or the seed it was replayed with.
    pub fn names_a_file(&self, message: &str) -> bool {
        let mentions = |p: &Path| message.contains(&*p.to_string_lossy());
        mentions(self.scratch.path()) || mentions(self.fixtures.folder())
    }
}

fn replay(args: ReplayArgs) -> Outcome {
    match job::replay(&args, None, &mut [], &Silent) {
        Ok(run) => match not_finite(&run) {
            None => Outcome::Accepted,
            Some(what) => {
                Outcome::NotInput(format!("accepted with a result that is not finite: {what}"))
            }
        },
        Err(e) => classify(&e),
    }
}

/// What of an accepted run is not finite: a number of its summary, or a
/// state that would not read back (a NaN is written as `null`).
fn not_finite(run: &Replayed) -> Option<String> {
    let s = &run.summary;
    for (quantity, n, rmse) in &s.rmse {
        if *n > 0 && !rmse.is_finite() {
            return Some(format!("RMSE of {quantity} {rmse}"));
        }
    }
    let b = &s.mass_balance;
    let balance = [
        ("on_rail_start_kg", b.on_rail_start_kg),
        ("applied_kg", b.applied_kg),
        ("on_rail_end_kg", b.on_rail_end_kg),
        ("carried_out_kg", b.carried_out_kg),
        ("consumed_kg", b.consumed_kg),
        ("capped_kg", b.capped_kg),
        ("effects_lost_kg", b.effects_lost_kg),
    ];
    if let Some((name, v)) = balance.iter().find(|(_, v)| !v.is_finite()) {
        return Some(format!("mass balance {name} {v}"));
    }
    let text = match serde_json::to_string(&run.state) {
        Ok(t) => t,
        Err(e) => return Some(format!("the state does not write: {e}")),
    };
    if let Err(e) = serde_json::from_str::<tortwin_engine::EngineState>(&text) {
        return Some(format!("the state does not read back: {e}"));
    }
    None
}

fn classify(e: &tortwin_study::Error) -> Outcome {
    let text = e.full_message();
    if e.is_input() {
        Outcome::Rejected(text)
    } else {
        Outcome::NotInput(text)
    }
}

fn read_recording(bytes: &[u8]) -> Result<SeedRecording> {
    let mut channels = BTreeMap::new();
    let mut messages = Vec::new();
    for message in mcap::MessageStream::new(bytes)? {
        let message = message?;
        let c = &message.channel;
        let (schema_name, schema_data) = c
            .schema
            .as_ref()
            .map(|s| (s.name.clone(), s.data.to_vec()))
            .unwrap_or_default();
        channels.entry(c.id).or_insert_with(|| {
            (
                c.topic.clone(),
                c.message_encoding.clone(),
                schema_name,
                schema_data,
            )
        });
        messages.push(SeedMessage {
            channel: c.id,
            sequence: message.sequence,
            log_time: message.log_time,
            data: message.data.into_owned(),
        });
    }
    Ok(SeedRecording { channels, messages })
}

#[derive(Clone, Copy)]
enum Layout {
    Uncompressed,
    Lz4Small,
    Unchunked,
}

fn write_recording(recording: &SeedRecording, layout: Layout) -> Result<Vec<u8>> {
    let options = mcap::WriteOptions::new()
        .calculate_chunk_crcs(false)
        .calculate_data_section_crc(false);
    let options = match layout {
        Layout::Uncompressed => options.compression(None),
        Layout::Lz4Small => options
            .compression(Some(mcap::Compression::Lz4))
            .chunk_size(Some(4096)),
        Layout::Unchunked => options.use_chunks(false),
    };
    let mut writer = options.create(std::io::Cursor::new(Vec::new()))?;
    let mut ids = BTreeMap::new();
    for (&id, (topic, encoding, schema_name, schema_data)) in &recording.channels {
        let schema = if schema_name.is_empty() {
            0
        } else {
            writer.add_schema(schema_name, "jsonschema", schema_data)?
        };
        ids.insert(
            id,
            writer.add_channel(schema, topic, encoding, &BTreeMap::new())?,
        );
    }
    for m in &recording.messages {
        let channel = ids.get(&m.channel).copied().unwrap_or(0);
        writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.log_time,
            },
            &m.data,
        )?;
    }
    writer.finish()?;
    Ok(writer.into_inner().into_inner())
}

/// One or two messages changed: the JSON as text, the log_time moved, a
/// message dropped or doubled.
fn mutate_messages(rng: &mut impl Rng, recording: &SeedRecording) -> SeedRecording {
    let mut messages = recording.messages.clone();
    for _ in 0..rng.random_range(1..=2) {
        let i = rng.random_range(0..messages.len());
        match rng.random_range(0..8) {
            0 => {
                let shift = [1u64, 1_000_000_000, 3_600_000_000_000][rng.random_range(0..3)];
                let m = &mut messages[i];
                m.log_time = if rng.random() {
                    m.log_time.saturating_add(shift)
                } else {
                    m.log_time.saturating_sub(shift)
                };
            }
            1 => {
                messages.remove(i);
            }
            2 => {
                let copy = messages[i].clone();
                messages.insert(i, copy);
            }
            _ => {
                let other = messages[rng.random_range(0..messages.len())].data.clone();
                mutate::text(rng, &mut messages[i].data, &other);
            }
        }
        if messages.is_empty() {
            break;
        }
    }
    SeedRecording {
        channels: recording.channels.clone(),
        messages,
    }
}
