//! Records parsed with the mcap crate, after their length prefixes are
//! checked against the record; a Message record's fixed header by hand.
//!
//! `mcap::parse_record` reserves the length a string or byte field claims
//! before it reads it: a corrupt 4-byte prefix inside a 100-byte record made
//! it ask for 4.2 GB (issue 15's campaign; `tortwin-fuzz` found it again as
//! allocations of 0.5-2.3 GB). Every prefix of the records tortwin parses
//! (Chunk, Channel, Message) is checked here to fit what is left of the
//! record first, so a parse allocates no more than the record's own size.

use mcap::records::{op, Record};

/// `mcap::parse_record`, refusing a length prefix that runs past the record.
pub(super) fn parse(opcode: u8, body: &[u8]) -> Result<Record<'_>, String> {
    let mut fields = Fields { rest: body };
    match opcode {
        op::CHUNK => {
            // message_start_time, message_end_time, uncompressed_size,
            // uncompressed_crc, compression, records.
            fields.skip(8 + 8 + 8 + 4, "chunk header")?;
            fields.string("compression")?;
            fields.bytes_u64("records")?;
        }
        op::CHANNEL => {
            // id, schema_id, topic, message_encoding, metadata.
            fields.skip(2 + 2, "channel id and schema id")?;
            fields.string("topic")?;
            fields.string("message_encoding")?;
            let mut metadata = Fields {
                rest: fields.bytes_u32("metadata")?,
            };
            while !metadata.rest.is_empty() {
                metadata.string("metadata key")?;
                metadata.string("metadata value")?;
            }
        }
        op::MESSAGE => {
            // Most records are messages: their fixed little-endian header
            // is read here, as the crate would read it, without its
            // general parser (a tenth of the layout pass's time).
            let head = fields.skip(2 + 4 + 8 + 8, "message header")?;
            return Ok(Record::Message {
                header: super::layout::message_header(head),
                data: std::borrow::Cow::Borrowed(fields.rest),
            });
        }
        _ => {}
    }
    mcap::parse_record(opcode, body).map_err(|e| e.to_string())
}

struct Fields<'a> {
    rest: &'a [u8],
}

impl<'a> Fields<'a> {
    fn skip(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if n > self.rest.len() {
            return Err(format!(
                "the {what} needs {n} bytes; the record has {} left",
                self.rest.len()
            ));
        }
        let (taken, rest) = self.rest.split_at(n);
        self.rest = rest;
        Ok(taken)
    }

    fn prefixed(&mut self, prefix: usize, what: &str) -> Result<&'a [u8], String> {
        let raw = self.skip(prefix, &format!("length of `{what}`"))?;
        let mut le = [0u8; 8];
        le[..prefix].copy_from_slice(raw);
        let claimed = u64::from_le_bytes(le);
        let left = self.rest.len() as u64;
        if claimed > left {
            return Err(format!(
                "field `{what}` claims {claimed} bytes; the record has {left} left"
            ));
        }
        self.skip(claimed as usize, what)
    }

    fn string(&mut self, what: &str) -> Result<&'a [u8], String> {
        self.prefixed(4, what)
    }

    fn bytes_u32(&mut self, what: &str) -> Result<&'a [u8], String> {
        self.prefixed(4, what)
    }

    fn bytes_u64(&mut self, what: &str) -> Result<&'a [u8], String> {
        self.prefixed(8, what)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel_body(topic_len: u32) -> Vec<u8> {
        let mut b = vec![1, 0, 0, 0];
        b.extend(topic_len.to_le_bytes());
        b.extend(b"/section");
        b.extend(4u32.to_le_bytes());
        b.extend(b"json");
        b.extend(0u32.to_le_bytes());
        b
    }

    #[test]
    fn a_sound_channel_parses_and_a_huge_prefix_is_refused_without_allocating() {
        match parse(op::CHANNEL, &channel_body(8)) {
            Ok(Record::Channel(c)) => assert_eq!(c.topic, "/section"),
            other => panic!("{other:?}"),
        }
        let err = parse(op::CHANNEL, &channel_body(0xfd2d_0a28)).unwrap_err();
        assert_eq!(
            err,
            "field `topic` claims 4247587368 bytes; the record has 20 left"
        );
    }

    /// A message record read by hand is what the crate's parser reads,
    /// header and data, whatever its bytes; one shorter than its header is
    /// refused.
    #[test]
    fn a_message_reads_as_the_crate_reads_it() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut byte = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state as u8
        };
        for len in [22, 23, 30, 157, 4096] {
            let body: Vec<u8> = (0..len).map(|_| byte()).collect();
            let ours = parse(op::MESSAGE, &body).unwrap();
            let crate_s = mcap::parse_record(op::MESSAGE, &body).unwrap();
            match (ours, crate_s) {
                (Record::Message { header, data }, Record::Message { header: h, data: d }) => {
                    assert_eq!(header, h);
                    assert_eq!(data, d);
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(parse(op::MESSAGE, &[0u8; 21]).is_err());
    }

    #[test]
    fn a_chunk_whose_records_run_past_the_record_is_refused() {
        let mut b = vec![0u8; 28];
        b.extend(0u32.to_le_bytes()); // compression ""
        b.extend(u64::MAX.to_le_bytes()); // records length
        let err = parse(op::CHUNK, &b).unwrap_err();
        assert!(
            err.contains("field `records` claims 18446744073709551615 bytes"),
            "{err}"
        );
        let err = parse(op::MESSAGE, &[0; 10]).unwrap_err();
        assert!(err.contains("message header needs 22 bytes"), "{err}");
    }
}
