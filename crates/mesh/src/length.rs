//! Length units of the coordinates users give and get back.
//!
//! augsim computes in metres. Coordinates read from a user (surfaces, clouds, targets, landmarks,
//! streamed points) are in a [`LengthUnit`]: millimetres, as medical images and 3D Slicer use,
//! metres, centimetres (some surface exports) or micrometres (as Slicer's markups may name). Every front (command line, server, Python) parses it with [`LengthUnit::from_str`]
//! and takes [`LengthUnit::DEFAULT`], the metre, when none is given; a file that names its unit
//! (`.fcsv`, `.mrk.json`, a CSV header `x_mm`) is read in its own. Where an organ's surface is
//! read, `auto` ([`parse_unit_or_auto`]) tells the unit from the organ's size instead.

use std::fmt;
use std::str::FromStr;

use crate::Point;

/// A length unit of coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum LengthUnit {
    /// Metres (augsim's unit), `m`.
    Metre,
    /// Centimetres (the unit of some surface exports), `cm`.
    Centimetre,
    /// Millimetres (the usual unit of medical images and of 3D Slicer), `mm`.
    Millimetre,
    /// Micrometres, `um` (as Slicer's markups write it; `µm` is read too).
    Micrometre,
}

impl LengthUnit {
    /// The unit of coordinates when none is given, on every front: the metre, the unit augsim
    /// computes and writes in, so that a number without a unit means the same everywhere.
    pub const DEFAULT: LengthUnit = LengthUnit::Metre;

    /// Every unit, from the largest.
    pub const ALL: [LengthUnit; 4] =
        [LengthUnit::Metre, LengthUnit::Centimetre, LengthUnit::Millimetre, LengthUnit::Micrometre];

    /// Its symbol: "m", "cm", "mm" or "um" (what [`LengthUnit::from_str`] reads).
    pub fn symbol(self) -> &'static str {
        match self {
            LengthUnit::Metre => "m",
            LengthUnit::Centimetre => "cm",
            LengthUnit::Millimetre => "mm",
            LengthUnit::Micrometre => "um",
        }
    }

    /// Its name in words: "metres", "centimetres", "millimetres" or "micrometres".
    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Metre => "metres",
            LengthUnit::Centimetre => "centimetres",
            LengthUnit::Millimetre => "millimetres",
            LengthUnit::Micrometre => "micrometres",
        }
    }

    /// Metres in one unit (the scale that brings coordinates in this unit to metres).
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::Metre => 1.0,
            LengthUnit::Centimetre => 1e-2,
            LengthUnit::Millimetre => 1e-3,
            LengthUnit::Micrometre => 1e-6,
        }
    }

    /// Millimetres in one unit (the scale that brings coordinates in this unit to millimetres, the unit of
    /// 3D Slicer's and a scanner's files).
    pub fn millimetres(self) -> f64 {
        self.metres() / LengthUnit::Millimetre.metres()
    }

    /// A length in this unit, in metres.
    pub fn to_metres(self, length: f64) -> f64 {
        length * self.metres()
    }

    /// A length in metres, in this unit.
    pub fn from_metres(self, metres: f64) -> f64 {
        metres / self.metres()
    }

    /// A point in this unit, in metres.
    pub fn point_to_metres(self, p: Point) -> Point {
        p.map(|x| self.to_metres(x))
    }

    /// A point in metres, in this unit.
    pub fn point_from_metres(self, p: Point) -> Point {
        p.map(|x| self.from_metres(x))
    }
}

impl Default for LengthUnit {
    fn default() -> LengthUnit {
        LengthUnit::DEFAULT
    }
}

impl fmt::Display for LengthUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// The units' symbols as messages list them.
const CHOICES: &str = "m, cm, mm or um";

impl FromStr for LengthUnit {
    type Err = String;

    /// "m", "cm", "mm" or "um" ("µm"), in either case ("MM").
    fn from_str(name: &str) -> Result<LengthUnit, String> {
        match name {
            "µm" | "μm" => Ok(LengthUnit::Micrometre),
            _ => LengthUnit::ALL
                .into_iter()
                .find(|unit| unit.symbol().eq_ignore_ascii_case(name))
                .ok_or_else(|| format!("must be {CHOICES}, got '{name}'")),
        }
    }
}

impl TryFrom<String> for LengthUnit {
    type Error = String;

    fn try_from(name: String) -> Result<LengthUnit, String> {
        name.parse()
    }
}

impl From<LengthUnit> for String {
    fn from(unit: LengthUnit) -> String {
        unit.symbol().to_string()
    }
}

/// A single length a user gives (a distance, a cell size, a shift), held in metres. On a command
/// line it is written with its unit, `7mm`, `2.5 cm` or `0.2m` ([`Length::from_str`]: a number
/// without one is refused, 0 aside, so that a distance in mm is never read as metres); in a
/// scenario file also as a bare number, in metres as every length there.
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "LengthGiven", into = "f64")]
pub struct Length(f64);

impl Length {
    /// The length of `metres` metres.
    pub fn metres(metres: f64) -> Length {
        Length(metres)
    }

    /// The length in metres.
    pub fn in_metres(self) -> f64 {
        self.0
    }
}

impl fmt::Display for Length {
    /// In millimetres, as reports give lengths: `7 mm`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} mm", number(mm(self.0)))
    }
}

impl FromStr for Length {
    type Err = String;

    /// A finite number and its unit ([`LengthUnit::from_str`]), a space between them or not:
    /// `7mm`, `2.5 cm`, `0.2m`; `0` alone.
    fn from_str(given: &str) -> Result<Length, String> {
        let given = given.trim();
        // The unit is the letters that end it (a number may hold an exponent's `e`: 1e-3m).
        let number = given.trim_end_matches(|c: char| c.is_alphabetic() || c == 'µ' || c == 'μ');
        let (number, unit) = (number.trim(), &given[number.len()..]);
        let value: f64 = number
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| format!("'{given}' is not a length: a number and its unit ({CHOICES}), e.g. 7mm"))?;
        match unit {
            "" if value == 0.0 => Ok(Length(0.0)),
            "" => Err(format!("'{given}' has no unit: give it, e.g. {given}mm or {given}m")),
            unit => unit
                .parse::<LengthUnit>()
                .map(|u| Length(u.to_metres(value)))
                .map_err(|e| format!("the unit of '{given}' {e}")),
        }
    }
}

/// A length as a scenario file holds it: a number in metres, or a text with its unit.
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum LengthGiven {
    Metres(f64),
    Text(String),
}

impl TryFrom<LengthGiven> for Length {
    type Error = String;

    fn try_from(given: LengthGiven) -> Result<Length, String> {
        match given {
            LengthGiven::Metres(m) if m.is_finite() => Ok(Length(m)),
            LengthGiven::Metres(m) => Err(format!("the length {m} is not finite")),
            LengthGiven::Text(text) => text.parse(),
        }
    }
}

impl From<Length> for f64 {
    fn from(length: Length) -> f64 {
        length.0
    }
}

/// A unit given, or `None`: told from the organ's size (see [`crate::repair::detect_unit`]).
pub type UnitOrAuto = Option<LengthUnit>;

/// A unit ("m", "cm", "mm", "um") or "auto" (`None`), where an organ's surface gives its scale.
pub fn parse_unit_or_auto(name: &str) -> Result<UnitOrAuto, String> {
    match name {
        "auto" => Ok(None),
        _ => name.parse().map(Some).map_err(|_| format!("must be m, cm, mm, um or auto, got '{name}'")),
    }
}

/// A length in metres, in millimetres (as reports and file columns give them).
pub fn mm(metres: f64) -> f64 {
    LengthUnit::Millimetre.from_metres(metres)
}

/// A length in millimetres, in metres.
pub fn from_mm(millimetres: f64) -> f64 {
    LengthUnit::Millimetre.to_metres(millimetres)
}

/// A point given in metres as a message shows it, in millimetres to six significant digits:
/// `(92.603, -55.448, -209.771) mm`.
pub fn point_in_mm(p: Point) -> String {
    let [x, y, z] = p.map(|c| number(mm(c)));
    format!("({x}, {y}, {z}) mm")
}

/// The units among `candidates` in which a largest extent of `extent` (a number, as a file holds
/// it) is an organ's size ([`ORGAN_EXTENT_M`]), in their order.
pub fn organ_units(extent: f64, candidates: &[LengthUnit]) -> Vec<LengthUnit> {
    candidates.iter().copied().filter(|u| ORGAN_EXTENT_M.contains(&u.to_metres(extent))).collect()
}

/// A unit mistake that numbers of lengths can carry: given in `given` where `expected` was meant,
/// so read [`UnitMistake::factor`] times too large or too small.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnitMistake {
    /// The unit the numbers are in.
    pub given: LengthUnit,
    /// The unit they were read in.
    pub expected: LengthUnit,
}

impl UnitMistake {
    /// The mistakes the checks look for, the likeliest first: millimetres and metres either way,
    /// then millimetres and centimetres either way.
    pub const COMMON: [UnitMistake; 4] = [
        UnitMistake { given: LengthUnit::Millimetre, expected: LengthUnit::Metre },
        UnitMistake { given: LengthUnit::Metre, expected: LengthUnit::Millimetre },
        UnitMistake { given: LengthUnit::Millimetre, expected: LengthUnit::Centimetre },
        UnitMistake { given: LengthUnit::Centimetre, expected: LengthUnit::Millimetre },
    ];

    /// What the numbers read must be multiplied by to undo the mistake (0.001 for millimetres
    /// read as metres).
    pub fn factor(self) -> f64 {
        self.given.metres() / self.expected.metres()
    }

    /// How the numbers compare with what they were meant to be, read once more with the mistake
    /// undone: "1,000 times smaller", "10 times larger".
    pub fn undone_words(self) -> String {
        let factor = self.factor();
        let times = |f: f64| match f.round() as u64 {
            n if n >= 1000 => format!("{},{:03}", n / 1000, n % 1000),
            n => n.to_string(),
        };
        match factor < 1.0 {
            true => format!("{} times smaller", times(1.0 / factor)),
            false => format!("{} times larger", times(factor)),
        }
    }

    /// The question a message asks about it: "given in mm where m were expected".
    pub fn question(self) -> String {
        format!("given in {} where {} were expected", self.given, self.expected)
    }
}

/// The largest extent of an organ (m): from 2 cm (a gallbladder, a kidney's tumour) to 60 cm.
pub const ORGAN_EXTENT_M: std::ops::RangeInclusive<f64> = 0.02..=0.6;

/// A number with six significant digits, without trailing zeros (in scientific notation beyond
/// 1e9 and below 1e-6: a damaged file's 1e300 as 3e300, not three hundred digits).
pub fn number(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    if !(1e-6..1e9).contains(&x.abs()) {
        let text = format!("{x:.5e}");
        let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
        return format!("{}e{exponent}", mantissa.trim_end_matches('0').trim_end_matches('.'));
    }
    let decimals = (5 - x.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let text = format!("{x:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short() {
        assert_eq!(number(187.3), "187.3");
        assert_eq!(number(6.41234567), "6.41235");
        assert_eq!(number(0.0002), "0.0002");
        assert_eq!(number(1500.0), "1500");
        assert_eq!(number(1e300), "1e300");
        assert_eq!(number(-2.5e-9), "-2.5e-9");
    }

    /// Each mistake's factor undoes it, in words as a message says it.
    #[test]
    fn unit_mistakes_are_undone_by_their_factor() {
        let [mm_for_m, m_for_mm, mm_for_cm, cm_for_mm] = UnitMistake::COMMON;
        assert_eq!((mm_for_m.factor(), m_for_mm.factor()), (1e-3, 1e3));
        assert!((mm_for_cm.factor() - 0.1).abs() < 1e-15 && (cm_for_mm.factor() - 10.0).abs() < 1e-12);
        let words: Vec<String> = UnitMistake::COMMON.iter().map(|m| m.undone_words()).collect();
        assert_eq!(words, ["1,000 times smaller", "1,000 times larger", "10 times smaller", "10 times larger"]);
        assert_eq!(mm_for_m.question(), "given in mm where m were expected");
        // 300 is an organ in mm; 8 one in cm; 45 one in either; 5000 in neither.
        let units = [LengthUnit::Millimetre, LengthUnit::Centimetre];
        let fits = |extent: f64| organ_units(extent, &units);
        assert_eq!((fits(300.0), fits(8.0)), (vec![LengthUnit::Millimetre], vec![LengthUnit::Centimetre]));
        assert_eq!((fits(45.0), fits(5000.0)), (units.to_vec(), vec![]));
        // 120 mm read as metres: the factor brings it back to 0.12 m.
        assert!((mm_for_m.factor() * 120.0 - LengthUnit::Millimetre.to_metres(120.0)).abs() < 1e-15);
    }

    #[test]
    fn symbols_parse_back_and_scale_to_metres() {
        for unit in LengthUnit::ALL {
            assert_eq!(unit.symbol().parse::<LengthUnit>().unwrap(), unit);
            assert_eq!(unit.to_string(), unit.symbol());
            assert_eq!(parse_unit_or_auto(unit.symbol()).unwrap(), Some(unit));
            assert!((unit.from_metres(unit.to_metres(2.5)) - 2.5).abs() < 1e-12);
        }
        assert_eq!(LengthUnit::Millimetre.metres() * 1000.0, LengthUnit::Metre.metres());
        assert_eq!(LengthUnit::Millimetre.point_to_metres([10.0, 20.0, -5.0]), [0.01, 0.02, -0.005]);
        assert_eq!(point_in_mm([0.092603, -5.5448e-8, 0.0]), "(92.603, -0.000055448, 0) mm");
        assert!((mm(0.0125) - 12.5).abs() < 1e-12 && (from_mm(12.5) - 0.0125).abs() < 1e-15);
        assert_eq!(LengthUnit::default(), LengthUnit::Metre);
        assert_eq!(LengthUnit::Centimetre.point_to_metres([10.0, 20.0, -5.0]), [0.1, 0.2, -0.05]);
        assert!((LengthUnit::Micrometre.to_metres(2.5e4) - 0.025).abs() < 1e-15);
        assert_eq!("µm".parse::<LengthUnit>().unwrap(), LengthUnit::Micrometre);
        let sizes: Vec<f64> = LengthUnit::ALL.iter().map(|u| u.metres()).collect();
        assert!(sizes.windows(2).all(|w| w[0] > w[1]), "{sizes:?}");
    }

    #[test]
    fn other_names_are_refused_with_the_choices() {
        assert_eq!("in".parse::<LengthUnit>().unwrap_err(), "must be m, cm, mm or um, got 'in'");
        assert_eq!("auto".parse::<LengthUnit>().unwrap_err(), "must be m, cm, mm or um, got 'auto'");
        assert_eq!(parse_unit_or_auto("auto").unwrap(), None);
        assert_eq!(parse_unit_or_auto("ft").unwrap_err(), "must be m, cm, mm, um or auto, got 'ft'");
        // Either case, as "RAS" and "ras" are the same frame.
        assert_eq!(parse_unit_or_auto("MM").unwrap(), Some(LengthUnit::Millimetre));
    }

    #[test]
    fn serialised_as_its_symbol() {
        #[derive(serde::Serialize, serde::Deserialize)]
        struct S {
            units: LengthUnit,
        }
        let text = serde_json::to_string(&S { units: LengthUnit::Millimetre }).unwrap();
        assert_eq!(text, r#"{"units":"mm"}"#);
        assert_eq!(serde_json::from_str::<S>(r#"{"units":"m"}"#).unwrap().units, LengthUnit::Metre);
        assert_eq!(serde_json::from_str::<S>(r#"{"units":"cm"}"#).unwrap().units, LengthUnit::Centimetre);
        let err = serde_json::from_str::<S>(r#"{"units":"ft"}"#).err().unwrap().to_string();
        assert!(err.contains("must be m, cm, mm or um"), "{err}");
    }

    #[test]
    fn a_length_is_read_with_its_unit_and_refused_without_one() {
        let read = |s: &str| s.parse::<Length>().map(Length::in_metres);
        assert_eq!(
            (read("7mm"), read("2.5 cm"), read(" 0.2m "), read("3 MM")),
            (Ok(0.007), Ok(0.025), Ok(0.2), Ok(0.003))
        );
        assert_eq!(
            (read("0"), read("-4mm"), read("1e-3m"), read("2.5E1 mm")),
            (Ok(0.0), Ok(-0.004), Ok(0.001), Ok(0.025))
        );
        let e = read("7").unwrap_err();
        assert!(e.contains("'7' has no unit") && e.contains("7mm"), "{e}");
        for bad in ["mm", "7 inches", "nan mm", ""] {
            assert!(read(bad).is_err(), "{bad} read as a length");
        }
        assert!(read("1e999 m").unwrap_err().contains("is not a length"), "{:?}", read("1e999 m"));
        #[derive(serde::Deserialize)]
        struct File {
            a: Length,
            b: Length,
        }
        let file: File = serde_json::from_str(r#"{"a": 0.007, "b": "7 mm"}"#).unwrap();
        assert_eq!((file.a.in_metres(), file.b.in_metres()), (0.007, 0.007));
        assert!(serde_json::from_str::<File>(r#"{"a": "7", "b": 0.0}"#).is_err());
        assert_eq!(Length::metres(0.0123).to_string(), "12.3 mm");
    }
}
