//! The OpenIGTLink messages the server reads and writes, encoded and decoded as the OpenIGTLink
//! specification lays them out (the protocol of 3D Slicer's OpenIGTLinkIF, PLUS and pyigtl).
//!
//! Wire format, every number big-endian:
//! - header, 58 bytes: version `u16` (1: the body is the content; 2: the body is an extended
//!   header, the content and metadata), type name (12 bytes, NUL-padded ASCII, e.g. `POINT`),
//!   device name (20 bytes, NUL-padded), timestamp `u64` (seconds since the Unix epoch in the upper
//!   32 bits, the fraction of a second in units of 2⁻³² s in the lower 32), body size `u64`, CRC
//!   `u64` of the body ([`crc64`]);
//! - body, header version 2: the extended header (its own size `u16`, at least 12; the metadata
//!   header's size `u16`; the metadata's size `u32`; a message id `u32`), the content, the
//!   metadata header, the metadata;
//! - content ([`Content`]): POINT ([`PointMessage`]), STRING ([`StringMessage`]), TRANSFORM
//!   ([`TransformMessage`]) here, POLYDATA in [`crate::polydata`].
//!
//! Messages are written with header version 1, which every OpenIGTLink application reads, and
//! read with header version 1 or 2. A malformed message is an error that says what is wrong,
//! never a panic.

/// The content of a message of one type: its bytes between the header (or the extended header)
/// and the metadata.
pub trait Content: Sized {
    /// The message type written in the header (e.g. `POINT`).
    const TYPE: &'static str;
    /// The content as bytes on the wire; an error when it does not fit the format.
    fn encode(&self) -> Result<Vec<u8>, String>;
    /// The content from its bytes; an error that says why when they are malformed.
    fn decode(content: &[u8]) -> Result<Self, String>;
}

/// The header that precedes every message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Header {
    /// Header version: 1 (body = content) or 2 (extended header, content, metadata).
    pub version: u16,
    /// Message type (at most 12 bytes, e.g. `POLYDATA`).
    pub type_name: String,
    /// Device name (at most 20 bytes, e.g. `cloud`).
    pub device_name: String,
    /// Seconds since the Unix epoch (upper 32 bits) and fraction of a second in units of 2⁻³² s
    /// (lower 32 bits).
    pub timestamp: u64,
    /// Bytes of the body that follows.
    pub body_size: u64,
    /// CRC-64 of the body ([`crc64`]).
    pub crc: u64,
}

/// Bytes of the type name field.
const TYPE_BYTES: usize = 12;
/// Bytes of the device name field.
const DEVICE_BYTES: usize = 20;

impl Header {
    /// Bytes of a header on the wire.
    pub const SIZE: usize = 58;

    /// The version 1 header of a message of `type_name` from `device_name` with `body`,
    /// timestamped now.
    pub fn new(type_name: &str, device_name: &str, body: &[u8]) -> Header {
        let since_epoch = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        Header {
            version: 1,
            type_name: type_name.to_string(),
            device_name: device_name.to_string(),
            timestamp: timestamp(since_epoch),
            body_size: body.len() as u64,
            crc: crc64(body),
        }
    }

    /// The header as bytes on the wire; an error when a name is too long for its field.
    pub fn encode(&self) -> Result<[u8; Header::SIZE], String> {
        let mut out = [0u8; Header::SIZE];
        out[..2].copy_from_slice(&self.version.to_be_bytes());
        write_name(&mut out[2..2 + TYPE_BYTES], "type", &self.type_name)?;
        write_name(&mut out[14..14 + DEVICE_BYTES], "device", &self.device_name)?;
        out[34..42].copy_from_slice(&self.timestamp.to_be_bytes());
        out[42..50].copy_from_slice(&self.body_size.to_be_bytes());
        out[50..58].copy_from_slice(&self.crc.to_be_bytes());
        Ok(out)
    }

    /// The header from the first [`Header::SIZE`] bytes of `bytes`; an error when there are fewer
    /// or its version is neither 1 nor 2 (OpenIGTLink 3 sends version 2 headers).
    pub fn decode(bytes: &[u8]) -> Result<Header, String> {
        let bytes: &[u8; Header::SIZE] = bytes
            .get(..Header::SIZE)
            .and_then(|b| b.try_into().ok())
            .ok_or_else(|| format!("a header of {} bytes, {} expected", bytes.len(), Header::SIZE))?;
        let u64_at = |at: usize| u64::from_be_bytes(std::array::from_fn(|k| bytes[at + k]));
        let version = u16::from_be_bytes([bytes[0], bytes[1]]);
        if !matches!(version, 1 | 2) {
            return Err(format!("header version {version}: OpenIGTLink headers are of version 1 or 2"));
        }
        Ok(Header {
            version,
            type_name: read_name(&bytes[2..2 + TYPE_BYTES]),
            device_name: read_name(&bytes[14..14 + DEVICE_BYTES]),
            timestamp: u64_at(34),
            body_size: u64_at(42),
            crc: u64_at(50),
        })
    }
}

/// The header's timestamp of a time since the Unix epoch: the whole seconds modulo 2³² (the
/// field's width) in the upper 32 bits, the nanoseconds in units of 2⁻³² s in the lower.
fn timestamp(since_epoch: std::time::Duration) -> u64 {
    (since_epoch.as_secs() << 32) | ((u64::from(since_epoch.subsec_nanos()) << 32) / 1_000_000_000)
}

/// A header's timestamp in seconds since the Unix epoch, as pyigtl gives it
/// (`message.timestamp`): the upper 32 bits whole seconds, the lower a fraction of 2³².
pub fn timestamp_seconds(timestamp: u64) -> f64 {
    (timestamp >> 32) as f64 + (timestamp & 0xffff_ffff) as f64 / 4_294_967_296.0
}

/// Writes `name` into its NUL-padded `field`; an error when it is longer than the field.
fn write_name(field: &mut [u8], what: &str, name: &str) -> Result<(), String> {
    if name.len() > field.len() {
        return Err(format!("{what} name '{name}' is longer than {} bytes", field.len()));
    }
    field[..name.len()].copy_from_slice(name.as_bytes());
    Ok(())
}

/// The text of a NUL-padded `field`, up to its first NUL. A byte that is not UTF-8 (a Latin-1
/// name, a character cut at the field's end) becomes U+FFFD: names label, they do not decide.
fn read_name(field: &[u8]) -> String {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end]).into_owned()
}

/// The generator polynomial of OpenIGTLink's CRC-64 (ECMA-182).
const CRC_POLYNOMIAL: u64 = 0x42F0_E1EB_A9EA_3693;

/// The CRC of each byte value, for [`crc64`].
const CRC_TABLE: [u64; 256] = {
    let mut table = [0u64; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut crc = (byte as u64) << 56;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc >> 63 == 1 { (crc << 1) ^ CRC_POLYNOMIAL } else { crc << 1 };
            bit += 1;
        }
        table[byte] = crc;
        byte += 1;
    }
    table
};

/// OpenIGTLink's CRC-64 of `data`: polynomial 0x42F0E1EBA9EA3693 (ECMA-182), initial value 0,
/// bits not reflected, no final xor.
pub fn crc64(data: &[u8]) -> u64 {
    data.iter().fold(0, |crc, &byte| CRC_TABLE[usize::from(byte ^ (crc >> 56) as u8)] ^ (crc << 8))
}

/// A message as bytes on the wire: a version 1 header (no extended header, what every
/// OpenIGTLink application reads), timestamped now, then the content.
pub fn encode_message<T: Content>(content: &T, device: &str) -> Result<Vec<u8>, String> {
    encode_message_stamped(content, device, None)
}

/// [`encode_message`] with the header's `timestamp` given (that of the message it answers);
/// timestamped now for `None`.
pub fn encode_message_stamped<T: Content>(
    content: &T,
    device: &str,
    timestamp: Option<u64>,
) -> Result<Vec<u8>, String> {
    let body = content.encode().map_err(|e| format!("encoding a {} message: {e}", T::TYPE))?;
    let mut header = Header::new(T::TYPE, device, &body);
    if let Some(timestamp) = timestamp {
        header.timestamp = timestamp;
    }
    Ok([&header.encode()?[..], &body].concat())
}

/// The content of a message of type `T` from its header and body: the CRC checked, the
/// content taken from between the extended header and the metadata for header version 2 or
/// later (the whole body for version 1), then decoded. Errors say what is wrong.
pub fn decode_body<T: Content>(header: &Header, body: &[u8]) -> Result<T, String> {
    let kind = T::TYPE;
    if crc64(body) != header.crc {
        return Err(format!("{kind} message: CRC mismatch"));
    }
    let content = if header.version < 2 {
        body
    } else {
        let field =
            |at: usize, n: usize| body.get(at..at + n).map(|b| b.iter().fold(0usize, |v, &x| v << 8 | x as usize));
        let bad = || format!("{kind} message: malformed extended header");
        let (ext, meta_header, meta) =
            (field(0, 2).ok_or_else(bad)?, field(2, 2).ok_or_else(bad)?, field(4, 4).ok_or_else(bad)?);
        let end = body.len().checked_sub(meta_header).and_then(|e| e.checked_sub(meta)).ok_or_else(bad)?;
        if ext < 12 || ext > end {
            return Err(bad());
        }
        &body[ext..end]
    };
    T::decode(content).map_err(|e| format!("malformed {kind} message: {e}"))
}

/// The first `N` big-endian `f32`s of `bytes` (at least `4 N` bytes long).
fn read_f32s<const N: usize>(bytes: &[u8]) -> [f32; N] {
    std::array::from_fn(|k| f32::from_be_bytes([bytes[4 * k], bytes[4 * k + 1], bytes[4 * k + 2], bytes[4 * k + 3]]))
}

/// One point of a POINT message.
#[derive(Clone, Debug, PartialEq)]
pub struct PointElement {
    /// Its name (at most 63 bytes are sent).
    pub name: String,
    /// Its group (at most 31 bytes are sent).
    pub group: String,
    /// Its colour, red, green, blue and opacity.
    pub rgba: [u8; 4],
    /// Its position.
    pub position: [f32; 3],
    /// Its diameter.
    pub diameter: f32,
    /// The device that owns it (at most 19 bytes are sent).
    pub owner: String,
}

impl PointElement {
    /// A white, opaque point of diameter 0 and no owner.
    pub fn new(name: impl Into<String>, group: impl Into<String>, position: [f32; 3]) -> PointElement {
        PointElement {
            name: name.into(),
            group: group.into(),
            rgba: [255; 4],
            position,
            diameter: 0.0,
            owner: String::new(),
        }
    }
}

/// A POINT message: a list of points, each in 136 bytes (name 64, group 32, RGBA 4, position
/// 3 × `f32`, diameter `f32`, owner 20; the texts NUL-terminated).
#[derive(Clone, Debug, PartialEq)]
pub struct PointMessage {
    /// The points.
    pub points: Vec<PointElement>,
}

/// Bytes of one point of a POINT message.
const POINT_BYTES: usize = 136;

/// Bytes of a POINT message's point name, its last a NUL: a longer name is cut ([`sent_text`]).
pub const POINT_NAME_BYTES: usize = 64;

/// What of `text` a NUL-padded field of `bytes` bytes holds: `text` cut at a character boundary
/// so as to keep the last byte a NUL.
pub fn sent_text(text: &str, bytes: usize) -> &str {
    let mut end = text.len().min(bytes - 1);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// Writes `text` into its NUL-padded `field` ([`sent_text`]).
fn write_text(field: &mut [u8], text: &str) {
    let sent = sent_text(text, field.len());
    field[..sent.len()].copy_from_slice(sent.as_bytes());
}

impl Content for PointMessage {
    const TYPE: &'static str = "POINT";

    fn encode(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::with_capacity(POINT_BYTES * self.points.len());
        for point in &self.points {
            let mut bytes = [0u8; POINT_BYTES];
            write_text(&mut bytes[..POINT_NAME_BYTES], &point.name);
            write_text(&mut bytes[64..96], &point.group);
            bytes[96..100].copy_from_slice(&point.rgba);
            for (k, x) in point.position.iter().chain([&point.diameter]).enumerate() {
                bytes[100 + 4 * k..104 + 4 * k].copy_from_slice(&x.to_be_bytes());
            }
            write_text(&mut bytes[116..], &point.owner);
            out.extend_from_slice(&bytes);
        }
        Ok(out)
    }

    fn decode(content: &[u8]) -> Result<PointMessage, String> {
        if !content.len().is_multiple_of(POINT_BYTES) {
            return Err(format!("{} bytes, not a whole number of {POINT_BYTES}-byte points", content.len()));
        }
        let points = content
            .chunks_exact(POINT_BYTES)
            .map(|bytes| {
                let [x, y, z, diameter] = read_f32s(&bytes[100..116]);
                PointElement {
                    name: read_name(&bytes[..64]),
                    group: read_name(&bytes[64..96]),
                    rgba: [bytes[96], bytes[97], bytes[98], bytes[99]],
                    position: [x, y, z],
                    diameter,
                    owner: read_name(&bytes[116..]),
                }
            })
            .collect();
        Ok(PointMessage { points })
    }
}

/// A STRING message: a text with its character encoding (IANA MIBenum: 3 US-ASCII, 106 UTF-8),
/// sent as the encoding `u16`, the length in bytes `u16`, then the bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StringMessage {
    /// The character encoding, as an IANA MIBenum.
    pub encoding: u16,
    /// The text.
    pub text: String,
}

impl StringMessage {
    /// A UTF-8 text.
    pub fn utf8(text: impl Into<String>) -> StringMessage {
        StringMessage { encoding: 106, text: text.into() }
    }
}

impl Content for StringMessage {
    const TYPE: &'static str = "STRING";

    fn encode(&self) -> Result<Vec<u8>, String> {
        let length = u16::try_from(self.text.len())
            .map_err(|_| format!("a text of {} bytes, longer than the {} a STRING holds", self.text.len(), u16::MAX))?;
        Ok([&self.encoding.to_be_bytes()[..], &length.to_be_bytes(), self.text.as_bytes()].concat())
    }

    fn decode(content: &[u8]) -> Result<StringMessage, String> {
        let [e0, e1, l0, l1, rest @ ..] = content else {
            return Err(format!("{} bytes, shorter than the 4 of the encoding and length", content.len()));
        };
        let length = usize::from(u16::from_be_bytes([*l0, *l1]));
        let bytes =
            rest.get(..length).ok_or_else(|| format!("a text of {length} bytes announced, {} sent", rest.len()))?;
        let text = String::from_utf8(bytes.to_vec()).map_err(|_| "the text is not UTF-8".to_string())?;
        Ok(StringMessage { encoding: u16::from_be_bytes([*e0, *e1]), text })
    }
}

/// A TRANSFORM message: a rigid or affine transform, sent as 12 `f32`: the 3 × 3 upper-left
/// block column by column, then the translation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransformMessage {
    /// The homogeneous matrix, row-major (its last row is `0 0 0 1`, not sent).
    pub matrix: [[f32; 4]; 4],
}

/// Bytes of a TRANSFORM message's content.
const TRANSFORM_BYTES: usize = 48;

impl Content for TransformMessage {
    const TYPE: &'static str = "TRANSFORM";

    fn encode(&self) -> Result<Vec<u8>, String> {
        let columns = (0..4).flat_map(|col| (0..3).map(move |row| (row, col)));
        Ok(columns.flat_map(|(row, col)| self.matrix[row][col].to_be_bytes()).collect())
    }

    fn decode(content: &[u8]) -> Result<TransformMessage, String> {
        if content.len() != TRANSFORM_BYTES {
            return Err(format!("{} bytes, {TRANSFORM_BYTES} expected", content.len()));
        }
        let values: [f32; 12] = read_f32s(content);
        let mut matrix = [[0.0, 0.0, 0.0, 1.0]; 4];
        for (k, value) in values.into_iter().enumerate() {
            matrix[k % 3][k / 3] = value;
        }
        Ok(TransformMessage { matrix })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polydata::PolyData;

    // Messages as the reference encoder wrote them (header version 1), their timestamp zeroed;
    // each header on three lines (version and type; device; timestamp, body size and CRC), then
    // the body.

    /// A TRANSFORM header, timestamp 0x65432101.89abcdef, body of 48 bytes, CRC 0x0123456789abcdef.
    const HEADER: &str = concat!(
        "00015452414e53464f524d000000",
        "7269676964000000000000000000000000000000",
        "6543210189abcdef00000000000000300123456789abcdef",
    );

    /// POINT `targets`: `target 1` at (1.5, -2.25, 3) and `target 2` at (1000, 0, -7.125), group `targets`.
    const POINT: &str = concat!(
        "0001504f494e5400000000000000",
        "7461726765747300000000000000000000000000",
        "00000000000000000000000000000110b41325b9e651f579",
        "746172676574203100000000000000000000000000000000000000000000000000000000000000000000000000000000",
        "000000000000000000000000000000007461726765747300000000000000000000000000000000000000000000000000",
        "ffffffff3fc00000c0100000404000000000000000000000000000000000000000000000000000007461726765742032",
        "000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000",
        "00000000000000007461726765747300000000000000000000000000000000000000000000000000ffffffff447a0000",
        "00000000c0e40000000000000000000000000000000000000000000000000000",
    );

    /// POINT `features`: one point with a name, group and owner longer than their fields (70, 40 and 25
    /// bytes), colour (1, 2, 3, 4), position (-0.5, 0.25, 8), diameter 2.5.
    const POINT_LONG: &str = concat!(
        "0001504f494e5400000000000000",
        "6665617475726573000000000000000000000000",
        "000000000000000000000000000000889d033f8b50ca4999",
        "6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e",
        "6e6e6e6e6e6e6e6e6e6e6e6e6e6e6e006767676767676767676767676767676767676767676767676767676767676700",
        "01020304bf0000003e80000041000000402000006f6f6f6f6f6f6f6f6f6f6f6f6f6f6f6f6f6f6f00",
    );

    /// STRING `status`: `{"frame":1,"error":"déjà vu"}` in UTF-8.
    const STRING: &str = concat!(
        "0001535452494e47000000000000",
        "7374617475730000000000000000000000000000",
        "0000000000000000000000000000002372cdfec1b91576fb",
        "006a001f7b226672616d65223a312c226572726f72223a2264c3a96ac3a0207675227d",
    );

    /// TRANSFORM `rigid`: rows (1 2 3 4), (5 6 7 8), (9 10 11 12).
    const TRANSFORM: &str = concat!(
        "00015452414e53464f524d000000",
        "7269676964000000000000000000000000000000",
        "00000000000000000000000000000030040e4bc21087a0bf",
        "3f80000040a00000411000004000000040c00000412000004040000040e0000041300000408000004100000041400000",
    );

    /// POLYDATA `organ`: points (0, 1, 2), (3, 4, 5), (6, 7, 8.5) and their triangle.
    const POLYDATA: &str = concat!(
        "0001504f4c594441544100000000",
        "6f7267616e000000000000000000000000000000",
        "0000000000000000000000000000005cb1ada060999f3843",
        "00000003000000000000000000000000000000000000000100000010000000000000000000000000000000003f800000",
        "40000000404000004080000040a0000040c0000040e000004108000000000003000000000000000100000002",
    );

    fn bytes(hex: &str) -> Vec<u8> {
        (0..hex.len()).step_by(2).map(|k| u8::from_str_radix(&hex[k..k + 2], 16).unwrap()).collect()
    }

    /// Encodes `content`, checks the bytes against `expected` (but for the timestamp, which must
    /// be now), then decodes them back.
    fn round_trip<T: Content + PartialEq + std::fmt::Debug>(content: &T, device: &str, expected: &str) {
        let mut wire = encode_message(content, device).unwrap();
        let header = Header::decode(&wire).unwrap();
        let now = timestamp(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap());
        assert!((now >> 32) - (header.timestamp >> 32) < 60, "timestamped now");
        wire[34..42].fill(0);
        assert_eq!(wire, bytes(expected), "{} bytes", T::TYPE);
        assert_eq!((header.type_name.as_str(), header.device_name.as_str()), (T::TYPE, device));
        assert_eq!(header.body_size as usize, wire.len() - Header::SIZE);
        assert_eq!(&decode_body::<T>(&header, &wire[Header::SIZE..]).unwrap(), content);
    }

    #[test]
    fn the_crc_is_openigtlinks_crc64() {
        assert_eq!(CRC_TABLE[1], CRC_POLYNOMIAL);
        // The check value of CRC-64/ECMA-182, then values of the reference implementation.
        assert_eq!(crc64(b"123456789"), 0x6c40_df5f_0b49_7347);
        assert_eq!(crc64(b""), 0);
        assert_eq!(crc64(b"\0"), 0);
        assert_eq!(crc64(b"OpenIGTLink"), 0x7079_2326_f2a3_8ce7);
        assert_eq!(crc64(&(0..=255).collect::<Vec<u8>>()), 0x62b0_da1c_1b13_0a91);
    }

    #[test]
    fn headers_are_written_and_read_as_the_reference_does() {
        let header = Header {
            version: 1,
            type_name: "TRANSFORM".into(),
            device_name: "rigid".into(),
            timestamp: 0x6543_2101_89ab_cdef,
            body_size: 48,
            crc: 0x0123_4567_89ab_cdef,
        };
        assert_eq!(header.encode().unwrap().to_vec(), bytes(HEADER));
        assert_eq!(Header::decode(&bytes(HEADER)).unwrap(), header);
        assert_eq!(timestamp(std::time::Duration::new(1000, 500_000_000)), 1000 << 32 | 0x8000_0000);
        assert_eq!(timestamp_seconds(1000 << 32 | 0x8000_0000), 1000.5);
        // A full-length device name fills its field without a NUL.
        let full = Header { device_name: "d".repeat(20), ..header.clone() };
        assert_eq!(Header::decode(&full.encode().unwrap()).unwrap(), full);

        let long = Header { device_name: "d".repeat(21), ..header.clone() };
        assert!(long.encode().unwrap_err().contains("longer than 20 bytes"));
        let long = Header { type_name: "TRANSFORMATION".into(), ..header };
        assert!(long.encode().unwrap_err().contains("longer than 12 bytes"));
        assert!(Header::decode(&bytes(HEADER)[..57]).unwrap_err().contains("57 bytes, 58 expected"));
        // A name that is not UTF-8 is read, its bad byte replaced; a version other than 1 or 2 is
        // refused.
        let mut not_text = bytes(HEADER);
        not_text[2] = 0xff;
        assert!(Header::decode(&not_text).unwrap().type_name.starts_with('\u{FFFD}'));
        for version in [0u16, 3] {
            let mut other = bytes(HEADER);
            other[..2].copy_from_slice(&version.to_be_bytes());
            let e = Header::decode(&other).unwrap_err();
            assert!(e.contains(&format!("header version {version}: OpenIGTLink headers are of version 1 or 2")), "{e}");
        }
    }

    #[test]
    fn messages_are_the_bytes_of_the_reference_encoder() {
        let targets = PointMessage {
            points: vec![
                PointElement::new("target 1", "targets", [1.5, -2.25, 3.0]),
                PointElement::new("target 2", "targets", [1000.0, 0.0, -7.125]),
            ],
        };
        round_trip(&targets, "targets", POINT);
        round_trip(&StringMessage::utf8(r#"{"frame":1,"error":"déjà vu"}"#), "status", STRING);
        let matrix = [[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0], [9.0, 10.0, 11.0, 12.0], [0.0, 0.0, 0.0, 1.0]];
        round_trip(&TransformMessage { matrix }, "rigid", TRANSFORM);
        let organ =
            PolyData { points: vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.5]], triangles: vec![[0, 1, 2]] };
        round_trip(&organ, "organ", POLYDATA);

        // Texts longer than their fields are cut, keeping a final NUL.
        let long = PointElement {
            name: "n".repeat(70),
            group: "g".repeat(40),
            rgba: [1, 2, 3, 4],
            position: [-0.5, 0.25, 8.0],
            diameter: 2.5,
            owner: "o".repeat(25),
        };
        let cut = PointElement { name: "n".repeat(63), group: "g".repeat(31), owner: "o".repeat(19), ..long.clone() };
        let mut wire = encode_message(&PointMessage { points: vec![long] }, "features").unwrap();
        wire[34..42].fill(0);
        assert_eq!(wire, bytes(POINT_LONG));
        let header = Header::decode(&wire).unwrap();
        assert_eq!(decode_body::<PointMessage>(&header, &wire[Header::SIZE..]).unwrap().points, [cut]);
        // A text is cut at a character boundary.
        for (text, written) in [("aéb", [b'a', 0xc3, 0xa9, 0]), ("aaé", [b'a', b'a', 0, 0])] {
            let mut field = [0u8; 4];
            write_text(&mut field, text);
            assert_eq!(field, written, "{text}");
        }
    }

    /// A header version 2 body: extended header, `content`, metadata header and metadata.
    fn version_2(content: &[u8]) -> (Header, Vec<u8>) {
        let (metadata_header, metadata) = (&[0u8, 1, 0, 4, 0, 3, 0, 0, 0, 2][..], &b"unitmm"[..]);
        let mut body = Vec::new();
        body.extend_from_slice(&12u16.to_be_bytes());
        body.extend_from_slice(&(metadata_header.len() as u16).to_be_bytes());
        body.extend_from_slice(&(metadata.len() as u32).to_be_bytes());
        body.extend_from_slice(&7u32.to_be_bytes());
        body.extend_from_slice(content);
        body.extend_from_slice(metadata_header);
        body.extend_from_slice(metadata);
        (Header { version: 2, ..Header::new("TRANSFORM", "rigid", &body) }, body)
    }

    #[test]
    fn version_2_bodies_are_read_past_their_extended_header_and_metadata() {
        let content = bytes(TRANSFORM)[Header::SIZE..].to_vec();
        let (header, body) = version_2(&content);
        let expected = TransformMessage::decode(&content).unwrap();
        assert_eq!(decode_body::<TransformMessage>(&header, &body).unwrap(), expected);

        let resealed = |body: &[u8]| (Header { crc: crc64(body), ..header.clone() }, body.to_vec());
        for (at, value) in [(0, 11u8), (1, 200), (3, 200), (7, 255)] {
            let mut bad = body.clone();
            bad[at] = value;
            let (h, b) = resealed(&bad);
            let e = decode_body::<TransformMessage>(&h, &b).unwrap_err();
            assert_eq!(e, "TRANSFORM message: malformed extended header", "byte {at} = {value}");
        }
        let (h, b) = resealed(&body[..7]);
        assert!(decode_body::<TransformMessage>(&h, &b).unwrap_err().contains("malformed extended header"));
        let mut corrupted = body.clone();
        corrupted[20] ^= 1;
        assert!(decode_body::<TransformMessage>(&header, &corrupted).unwrap_err().contains("CRC mismatch"));
    }

    #[test]
    fn malformed_contents_are_errors_that_say_why() {
        let content = |hex: &str| bytes(hex)[Header::SIZE..].to_vec();
        let point = content(POINT);
        assert!(PointMessage::decode(&point[..200]).unwrap_err().contains("not a whole number of 136-byte points"));
        // A Latin-1 group name (é) is read, its byte replaced: names label, they do not decide.
        let mut not_text = point.clone();
        not_text[136 + 64] = 0xe9;
        let read = PointMessage::decode(&not_text).unwrap();
        assert!(read.points[1].group.starts_with('\u{FFFD}'), "{:?}", read.points[1].group);
        assert!(PointMessage::decode(&[]).unwrap().points.is_empty());

        let text = content(STRING);
        assert!(StringMessage::decode(&text[..3]).unwrap_err().contains("shorter than the 4"));
        assert!(StringMessage::decode(&text[..20]).unwrap_err().contains("31 bytes announced, 16 sent"));
        let mut not_utf8 = text.clone();
        not_utf8[4] = 0xff;
        assert!(StringMessage::decode(&not_utf8).unwrap_err().contains("not UTF-8"));
        let huge = StringMessage::utf8("x".repeat(70_000));
        assert!(encode_message(&huge, "status").unwrap_err().contains("longer than the 65535"));

        let transform = content(TRANSFORM);
        assert!(TransformMessage::decode(&transform[..47]).unwrap_err().contains("47 bytes, 48 expected"));
        assert!(encode_message(&TransformMessage { matrix: [[0.0; 4]; 4] }, "a device name of 25 bytes")
            .unwrap_err()
            .contains("longer than 20 bytes"));
    }

    /// Every truncation and every single-byte change of each message is decoded without a panic.
    #[test]
    fn no_malformed_content_panics() {
        fn each_variant(hex: &str, decode: impl Fn(&[u8]) -> bool) {
            let content = bytes(hex)[Header::SIZE..].to_vec();
            for n in 0..content.len() {
                decode(&content[..n]);
            }
            for at in 0..content.len() {
                for value in [0, 1, 3, 0x7f, 0x80, 0xff] {
                    let mut changed = content.clone();
                    changed[at] = value;
                    decode(&changed);
                }
            }
        }
        each_variant(POINT, |b| PointMessage::decode(b).is_ok());
        each_variant(STRING, |b| StringMessage::decode(b).is_ok());
        each_variant(TRANSFORM, |b| TransformMessage::decode(b).is_ok());
        each_variant(POLYDATA, |b| PolyData::decode(b).is_ok());
        let (header, body) = version_2(&bytes(TRANSFORM)[Header::SIZE..]);
        for n in 0..body.len() {
            let header = Header { crc: crc64(&body[..n]), ..header.clone() };
            assert!(decode_body::<TransformMessage>(&header, &body[..n]).is_err());
        }
    }
}
