//! Writing a recording: the five topics' channels, each with its JSON Schema
//! ([`Topic::schema`]), and the wire messages ([`crate::wire`]) on them.
//!
//! `tortwin synth` writes its recordings with it, and the tests build their
//! input recordings with it, odd ones included: the MCAP options (chunked or
//! not, compression) are the caller's, [`RecordingWriter::end_chunk`] cuts
//! chunks where a test wants them, [`RecordingWriter::write_json`] puts
//! bytes that need not be valid JSON on a topic, and
//! [`RecordingWriter::add_channel`] opens a channel outside the format (an
//! unknown topic, a known one in another encoding). Messages go into the
//! file in the order they are written: the replay order is the reader's
//! business.
//!
//! Every byte follows from the calls (no clock, no map in hash order), so
//! the same calls write the same file.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use mcap::records::{MessageHeader, Metadata};

use crate::error::WriteError;
use crate::topic::Topic;
use crate::wire::WireMessage;

/// A recording being written to `W`; [`RecordingWriter::finish`] ends it.
pub struct RecordingWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    /// The channel of each topic, by its place in [`Topic::ALL`]; `/line`'s
    /// only once a line is written (a recording of a section declares the
    /// five topics it always did, byte for byte).
    channels: [Option<u16>; Topic::ALL.len()],
    /// The last sequence number written on each channel.
    sequences: BTreeMap<u16, u32>,
    /// Reused for every message's JSON.
    json: Vec<u8>,
    messages: u64,
}

impl<W: Write + Seek> RecordingWriter<W> {
    /// Starts a recording with `options`, writes `metadata` (if any) and
    /// then a schema and a `json` channel for each topic, in the format's
    /// order.
    pub fn new(
        out: W,
        options: mcap::WriteOptions,
        metadata: Option<&Metadata>,
    ) -> Result<Self, WriteError> {
        let mcap_error = |what: &str| {
            let what = what.to_string();
            move |source| WriteError::Mcap { what, source }
        };
        let mut mcap = options
            .create(out)
            .map_err(mcap_error("starting the recording"))?;
        if let Some(metadata) = metadata {
            mcap.write_metadata(metadata)
                .map_err(mcap_error("writing the metadata"))?;
        }
        let mut channels = [None; Topic::ALL.len()];
        for topic in Topic::ALL.into_iter().filter(|&t| t != Topic::Line) {
            channels[topic as usize] = Some(declare(&mut mcap, topic)?);
        }
        Ok(Self {
            mcap,
            channels,
            sequences: BTreeMap::new(),
            json: Vec::with_capacity(64 * 1024),
            messages: 0,
        })
    }

    /// Writes `message` on its topic at `log_time_ns` (also its
    /// publish_time).
    pub fn write<M: WireMessage>(
        &mut self,
        log_time_ns: u64,
        message: &M,
    ) -> Result<(), WriteError> {
        let mut json = std::mem::take(&mut self.json);
        json.clear();
        let written = serde_json::to_writer(&mut json, message)
            .map_err(|source| WriteError::Json {
                topic: M::TOPIC.name(),
                source,
            })
            .and_then(|()| self.write_json(M::TOPIC, log_time_ns, &json));
        self.json = json;
        written
    }

    /// Writes `json` as it is (valid JSON or not) on `topic`.
    pub fn write_json(
        &mut self,
        topic: Topic,
        log_time_ns: u64,
        json: &[u8],
    ) -> Result<(), WriteError> {
        let channel = self.channel_of(topic)?;
        self.write_to_channel(channel, log_time_ns, json)
    }

    /// A channel outside the format's five: an unknown topic, or a known
    /// topic in another message encoding. It has no schema.
    pub fn add_channel(&mut self, topic: &str, message_encoding: &str) -> Result<u16, WriteError> {
        self.mcap
            .add_channel(0, topic, message_encoding, &BTreeMap::new())
            .map_err(|source| WriteError::Mcap {
                what: format!("adding channel {topic} ({message_encoding})"),
                source,
            })
    }

    /// The channel of a topic of the format (`/line`'s declared on its
    /// first use).
    pub fn channel_of(&mut self, topic: Topic) -> Result<u16, WriteError> {
        match self.channels[topic as usize] {
            Some(channel) => Ok(channel),
            None => {
                let channel = declare(&mut self.mcap, topic)?;
                self.channels[topic as usize] = Some(channel);
                Ok(channel)
            }
        }
    }

    /// Writes `data` on a channel of this writer.
    pub fn write_to_channel(
        &mut self,
        channel_id: u16,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
        self.write_message(channel_id, log_time_ns, log_time_ns, data)
    }

    /// Writes `data` on a channel of this writer with its own publish_time.
    pub fn write_message(
        &mut self,
        channel_id: u16,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
        let sequence = self.sequences.entry(channel_id).or_insert(0);
        *sequence = sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: *sequence,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|source| WriteError::Mcap {
                what: format!("writing message {} (channel {channel_id})", self.messages),
                source,
            })?;
        self.messages += 1;
        Ok(())
    }

    /// Ends the current chunk: the next message starts a new one.
    pub fn end_chunk(&mut self) -> Result<(), WriteError> {
        self.mcap.flush().map_err(|source| WriteError::Mcap {
            what: "ending a chunk".to_string(),
            source,
        })
    }

    /// Messages written so far; the next message's index in the file.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Writes the summary and the footer and gives the output back.
    pub fn finish(mut self) -> Result<W, WriteError> {
        self.mcap.finish().map_err(|source| WriteError::Mcap {
            what: "finishing the recording".to_string(),
            source,
        })?;
        Ok(self.mcap.into_inner())
    }
}

/// A schema and a `json` channel for `topic` on `mcap`: its channel id.
fn declare<W: Write + Seek>(mcap: &mut mcap::Writer<W>, topic: Topic) -> Result<u16, WriteError> {
    let mcap_error = |what: String| move |source| WriteError::Mcap { what, source };
    let schema_id = mcap
        .add_schema(topic.schema_name(), "jsonschema", topic.schema().as_bytes())
        .map_err(mcap_error(format!("adding the schema of {}", topic.name())))?;
    mcap.add_channel(schema_id, topic.name(), "json", &BTreeMap::new())
        .map_err(mcap_error(format!("adding channel {}", topic.name())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reader::{ReaderContext, RecordingReader};
    use crate::wire::{ApplicatorMsg, PulseMsg, SectionMsg, SiteMsg, WeatherMsg};
    use crate::EventKind;

    #[test]
    fn what_the_writer_writes_the_reader_reads() {
        let dir = std::env::temp_dir().join(format!("tortwin-writer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("small.mcap");
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = RecordingWriter::new(file, mcap::WriteOptions::new(), None).unwrap();
        let t0 = 1_712_534_400_000_000_000;
        writer
            .write(
                t0,
                &SectionMsg {
                    section_id: "s".into(),
                    length_m: 100.0,
                    rails: vec!["left".into(), "right".into()],
                    curve_radius_m: None,
                    rail_head_radius_m: 0.3,
                    nominal_wheel_diameter_m: 0.92,
                    applicators: vec![ApplicatorMsg {
                        id: "A1".into(),
                        position_m: 5.0,
                        rails: vec!["right".into()],
                        nominal_pulse_g: 0.2,
                    }],
                    measurement_sites: vec![SiteMsg {
                        id: "M1".into(),
                        position_m: 50.0,
                    }],
                },
            )
            .unwrap();
        let weather = WeatherMsg {
            air_temperature_c: 3.5,
            relative_humidity: 0.9,
            precipitation_mm_h: 1.2,
        };
        writer.write(t0 + 2, &weather).unwrap();
        let pulse = PulseMsg {
            applicator_id: "A1".into(),
            rail: "right".into(),
            mass_g: 0.25,
        };
        writer.write(t0 + 1, &pulse).unwrap();
        let other = writer.add_channel("/x/other", "cdr").unwrap();
        writer.write_to_channel(other, t0 + 1, &[0xff]).unwrap();
        assert_eq!(writer.messages(), 4);
        writer.finish().unwrap();

        let mut reader = RecordingReader::open(&path, ReaderContext::default()).unwrap();
        assert_eq!(reader.section().applicators[0].rails, [1]);
        let events: Vec<_> = reader.by_ref().collect::<Result<_, _>>().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(reader.unknown_topic_messages(), 1);
        let EventKind::Pulse(p) = &events[0].kind else {
            panic!("{events:?}")
        };
        assert_eq!((p.applicator, p.rail, p.mass_kg), (0, 1, 0.25 * 1e-3));
        let EventKind::Weather(w) = &events[1].kind else {
            panic!("{events:?}")
        };
        assert_eq!(w.precipitation_mm_h, 1.2);
    }
}
