//! Messages in their compact shape, read without serde: the two topics
//! that are nearly all of a recording, `/measurement/friction` (most of its
//! messages: a year on the 1.5 km curve has 2.46 M of 2.59 M) and
//! `/train/passage` (most of its bytes: the same year's 20 440 passages are
//! 370 MB of JSON, its measurements 250 MB), and `/applicator/pulse` (a
//! third of a 3-day recording's messages on the 600 m curve).
//!
//! serde spent most of the reader thread's time on them: a derived struct
//! matches every key through a visitor, and the strings (a measurement's
//! `site_id` and `rail`, a passage's four rail names per axle) were
//! allocated only to be looked up and dropped. The shape every writer we
//! know of produces (`tortwin synth`, the CSV import, the mcap and json
//! libraries' compact output) is objects and arrays without whitespace
//! whose values are strings without escapes, `null`, plain integers and
//! numbers; [`compact_measurement`], [`compact_passage`] and
//! [`compact_pulse`] read exactly that shape and borrow the strings. Anything else (whitespace, an escape,
//! an unknown or repeated key, a missing field, an empty object or array, a
//! value of another type, a number serde would refuse, a passage's
//! `segments` of a line) is `None`, and the caller parses the message with
//! serde, whose result or error is then the answer: this is a shortcut for
//! well-formed messages, never a second grammar. Numbers are converted by
//! serde_json itself (the same function as the full parse), except plain
//! decimals of up to 15 digits, which one exact division converts to the
//! same double ([`plain_decimal`]); a value is the same double either way,
//! and the tests compare the two on the written shape, on thousands of
//! variations of it and on every decimal of up to four digits.

use super::{AxleFields, MeasurementFields, PassageFields, PulseFields};
use crate::event::{BogiePosition, Direction, Quantity};
use crate::wire::json::number;
use crate::wire::CreepageMsg;

/// The fields of a measurement message in the compact shape, or `None`
/// (then [`super::parse`] decides).
pub(crate) fn compact_measurement(data: &[u8]) -> Option<MeasurementFields<'_>> {
    let text = std::str::from_utf8(data).ok()?;
    let mut scan = Scan { text, at: 0 };
    let mut site_id = None;
    let mut rail = None;
    let mut quantity = None;
    let mut train_id = None;
    let mut axle_index = None;
    let mut value = None;
    scan.object(|scan, key| match key {
        "site_id" => once(&mut site_id, scan.string()?),
        "rail" => once(&mut rail, scan.string()?),
        "quantity" => once(
            &mut quantity,
            scan.name(&[
                ("mu", Quantity::Mu),
                ("adhesion", Quantity::Adhesion),
                ("rail_mu", Quantity::RailMu),
            ])?,
        ),
        "train_id" => once(&mut train_id, scan.or_null(Scan::string)?),
        "axle_index" => once(&mut axle_index, scan.or_null(Scan::index)?),
        "value" => once(&mut value, scan.number()?),
        _ => None,
    })?;
    scan.end()?;
    Some(MeasurementFields {
        site_id: site_id?,
        rail: rail?,
        quantity: quantity?,
        train_id: train_id.flatten(),
        axle_index: axle_index.flatten(),
        value: value?,
    })
}

/// The fields of a pulse message in the compact shape, or `None` (then
/// [`super::parse`] decides).
pub(crate) fn compact_pulse(data: &[u8]) -> Option<PulseFields<'_>> {
    let text = std::str::from_utf8(data).ok()?;
    let mut scan = Scan { text, at: 0 };
    let mut applicator_id = None;
    let mut rail = None;
    let mut mass_g = None;
    scan.object(|scan, key| match key {
        "applicator_id" => once(&mut applicator_id, scan.string()?),
        "rail" => once(&mut rail, scan.string()?),
        "mass_g" => once(&mut mass_g, scan.number()?),
        _ => None,
    })?;
    scan.end()?;
    Some(PulseFields {
        applicator_id: applicator_id?,
        rail: rail?,
        mass_g: mass_g?,
    })
}

/// The fields of a passage message in the compact shape, or `None` (then
/// [`super::parse`] decides). `consist` is skipped as serde skips it (any
/// string, as often as it comes).
pub(crate) fn compact_passage(data: &[u8]) -> Option<PassageFields<'_>> {
    let text = std::str::from_utf8(data).ok()?;
    let mut scan = Scan { text, at: 0 };
    // About 230 bytes an axle as written; the lists grow past a guess too low.
    let axles_guess = data.len() / 256;
    let mut fields = PassageFields {
        train_id: "",
        direction: Direction::Up,
        speed_mps: 0.0,
        axles: Vec::with_capacity(axles_guess),
        wheel_loads_kn: Vec::with_capacity(2 * axles_guess),
        creepages: Vec::with_capacity(2 * axles_guess),
    };
    let mut train_id = None;
    let mut direction = None;
    let mut speed_mps = None;
    let mut axles = None;
    scan.object(|scan, key| match key {
        "train_id" => once(&mut train_id, scan.string()?),
        "direction" => once(
            &mut direction,
            scan.name(&[("up", Direction::Up), ("down", Direction::Down)])?,
        ),
        "speed_mps" => once(&mut speed_mps, scan.number()?),
        "consist" => scan.string().map(drop),
        "axles" => {
            once(&mut axles, ())?;
            scan.array(|scan| axle(scan, &mut fields))
        }
        _ => None,
    })?;
    scan.end()?;
    axles?;
    fields.train_id = train_id?;
    fields.direction = direction?;
    fields.speed_mps = speed_mps?;
    Some(fields)
}

/// One axle object, added to `fields`.
fn axle<'a>(scan: &mut Scan<'a>, fields: &mut PassageFields<'a>) -> Option<()> {
    let mut offset_m = None;
    let mut bogie_position = None;
    let mut wheel_diameter_m = None;
    let mut wheel_load_kn = None;
    let mut creepage = None;
    scan.object(|scan, key| match key {
        "offset_m" => once(&mut offset_m, scan.number()?),
        "bogie_position" => once(
            &mut bogie_position,
            scan.name(&[
                ("leading", BogiePosition::Leading),
                ("trailing", BogiePosition::Trailing),
            ])?,
        ),
        "wheel_diameter_m" => once(&mut wheel_diameter_m, scan.number()?),
        "wheel_load_kN" => {
            let start = fields.wheel_loads_kn.len();
            scan.object(|scan, rail| {
                fields.wheel_loads_kn.push((rail, scan.number()?));
                Some(())
            })?;
            once(&mut wheel_load_kn, start..fields.wheel_loads_kn.len())
        }
        "creepage" => {
            let start = fields.creepages.len();
            scan.object(|scan, rail| {
                fields.creepages.push((rail, creepage_of(scan)?));
                Some(())
            })?;
            once(&mut creepage, start..fields.creepages.len())
        }
        _ => None,
    })?;
    fields.axles.push(AxleFields {
        offset_m: offset_m?,
        bogie_position: bogie_position?,
        wheel_diameter_m: wheel_diameter_m?,
        wheel_load_kn: wheel_load_kn?,
        creepage: creepage?,
        segments: None,
    });
    Some(())
}

/// One rail's creepage object.
fn creepage_of(scan: &mut Scan<'_>) -> Option<CreepageMsg> {
    let mut cx = None;
    let mut cy = None;
    let mut spin_per_m = None;
    scan.object(|scan, key| match key {
        "cx" => once(&mut cx, scan.number()?),
        "cy" => once(&mut cy, scan.number()?),
        "spin_per_m" => once(&mut spin_per_m, scan.number()?),
        _ => None,
    })?;
    Some(CreepageMsg {
        cx: cx?,
        cy: cy?,
        spin_per_m: spin_per_m?,
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
    /// A non-empty object: `field` reads each key's value.
    fn object(&mut self, mut field: impl FnMut(&mut Self, &'a str) -> Option<()>) -> Option<()> {
        self.byte(b'{')?;
        loop {
            let key = self.string()?;
            self.byte(b':')?;
            field(self, key)?;
            match self.next()? {
                b',' => {}
                b'}' => return Some(()),
                _ => return None,
            }
        }
    }

    /// A non-empty array: `item` reads each element.
    fn array(&mut self, mut item: impl FnMut(&mut Self) -> Option<()>) -> Option<()> {
        self.byte(b'[')?;
        loop {
            item(self)?;
            match self.next()? {
                b',' => {}
                b']' => return Some(()),
                _ => return None,
            }
        }
    }

    /// Nothing after the message's value.
    fn end(&self) -> Option<()> {
        (self.at == self.text.len()).then_some(())
    }

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

    /// A string that is one of `names` (an enum's wire names), as its value.
    fn name<T: Copy>(&mut self, names: &[(&str, T)]) -> Option<T> {
        let name = self.string()?;
        names
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, value)| value)
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

    /// A JSON number, converted by the function the full parse uses, or
    /// to the same double by one exact division ([`plain_decimal`]).
    fn number(&mut self) -> Option<f64> {
        if let Some((value, len)) = plain_decimal(&self.text.as_bytes()[self.at..]) {
            self.at += len;
            return Some(value);
        }
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

/// Digits of a plain decimal [`plain_decimal`] converts: 10^15 - 1 is
/// below 2^53, so each such integer is a double.
const PLAIN_DIGITS: usize = 15;

/// The number at the start of `bytes` and its length, where it is a plain
/// decimal `-?(0|[1-9][0-9]*)(\.[0-9]+)?` of at most [`PLAIN_DIGITS`]
/// digits that the next byte does not continue (no exponent, no second
/// point: the bytes [`Scan::number`]'s token would take are exactly these),
/// converted as serde_json converts it. Such a decimal is an integer below
/// 2^53 over a power of ten up to 10^15, both exact doubles, so their
/// quotient, rounded once, is the double nearest the decimal: what
/// serde_json returns (its `float_roundtrip` parse rounds correctly, and a
/// correctly rounded result is one double). Without a fraction it is the
/// integer itself, as serde's `as f64` gives it, and `-0` is -0.0 as in
/// serde. Anything else is `None`, for serde. serde_json's number parse
/// was a sixth of the reader thread's instructions on the 3-day benchmark
/// (measured 2026-12-05), read in one pass here.
fn plain_decimal(bytes: &[u8]) -> Option<(f64, usize)> {
    const POW10: [f64; PLAIN_DIGITS + 1] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
    ];
    let negative = bytes.first() == Some(&b'-');
    let mut at = usize::from(negative);
    // Wrapping: a number of more digits than a u64 holds is refused below.
    let mut units = 0u64;
    let mut digits = |at: &mut usize| {
        let start = *at;
        while let Some(&b) = bytes.get(*at).filter(|b| b.is_ascii_digit()) {
            units = units.wrapping_mul(10).wrapping_add(u64::from(b - b'0'));
            *at += 1;
        }
        *at - start
    };
    let int_start = at;
    let int = digits(&mut at);
    if int == 0 || (int > 1 && bytes[int_start] == b'0') {
        return None;
    }
    let mut fraction = 0;
    if bytes.get(at) == Some(&b'.') {
        at += 1;
        fraction = digits(&mut at);
        if fraction == 0 {
            return None;
        }
    }
    if int + fraction > PLAIN_DIGITS
        || matches!(bytes.get(at), Some(b'-' | b'+' | b'.' | b'e' | b'E'))
    {
        return None;
    }
    // Exact below 2^53; the division rounds once (by 1: not at all).
    let value = units as f64 / POW10[fraction];
    Some((if negative { -value } else { value }, at))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::parse;
    use crate::wire::{AxleMsg, MeasurementMsg, PassageMsg, PerRail, PulseMsg};

    /// Numbers as JSON has them and as it does not, for a number field.
    const NUMBERS: &[&str] = &[
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
        "{}",
    ];

    /// What serde_json's parse makes of `text` as a number field.
    fn serde_number(text: &str) -> Option<f64> {
        let mut json = serde_json::Deserializer::from_str(text);
        let value = number(&mut json).ok()?;
        json.end().ok()?;
        Some(value)
    }

    /// [`plain_decimal`]'s double is serde's, bit for bit (`{:?}` tells
    /// -0.0 from 0.0), where it gives one; it gives one for every plain
    /// decimal of up to 15 digits and for nothing serde refuses.
    fn plain_agrees(text: &str) {
        let plain = plain_decimal(text.as_bytes())
            .filter(|&(_, len)| len == text.len())
            .map(|(value, _)| value);
        let digits = text.bytes().filter(u8::is_ascii_digit).count();
        let grammar = {
            let unsigned = text.strip_prefix('-').unwrap_or(text);
            let (int, fraction) = unsigned.split_once('.').unwrap_or((unsigned, "1"));
            let leading_zero = int.len() > 1 && int.starts_with('0');
            let empty = int.is_empty() || fraction.is_empty();
            let all_digits = int
                .bytes()
                .chain(fraction.bytes())
                .all(|b| b.is_ascii_digit());
            !leading_zero && !empty && all_digits
        };
        assert_eq!(plain.is_some(), grammar && digits <= PLAIN_DIGITS, "{text}");
        if let Some(value) = plain {
            let serde = serde_number(text).unwrap_or_else(|| panic!("serde refuses {text}"));
            assert_eq!(
                value.to_bits(),
                serde.to_bits(),
                "{text}: {value:?} against {serde:?}"
            );
        }
    }

    /// Every decimal of up to four digits, the point anywhere, either sign;
    /// and the numbers the other tests use.
    #[test]
    fn short_decimals_are_serdes_doubles() {
        for n in 0..10_000u32 {
            for width in 1..=4usize {
                let digits = format!("{n:0width$}");
                if digits.len() > width {
                    continue;
                }
                for point in 0..=width {
                    let text = if point == width {
                        digits.clone()
                    } else {
                        format!("{}.{}", &digits[..point], &digits[point..])
                    };
                    plain_agrees(&text);
                    plain_agrees(&format!("-{text}"));
                }
            }
        }
        for text in NUMBERS {
            plain_agrees(text);
        }
        for text in [
            "999999999999999",
            "0.99999999999999",
            "99999999999999.9",
            "0.000000000000001",
            "-0.0",
            "-0",
            "1234567890123456",
            "0.1000000000000000",
            "2.675",
            "0.3",
            "1e5",
        ] {
            plain_agrees(text);
        }
    }

    proptest::proptest! {
        /// Decimals of 1 to 17 digits, the point anywhere, leading zeros
        /// after it (those over 15 digits go to serde).
        #[test]
        fn long_decimals_are_serdes_doubles(
            negative in proptest::bool::ANY,
            digits in "[1-9][0-9]{0,16}",
            point in 0usize..18,
            zeros in 0usize..4,
        ) {
            let point = point.min(digits.len());
            let int = if point == 0 { "0".to_string() } else { digits[..point].to_string() };
            let fraction = format!("{}{}", "0".repeat(zeros), &digits[point..]);
            let text = if fraction.len() > zeros || point == 0 {
                format!("{}{int}.{fraction}", if negative { "-" } else { "" })
            } else {
                format!("{}{int}", if negative { "-" } else { "" })
            };
            plain_agrees(&text);
        }
    }

    /// Every prefix of `base` (`true`), and `base` with each byte changed to
    /// each of a few that matter to the grammar (`false`).
    fn for_each_mutation(base: &[u8], mut check: impl FnMut(&[u8], bool)) {
        for end in 0..base.len() {
            check(&base[..end], true);
        }
        for at in 0..base.len() {
            for b in [
                b'"', b'\\', b',', b':', b'}', b'{', b'[', b']', b' ', b'0', b'e', b'-', b'n',
                0x01, 0xff,
            ] {
                let mut changed = base.to_vec();
                changed[at] = b;
                check(&changed, false);
            }
        }
    }

    /// Whatever a shortcut read from `data` (its fields printed, `read`),
    /// serde reads the same: `{:?}` shows every number exactly (`-0.0`
    /// too).
    fn agrees_with_serde<M: for<'de> crate::wire::json::FromJson<'de>>(
        data: &[u8],
        read: Option<String>,
        print: impl Fn(&M) -> String,
    ) {
        let Some(read) = read else {
            return;
        };
        let text = String::from_utf8_lossy(data);
        let msg = parse::<M>(data)
            .unwrap_or_else(|_| panic!("serde refuses what the compact reader took: {text}"));
        assert_eq!(read, print(&msg), "{text}");
    }

    /// `same` on every case and every mutation of `base`; the shortcut
    /// (`reads`) reads no prefix of `base`, and more than ten of the cases.
    fn each_case_and_mutation(
        cases: &[String],
        base: &[u8],
        same: impl Fn(&[u8]),
        reads: impl Fn(&[u8]) -> bool,
    ) {
        let mut read = 0;
        for case in cases {
            same(case.as_bytes());
            read += usize::from(reads(case.as_bytes()));
        }
        for_each_mutation(base, |case, prefix| {
            same(case);
            assert!(!prefix || !reads(case));
        });
        assert!(read > 10, "the shortcut read only {read} of the cases");
    }

    fn same(data: &[u8]) {
        agrees_with_serde::<MeasurementMsg>(
            data,
            compact_measurement(data).map(|f| format!("{f:?}")),
            |m| format!("{:?}", MeasurementFields::from(m)),
        );
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
        for v in NUMBERS {
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
        each_case_and_mutation(&cases, base, same, |d| compact_measurement(d).is_some());
    }

    fn same_pulse(data: &[u8]) {
        agrees_with_serde::<PulseMsg>(data, compact_pulse(data).map(|f| format!("{f:?}")), |m| {
            format!("{:?}", PulseFields::from(m))
        });
    }

    /// A pulse as written is read by the shortcut; its variations, byte by
    /// byte, agree with serde or are left to it.
    #[test]
    fn pulses_agree_with_serde_or_are_left_to_it() {
        for msg in [
            PulseMsg {
                applicator_id: "A1".into(),
                rail: "high".into(),
                mass_g: 0.2065,
            },
            PulseMsg {
                applicator_id: "wayside ü".into(),
                rail: "left".into(),
                mass_g: 0.0,
            },
        ] {
            let data = serde_json::to_vec(&msg).unwrap();
            let fields = compact_pulse(&data)
                .unwrap_or_else(|| panic!("not read: {}", String::from_utf8_lossy(&data)));
            assert_eq!(fields, PulseFields::from(&msg));
        }
        let base = br#"{"applicator_id":"A1","rail":"high","mass_g":0.2065}"#;
        let text = std::str::from_utf8(base).unwrap();
        let mut cases: Vec<String> = NUMBERS.iter().map(|v| text.replace("0.2065", v)).collect();
        cases.extend([
            text.replace(',', ", "),
            text.replace(",\"mass_g\":0.2065", ""),
            text.replace("\"rail\":\"high\"", "\"rail\":\"high\",\"rail\":\"low\""),
            text.replace("\"rail\":\"high\"", "\"extra\":1,\"rail\":\"high\""),
            text.replace("\"A1\"", "\"A\\u0031\""),
            text.replace("\"A1\"", "null"),
            r#"{"mass_g":1,"rail":"low","applicator_id":"A2"}"#.to_string(),
            "{}".to_string(),
        ]);
        each_case_and_mutation(&cases, base, same_pulse, |d| compact_pulse(d).is_some());
    }

    /// What serde makes of a passage's bytes, as fields, printed: `{:?}`
    /// shows every number exactly (`-0.0` too).
    fn passage_by_serde(data: &[u8]) -> Option<String> {
        let msg = parse::<PassageMsg>(data).ok()?;
        Some(format!("{:?}", PassageFields::from(&msg)))
    }

    fn same_passage(data: &[u8]) -> bool {
        let text = String::from_utf8_lossy(data);
        let Some(fields) = compact_passage(data) else {
            return false;
        };
        let expected = passage_by_serde(data)
            .unwrap_or_else(|| panic!("serde refuses what the compact reader took: {text}"));
        assert_eq!(format!("{fields:?}"), expected, "{text}");
        true
    }

    fn axle(offset_m: f64, rails: [&str; 2]) -> AxleMsg {
        let creepage = |cx: f64| CreepageMsg {
            cx,
            cy: -0.0004,
            spin_per_m: 0.18,
        };
        AxleMsg {
            offset_m,
            bogie_position: BogiePosition::Trailing,
            wheel_diameter_m: 0.92,
            wheel_load_kn: PerRail(vec![(rails[0].into(), 92.1), (rails[1].into(), 80.0)]),
            creepage: PerRail(vec![
                (rails[0].into(), creepage(0.005)),
                (rails[1].into(), creepage(-0.0)),
            ]),
            segments: None,
        }
    }

    /// The shape `tortwin synth` writes is read by the shortcut, and gives
    /// what serde gives; so does each axle's own shape after another.
    #[test]
    fn the_written_passage_is_read_and_agrees_with_serde() {
        let msg = PassageMsg {
            train_id: "F-00012".into(),
            direction: Direction::Down,
            speed_mps: 21.9,
            consist: Some("freight".into()),
            axles: vec![
                axle(2.45, ["high", "low"]),
                axle(4.95, ["low", "high"]),
                axle(1e-3, ["left ü", "right"]),
            ],
        };
        let data = serde_json::to_vec(&msg).unwrap();
        assert!(
            same_passage(&data),
            "not read: {}",
            String::from_utf8_lossy(&data)
        );
        let fields = compact_passage(&data).unwrap();
        assert_eq!(fields.axles.len(), 3);
        assert_eq!(
            fields.wheel_loads_kn[fields.axles[1].wheel_load_kn.clone()][0],
            ("low", 92.1)
        );
        let without = PassageMsg {
            consist: None,
            ..msg
        };
        assert!(same_passage(&serde_json::to_vec(&without).unwrap()));
    }

    /// Variations of the shape: whatever the shortcut reads, serde reads
    /// the same; whatever serde refuses, the shortcut leaves to it.
    #[test]
    fn passage_variations_agree_with_serde_or_are_left_to_it() {
        let base = br#"{"train_id":"P-1","direction":"up","speed_mps":20.5,"consist":"passenger","axles":[{"offset_m":2.5,"bogie_position":"leading","wheel_diameter_m":0.9,"wheel_load_kN":{"high":92.1,"low":80.6},"creepage":{"high":{"cx":0.005,"cy":0.004,"spin_per_m":0.18},"low":{"cx":-0.005,"cy":0.004,"spin_per_m":-0.1}}}]}"#;
        let text = std::str::from_utf8(base).unwrap();
        let strings = [
            "\"\"",
            "\"a\\\"b\"",
            "\"a\\u0041\"",
            "\"tab\there\"",
            "null",
            "1",
            "\"ü\"",
            "\"down\"",
            "\"trailing\"",
            "\"Up\"",
        ];
        let mut cases: Vec<String> = Vec::new();
        for v in NUMBERS {
            for field in ["20.5", "2.5", "0.9", "92.1", "0.005", "-0.1"] {
                cases.push(text.replacen(field, v, 1));
            }
        }
        for v in strings {
            for field in [
                "\"P-1\"",
                "\"up\"",
                "\"leading\"",
                "\"passenger\"",
                "\"low\"",
            ] {
                cases.push(text.replacen(field, v, 1));
            }
        }
        let axle = &text[text.find("[{").unwrap() + 1..text.rfind("}]").unwrap() + 1];
        cases.extend([
            // More axles, none, an axle that is not an object.
            text.replace(axle, &format!("{axle},{axle},{axle}")),
            text.replace(axle, ""),
            text.replace(axle, "1"),
            text.replace(axle, &format!("{axle},")),
            text.replace(axle, &format!("[{axle}]")),
            // Whitespace, order, repeats, unknown, missing and skipped keys.
            text.replace(',', ", "),
            text.replace(':', " : "),
            format!(" {text}"),
            format!("{text} "),
            format!("{text}x"),
            text.replace(",\"consist\":\"passenger\"", ""),
            text.replace("\"consist\":\"passenger\"", "\"consist\":\"a\",\"consist\":\"b\""),
            text.replace("\"consist\":\"passenger\"", "\"consist\":{\"cars\":3}"),
            text.replace("\"consist\":\"passenger\"", "\"extra\":1"),
            text.replace("\"direction\":\"up\"", "\"direction\":\"up\",\"direction\":\"down\""),
            text.replace("\"speed_mps\":20.5,", ""),
            text.replace("\"train_id\":\"P-1\",", ""),
            text.replace("\"offset_m\":2.5,", ""),
            text.replace("\"offset_m\":2.5,", "\"offset_m\":2.5,\"offset_m\":2.5,"),
            text.replace("\"bogie_position\":\"leading\",", ""),
            text.replace("\"wheel_diameter_m\":0.9,", "\"wheel_diameter_m\":0.9,\"segments\":{}"),
            text.replace("\"wheel_diameter_m\":0.9,", "\"wheel_diameter_m\":0.9,\"segments\":null,"),
            text.replace("\"wheel_diameter_m\":0.9,", "\"wheel_diameter_m\":0.9,\"segments\":{\"S1\":1},"),
            text.replace(
                "\"wheel_diameter_m\":0.9,",
                "\"wheel_diameter_m\":0.9,\"segments\":{\"S1\":{\"wheel_load_kN\":{\"high\":1,\"low\":2}}},",
            ),
            text.replace("\"wheel_diameter_m\":0.9,", "\"wheel_diameter_m\":0.9,\"x\":0,"),
            // Per-rail maps: empty, a rail twice, a rail missing, arrays.
            text.replace("{\"high\":92.1,\"low\":80.6}", "{}"),
            text.replace("{\"high\":92.1,\"low\":80.6}", "{\"high\":92.1,\"high\":80.6}"),
            text.replace("{\"high\":92.1,\"low\":80.6}", "{\"high\":92.1}"),
            text.replace("{\"high\":92.1,\"low\":80.6}", "[92.1,80.6]"),
            text.replace("\"cx\":0.005,", ""),
            text.replace("\"cx\":0.005,", "\"cx\":0.005,\"cx\":0.005,"),
            text.replace("\"cx\":0.005,", "\"cz\":0.005,"),
            text.replace("{\"cx\":0.005,\"cy\":0.004,\"spin_per_m\":0.18}", "[0.005,0.004,0.18]"),
            text.replace("{\"cx\":0.005,\"cy\":0.004,\"spin_per_m\":0.18}", "{}"),
            "{}".to_string(),
            "[]".to_string(),
            String::new(),
        ]);
        let mut read = 0;
        for case in &cases {
            read += usize::from(same_passage(case.as_bytes()));
        }
        for_each_mutation(base, |case, prefix| {
            assert!(!same_passage(case) || !prefix);
        });
        assert!(
            read > 40,
            "the shortcut read only {read} of the {} cases",
            cases.len()
        );
    }
}
