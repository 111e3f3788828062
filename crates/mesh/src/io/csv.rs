//! CSV tables, the one reader and writer of augsim's CSV files: fields split at a separator (a
//! comma unless the [`Dialect`] says otherwise), a field in double quotes (RFC 4180) holding
//! separators and doubled quotes, fields trimmed, blank lines skipped, a byte-order mark ignored.
//! Comment lines start with `#`: before the header, those of the form `# key = value` are kept as
//! [`Setting`]s (Slicer's `# CoordinateSystem = LPS`, `# columns = …`); after it, they are skipped.
//!
//! Readers parse text and turn a [`CsvError`] (a message and its line) into their own error,
//! naming their file.

use std::io::Write as _;
use std::path::Path;

use super::{write_atomic, WriteError};
use crate::Point;

/// Where a table's column names come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Header {
    /// The first line that is not a comment.
    Line,
    /// The first line that is not a comment, unless all its fields are numbers (or empty): then
    /// the table has no header and that line is data.
    Optional,
    /// A `# key = …` comment line before the data (Slicer's `.fcsv` names its columns so).
    Comment(&'static str),
}

/// How a table is written: its field separators and where its header is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dialect {
    /// The characters that separate fields.
    pub separators: &'static [char],
    /// Where the column names are.
    pub header: Header,
}

impl Dialect {
    /// Comma-separated, a header line naming the columns.
    pub const CSV: Dialect = Dialect { separators: &[','], header: Header::Line };
}

/// What is wrong with a table: the message and, where it has one, the line (1-based).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}{message}", line.map_or(String::new(), |l| format!("line {l}: ")))]
pub struct CsvError {
    /// The line, when the error has one.
    pub line: Option<usize>,
    /// What is wrong.
    pub message: String,
}

impl CsvError {
    /// An error on `line`.
    pub fn at(line: usize, message: impl Into<String>) -> CsvError {
        CsvError { line: Some(line), message: message.into() }
    }
}

/// A `# key = value` comment line before the header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Setting {
    /// Its line.
    pub line: usize,
    /// The key, trimmed and in lower case.
    pub key: String,
    /// The value, trimmed.
    pub value: String,
}

/// A data row: its line and its fields (unquoted, trimmed).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Row {
    /// Its line.
    pub line: usize,
    /// Its fields.
    pub fields: Vec<String>,
}

/// A parsed table.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Table {
    /// The `# key = value` comments before the header.
    pub settings: Vec<Setting>,
    /// The line of the header; `None` when there is none (no line at all, or, with
    /// [`Header::Optional`], a first line of numbers).
    pub header_line: Option<usize>,
    /// The column names, in lower case (empty when there is no header).
    pub names: Vec<String>,
    /// The data rows.
    pub rows: Vec<Row>,
}

impl Table {
    /// Parses CSV text in `dialect` (see the [module](self) documentation).
    pub fn parse(text: &str, dialect: &Dialect) -> Result<Table, CsvError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines =
            text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty()).peekable();
        let mut table = Table::default();
        while let Some(&(line, text)) = lines.peek().filter(|(_, l)| l.starts_with('#')) {
            lines.next();
            if let Some((key, value)) = text.trim_start_matches('#').split_once('=') {
                let key = key.trim().to_ascii_lowercase();
                table.settings.push(Setting { line, key, value: value.trim().to_string() });
            }
        }
        let split = |line: usize, text: &str| split_fields(text, dialect.separators).map_err(|m| CsvError::at(line, m));
        let header = match dialect.header {
            Header::Comment(key) => {
                let setting = table.settings.iter().find(|s| s.key == key).ok_or_else(|| CsvError {
                    line: None,
                    message: format!("no '# {key} = …' line naming the columns"),
                })?;
                Some((setting.line, setting.value.clone()))
            }
            Header::Line => lines.next().map(|(line, text)| (line, text.to_string())),
            Header::Optional => match lines.peek() {
                Some(&(line, text)) if !split(line, text)?.iter().all(|f| f.is_empty() || f.parse::<f64>().is_ok()) => {
                    lines.next();
                    Some((line, text.to_string()))
                }
                _ => None,
            },
        };
        if let Some((line, text)) = header {
            table.names = split(line, &text)?.iter().map(|n| n.to_ascii_lowercase()).collect();
            table.header_line = Some(line);
        }
        for (line, text) in lines.filter(|(_, l)| !l.starts_with('#')) {
            table.rows.push(Row { line, fields: split(line, text)? });
        }
        Ok(table)
    }

    /// The column named `name` (in lower case), if any.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Checks that every row has as many fields as the header has columns.
    pub fn check_widths(&self) -> Result<(), CsvError> {
        let n = self.names.len();
        match self.rows.iter().find(|r| r.fields.len() != n) {
            Some(r) => Err(CsvError::at(r.line, format!("{} fields, the header has {n} columns", r.fields.len()))),
            None => Ok(()),
        }
    }
}

impl Row {
    /// The point in columns `xyz` of this row (finite numbers).
    pub fn point(&self, xyz: [usize; 3]) -> Result<Point, CsvError> {
        let mut p = [0.0; 3];
        for (axis, &column) in xyz.iter().enumerate() {
            let name = ["x", "y", "z"][axis];
            let field = self.fields.get(column).ok_or_else(|| {
                CsvError::at(
                    self.line,
                    format!("no {name}: {} fields, {name} is field {}", self.fields.len(), column + 1),
                )
            })?;
            p[axis] = number(field).map_err(|m| CsvError::at(self.line, format!("{name} {m}")))?;
        }
        Ok(p)
    }
}

/// A finite number, or what is wrong with `text` (`= "abc" is not a number`).
pub fn number(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("= {text:?} is not finite")),
        Err(_) => Err(format!("= {text:?} is not a number")),
    }
}

/// The fields of a line split at any of `separators`, trimmed; a field in double quotes may hold
/// separators and doubled quotes.
pub fn split_fields(line: &str, separators: &[char]) -> Result<Vec<String>, String> {
    let mut fields = Vec::new();
    let mut chars = line.chars().peekable();
    loop {
        while chars.next_if(|c| *c == ' ' || *c == '\t').is_some() {}
        let mut field = String::new();
        if chars.next_if_eq(&'"').is_some() {
            loop {
                match chars.next() {
                    Some('"') if chars.next_if_eq(&'"').is_some() => field.push('"'),
                    Some('"') => break,
                    Some(c) => field.push(c),
                    None => return Err(format!("field {} opens a quote that is not closed", fields.len() + 1)),
                }
            }
            while chars.next_if(|c| *c == ' ' || *c == '\t').is_some() {}
            if chars.peek().is_some_and(|c| !separators.contains(c)) {
                return Err(format!("field {} has text after its closing quote", fields.len() + 1));
            }
        } else {
            while let Some(c) = chars.next_if(|c| !separators.contains(c)) {
                field.push(c);
            }
            field.truncate(field.trim_end().len());
        }
        fields.push(field);
        if chars.next().is_none() {
            return Ok(fields);
        }
    }
}

/// `text` as a CSV field (RFC 4180): quoted, its quotes doubled, when it holds a comma, a quote or a
/// line break, or starts with `#` (which would make a row it starts a comment); as it is otherwise.
pub fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) || text.trim_start().starts_with('#') {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// Writes a comma-separated table atomically: each of `comments` as a `# ` line, the `header`,
/// then a line per row, every field quoted where it must be ([`csv_field`]).
pub fn write_csv<R: AsRef<[String]>>(
    path: &Path,
    comments: &[String],
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<(), WriteError> {
    write_atomic(path, |w| {
        for comment in comments {
            writeln!(w, "# {comment}")?;
        }
        writeln!(w, "{}", header.iter().map(|h| csv_field(h)).collect::<Vec<_>>().join(","))?;
        for row in rows {
            writeln!(w, "{}", row.as_ref().iter().map(|f| csv_field(f)).collect::<Vec<_>>().join(","))?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_split_at_separators_outside_quotes() {
        assert_eq!(split_fields("a, b ,c", &[',']).unwrap(), ["a", "b", "c"]);
        assert_eq!(split_fields("1,\"F, 1\",\"say \"\"hi\"\"\",", &[',']).unwrap(), ["1", "F, 1", "say \"hi\"", ""]);
        assert_eq!(split_fields("1;2,3", &[',', ';']).unwrap(), ["1", "2", "3"]);
        assert_eq!(split_fields("", &[',']).unwrap(), [""]);
        assert!(split_fields("1,\"open", &[',']).unwrap_err().contains("field 2"));
        assert!(split_fields("\"a\"b,c", &[',']).unwrap_err().contains("after its closing quote"));
    }

    #[test]
    fn fields_are_quoted_only_when_they_must_be() {
        assert_eq!(csv_field("FEM co-rotational (3k T4)"), "FEM co-rotational (3k T4)");
        assert_eq!(csv_field(""), "");
        assert_eq!(csv_field("liver 5012 T4, Svk"), "\"liver 5012 T4, Svk\"");
        assert_eq!(csv_field("a \"b\""), "\"a \"\"b\"\"\"");
        assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
        assert_eq!(csv_field("#1"), "\"#1\"");
        assert_eq!(csv_field(" # 2"), "\" # 2\"");
        assert_eq!(csv_field("T#1"), "T#1");
    }

    /// A header line after comments and a byte-order mark; settings kept, comments among the rows skipped.
    #[test]
    fn a_header_line_after_settings() {
        let text = "\u{feff}# CoordinateSystem = LPS\n# a note\n\nLabel, X_mm ,y_mm,z_mm\nT1,1,2,3\n# skipped\n\n\"T2, deep\",4,5,6\n";
        let t = Table::parse(text, &Dialect::CSV).unwrap();
        assert_eq!(t.settings, [Setting { line: 1, key: "coordinatesystem".into(), value: "LPS".into() }]);
        assert_eq!(t.header_line, Some(4));
        assert_eq!(t.names, ["label", "x_mm", "y_mm", "z_mm"]);
        assert_eq!(t.rows.iter().map(|r| r.line).collect::<Vec<_>>(), [5, 8]);
        assert_eq!(t.rows[1].fields[0], "T2, deep");
        assert_eq!(t.rows[1].point([1, 2, 3]).unwrap(), [4.0, 5.0, 6.0]);
        assert_eq!(t.column("y_mm"), Some(2));
        t.check_widths().unwrap();
        let empty = Table::parse("\n# only a comment\n", &Dialect::CSV).unwrap();
        assert_eq!((empty.header_line, empty.rows.len()), (None, 0));
    }

    /// Slicer's `.fcsv`: the columns named by a comment, every other line data.
    #[test]
    fn a_header_in_a_comment() {
        let dialect = Dialect { separators: &[','], header: Header::Comment("columns") };
        let t = Table::parse("# columns = id,x,y,z\n1,0,0,0\n2,1,1,1\n", &dialect).unwrap();
        assert_eq!((t.header_line, t.names.len(), t.rows.len()), (Some(1), 4, 2));
        let e = Table::parse("1,0,0,0\n", &dialect).unwrap_err();
        assert_eq!((e.line, e.to_string()), (None, "no '# columns = …' line naming the columns".to_string()));
    }

    /// A first line of words is a header, one of numbers is data; either separator.
    #[test]
    fn an_optional_header() {
        let dialect = Dialect { separators: &[',', ';'], header: Header::Optional };
        let named = Table::parse("x;y;z\n1;2;3\n", &dialect).unwrap();
        assert_eq!((named.header_line, named.rows.len()), (Some(1), 1));
        let bare = Table::parse("\n1,2,3\n4,5,6\n", &dialect).unwrap();
        assert_eq!((bare.header_line, bare.names.len(), bare.rows[0].line), (None, 0, 2));
    }

    #[test]
    fn bad_rows_are_told_by_their_line() {
        let t = Table::parse("x,y,z\n1,2,3\n4,5\n", &Dialect::CSV).unwrap();
        assert_eq!(t.check_widths().unwrap_err().to_string(), "line 3: 2 fields, the header has 3 columns");
        let t = Table::parse("x,y,z\n1,inf,3\n1,two,3\n", &Dialect::CSV).unwrap();
        assert_eq!(t.rows[0].point([0, 1, 2]).unwrap_err().to_string(), "line 2: y = \"inf\" is not finite");
        assert_eq!(t.rows[1].point([0, 1, 2]).unwrap_err().to_string(), "line 3: y = \"two\" is not a number");
        let short = Row { line: 7, fields: vec!["1".into()] };
        assert_eq!(short.point([0, 1, 2]).unwrap_err().to_string(), "line 7: no y: 1 fields, y is field 2");
        let e = Table::parse("x,y\n\"open,1\n", &Dialect::CSV).unwrap_err();
        assert_eq!(e.to_string(), "line 2: field 1 opens a quote that is not closed");
    }

    /// What [`write_csv`] writes reads back the same, quoted fields included.
    #[test]
    fn written_tables_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        let rows = [
            vec!["a, b".to_string(), "1.5".to_string()],
            vec!["say \"hi\"".to_string(), "-2e-7".to_string()],
            vec!["#3".to_string(), "4".to_string()],
        ];
        write_csv(&path, &["CoordinateSystem = RAS".to_string()], &["label", "x"], &rows).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("# CoordinateSystem = RAS\nlabel,x\n\"a, b\",1.5\n"), "{text}");
        let t = Table::parse(&text, &Dialect::CSV).unwrap();
        assert_eq!(t.settings[0].value, "RAS");
        assert_eq!(t.rows.iter().map(|r| r.fields.clone()).collect::<Vec<_>>(), rows);
    }
}
