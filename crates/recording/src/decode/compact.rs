//! A `/measurement/friction` message in its compact shape, read without
//! serde.
//!
//! Measurements are most of a recording's messages (a year on the 1.5 km
//! curve: 2.46 M of 2.50 M), and serde spent most of the reader thread's
//! time on them: a derived struct matches every key through a visitor, and
//! `site_id` and `rail` were allocated only to be looked up and dropped.
//! The shape every writer we know of produces (`tortwin synth`, the CSV
//! import, the mcap and json libraries' compact output) is one object
//! without whitespace whose values are strings without escapes, `null`,
//! plain integers and numbers; [`compact_measurement`] reads exactly that
//! shape and borrows the strings. Anything else (whitespace, an escape, an
//! unknown or repeated key, a missing field, a value of another type, a
//! number serde would refuse) is `None`, and the caller parses the message
//! with serde, whose result or error is then the answer: this is a shortcut
//! for well-formed messages, never a second grammar. Numbers are converted
//! by serde_json itself (the same function as the full parse), so a value
//! is the same double either way; the tests compare the two on the written
//! shape and on thousands of variations of it.

use super::MeasurementFields;
use crate::event::Quantity;
use crate::wire::json::number;

/// The fields of a measurement message in the compact shape, or `None`
/// (then [`super::parse`] decides).
pub(crate) fn compact_measurement(data: &[u8]) -> Option<MeasurementFields<'_>> {
    let text = std::str::from_utf8(data).ok()?;
    let mut scan = Scan { text, at: 0 };
    scan.byte(b'{')?;
    let mut site_id = None;
    let mut rail = None;
    let mut quantity = None;
    let mut train_id = None;
    let mut axle_index = None;
    let mut value = None;
    loop {
        let key = scan.string()?;
        scan.byte(b':')?;
        match key {
            "site_id" => once(&mut site_id, scan.string()?)?,
            "rail" => once(&mut rail, scan.string()?)?,
            "quantity" => {
                let q = match scan.string()? {
                    "mu" => Quantity::Mu,
                    "adhesion" => Quantity::Adhesion,
                    "rail_mu" => Quantity::RailMu,
                    _ => return None,
                };
                once(&mut quantity, q)?
            }
            "train_id" => once(&mut train_id, scan.or_null(Scan::string)?)?,
            "axle_index" => once(&mut axle_index, scan.or_null(Scan::index)?)?,
            "value" => once(&mut value, scan.number()?)?,
            _ => return None,
        }
        match scan.next()? {
            b',' => {}
            b'}' => break,
            _ => return None,
        }
    }
    if scan.at != text.len() {
        return None;
    }
    Some(MeasurementFields {
        site_id: site_id?,
        rail: rail?,
        quantity: quantity?,
        train_id: train_id.flatten(),
        axle_index: axle_index.flatten(),
        value: value?,
    })
}

/// Sets a field seen for the first time; a repeated key is serde's to refuse.
fn once<T>(slot: &mut Option<T>, value: T) -> Option<()> {
    match slot {
        Some(_) => None,
        None => {
            *slot = Some(value);
            Some(())
        }
    }
}

struct Scan<'a> {
    text: &'a str,
    at: usize,
}

impl<'a> Scan<'a> {
    fn next(&mut self) -> Option<u8> {
        let b = *self.text.as_bytes().get(self.at)?;
        self.at += 1;
        Some(b)
    }

    fn byte(&mut self, expected: u8) -> Option<()> {
        (self.next()? == expected).then_some(())
    }

    /// A string without escapes or control characters (which JSON does not
    /// allow unescaped), borrowed.
    fn string(&mut self) -> Option<&'a str> {
        self.byte(b'"')?;
        let start = self.at;
        let rest = &self.text.as_bytes()[start..];
        let len = rest
            .iter()
            .position(|&b| b == b'"' || b == b'\\' || b < 0x20)?;
        if rest[len] != b'"' {
            return None;
        }
        self.at = start + len + 1;
        // Both ends are ASCII bytes of valid UTF-8: character boundaries.
        self.text.get(start..start + len)
    }

    /// `null` (absent, as serde reads an optional field) or what `read` reads.
    fn or_null<T>(&mut self, read: impl FnOnce(&mut Self) -> Option<T>) -> Option<Option<T>> {
        if self.text.as_bytes()[self.at..].starts_with(b"null") {
            self.at += 4;
            Some(None)
        } else {
            read(self).map(Some)
        }
    }

    /// A JSON integer of at most 18 digits (no sign, fraction or exponent:
    /// serde refuses those for an index, with its own words).
    fn index(&mut self) -> Option<usize> {
        let digits = self.token(|b| b.is_ascii_digit());
        if digits.is_empty() || digits.len() > 18 || (digits.len() > 1 && digits.starts_with('0')) {
            return None;
        }
        digits.parse().ok()
    }

    /// A JSON number, converted by the function the full parse uses.
    fn number(&mut self) -> Option<f64> {
        let token =
            self.token(|b| b.is_ascii_digit() || matches!(b, b'-' | b'+' | b'.' | b'e' | b'E'));
        let mut json = serde_json::Deserializer::from_str(token);
        let value = number(&mut json).ok()?;
        json.end().ok()?;
        Some(value)
    }

    fn token(&mut self, part: impl Fn(u8) -> bool) -> &'a str {
        let start = self.at;
        let len = self.text.as_bytes()[start..]
            .iter()
            .position(|&b| !part(b))
            .unwrap_or(self.text.len() - start);
        self.at = start + len;
        // ASCII bytes: character boundaries.
        &self.text[start..start + len]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::parse;
    use crate::wire::MeasurementMsg;

    /// What serde makes of the same bytes, as fields.
    fn by_serde(data: &[u8]) -> Option<MeasurementMsg> {
        parse::<MeasurementMsg>(data).ok()
    }

    fn same(data: &[u8]) {
        let text = String::from_utf8_lossy(data);
        if let Some(fields) = compact_measurement(data) {
            let msg = by_serde(data)
                .unwrap_or_else(|| panic!("serde refuses what the compact reader took: {text}"));
            let expected = MeasurementFields::from(&msg);
            assert_eq!(fields, expected, "{text}");
            assert_eq!(fields.value.to_bits(), expected.value.to_bits(), "{text}");
        }
    }

    /// The shape tortwin's writer produces is read by the shortcut, and
    /// gives what serde gives.
    #[test]
    fn the_written_shape_is_read_and_agrees_with_serde() {
        let messages = [
            MeasurementMsg {
                site_id: "M1".into(),
                rail: "high".into(),
                quantity: Quantity::Mu,
                train_id: Some("P-00001".into()),
                axle_index: Some(0),
                value: 0.58502,
            },
            MeasurementMsg {
                site_id: "tribometer ü 2".into(),
                rail: "low".into(),
                quantity: Quantity::RailMu,
                train_id: None,
                axle_index: None,
                value: 1e-7,
            },
            MeasurementMsg {
                site_id: "S".into(),
                rail: "left".into(),
                quantity: Quantity::Adhesion,
                train_id: Some("F-12".into()),
                axle_index: Some(199),
                value: -0.0,
            },
        ];
        for msg in &messages {
            let data = serde_json::to_vec(msg).unwrap();
            let fields = compact_measurement(&data)
                .unwrap_or_else(|| panic!("not read: {}", String::from_utf8_lossy(&data)));
            assert_eq!(fields, MeasurementFields::from(msg));
            same(&data);
        }
    }

    /// Variations of the shape, byte by byte: whatever the shortcut reads,
    /// serde reads the same; whatever serde refuses, the shortcut leaves to
    /// it.
    #[test]
    fn variations_agree_with_serde_or_are_left_to_it() {
        let base = br#"{"site_id":"M1","rail":"high","quantity":"adhesion","train_id":"P-1","axle_index":3,"value":0.41}"#;
        let values = [
            "0.41",
            "1",
            "-2",
            "0",
            "-0",
            "1e3",
            "1E-3",
            "1.5e+2",
            "2.5E308",
            "1e309",
            "-1e-320",
            "0.1000000000000000055511151231257827",
            "9007199254740993",
            "18446744073709551616",
            "01",
            "1.",
            ".5",
            "+1",
            "1e",
            "--1",
            "1.2.3",
            "0x10",
            "true",
            "null",
            "\"1\"",
            "NaN",
            "1 ",
            "[1]",
        ];
        let indices = [
            "3",
            "0",
            "00",
            "07",
            "-1",
            "3.0",
            "3e0",
            "null",
            "\"3\"",
            "999999999999999999",
            "9999999999999999999",
            "18446744073709551616",
            "true",
            "",
        ];
        let strings = [
            "\"P-1\"",
            "\"\"",
            "\"a\\\"b\"",
            "\"a\\u0041\"",
            "\"tab\there\"",
            "null",
            "1",
            "\"ü\"",
            "\"unterminated",
        ];
        let quantities = [
            "\"mu\"",
            "\"adhesion\"",
            "\"rail_mu\"",
            "\"Mu\"",
            "\"\"",
            "null",
            "2",
        ];
        let text = std::str::from_utf8(base).unwrap();
        let mut cases: Vec<String> = Vec::new();
        for v in values {
            cases.push(text.replace("0.41", v));
        }
        for i in indices {
            cases.push(text.replace("\"axle_index\":3", &format!("\"axle_index\":{i}")));
        }
        for s in strings {
            cases.push(text.replace("\"P-1\"", s));
            cases.push(text.replace("\"M1\"", s));
        }
        for q in quantities {
            cases.push(text.replace("\"adhesion\"", q));
        }
        // Structure: whitespace, order, repeats, unknown and missing keys,
        // what follows the object.
        cases.extend([
            text.replace(',', ", "),
            text.replace(':', " : "),
            format!(" {text}"),
            format!("{text} "),
            format!("{text}x"),
            format!("{text}{{}}"),
            text.replace(",\"axle_index\":3", ""),
            text.replace(",\"train_id\":\"P-1\"", ""),
            text.replace("\"site_id\":\"M1\",", ""),
            text.replace(",\"value\":0.41", ""),
            text.replace("\"rail\":\"high\"", "\"rail\":\"high\",\"rail\":\"low\""),
            text.replace("\"rail\":\"high\"", "\"extra\":1,\"rail\":\"high\""),
            text.replace("{", "{\"value\":1,").replace(",\"value\":0.41", ""),
            r#"{"value":0.5,"axle_index":null,"train_id":null,"quantity":"rail_mu","rail":"low","site_id":"M2"}"#.to_string(),
            "{}".to_string(),
            "{".to_string(),
            "[]".to_string(),
            String::new(),
            text.replace('}', ",}"),
            text.replace('{', "{,"),
        ]);
        let mut read = 0;
        for case in &cases {
            same(case.as_bytes());
            read += usize::from(compact_measurement(case.as_bytes()).is_some());
        }
        // Every prefix of the written shape, and every single byte changed
        // to one of a few that matter to the grammar.
        for end in 0..base.len() {
            same(&base[..end]);
            assert!(compact_measurement(&base[..end]).is_none());
        }
        for at in 0..base.len() {
            for b in [
                b'"', b'\\', b',', b':', b'}', b'{', b' ', b'0', b'e', b'-', b'n', 0x01, 0xff,
            ] {
                let mut changed = base.to_vec();
                changed[at] = b;
                same(&changed);
            }
        }
        assert!(read > 10, "the shortcut read only {read} of the cases");
    }
}
