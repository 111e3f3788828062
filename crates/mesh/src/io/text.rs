//! Line-oriented text parsing with line numbers in every error.

use std::path::Path;
use std::str::{FromStr, SplitWhitespace};

use crate::MeshError;

/// The non-blank lines of a text file, numbered from 1.
pub(super) struct LineReader<'a> {
    path: &'a Path,
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    last: usize,
    /// Number of the last line when the file ends without a newline (a cut line), else 0.
    cut_line: usize,
}

impl<'a> LineReader<'a> {
    pub(super) fn new(path: &'a Path, text: &'a str) -> Self {
        let cut_line = if text.ends_with('\n') { 0 } else { text.lines().count() };
        LineReader { path, lines: text.lines().enumerate(), last: 0, cut_line }
    }

    /// The next non-blank line, or `None` at the end of the file.
    pub(super) fn next_line(&mut self) -> Option<Line<'a>> {
        for (i, text) in self.lines.by_ref() {
            self.last = i + 1;
            if !text.trim().is_empty() {
                let cut = i + 1 == self.cut_line;
                return Some(Line { path: self.path, no: i + 1, text, tokens: text.split_whitespace(), cut });
            }
        }
        None
    }

    /// The next non-blank line; the end of the file is an error saying what was expected.
    pub(super) fn expect(&mut self, what: &str) -> Result<Line<'a>, MeshError> {
        self.next_line().ok_or_else(|| self.end_of_file(what))
    }

    /// The error for a file that ends while `what` is still expected.
    pub(super) fn end_of_file(&self, what: &str) -> MeshError {
        MeshError::parse(self.path, format!("file ends at line {} while reading {what} (truncated file?)", self.last))
    }
}

/// One line of text and a cursor over its whitespace-separated tokens.
pub(super) struct Line<'a> {
    path: &'a Path,
    /// Line number, from 1.
    pub(super) no: usize,
    /// The whole line.
    pub(super) text: &'a str,
    tokens: SplitWhitespace<'a>,
    /// The file ends in the middle of this line.
    cut: bool,
}

impl<'a> Line<'a> {
    /// An error located on this line.
    pub(super) fn error(&self, message: impl std::fmt::Display) -> MeshError {
        let cut = if self.cut { " (the file ends in the middle of this line: truncated?)" } else { "" };
        MeshError::parse(self.path, format!("line {}: {message}{cut}", self.no))
    }

    /// The next token, or an error naming what is missing.
    pub(super) fn token(&mut self, what: &str) -> Result<&'a str, MeshError> {
        self.tokens.next().ok_or_else(|| self.error(format!("missing {what} in '{}'", self.text.trim())))
    }

    /// The next token, if any.
    pub(super) fn next_token(&mut self) -> Option<&'a str> {
        self.tokens.next()
    }

    /// The next token parsed as `T`, or an error naming what was expected.
    pub(super) fn parse<T: FromStr>(&mut self, what: &str) -> Result<T, MeshError> {
        let token = self.token(what)?;
        token.parse().map_err(|_| self.error(format!("expected {what}, found '{token}'")))
    }

    /// The next token as a finite floating-point number.
    pub(super) fn real(&mut self, what: &str) -> Result<f64, MeshError> {
        let x: f64 = self.parse(what)?;
        if x.is_finite() {
            Ok(x)
        } else {
            Err(self.error(format!("{what} is not finite ({x})")))
        }
    }

    /// The next three tokens as a point.
    pub(super) fn point(&mut self, what: &str) -> Result<[f64; 3], MeshError> {
        Ok([self.real(what)?, self.real(what)?, self.real(what)?])
    }

    /// Number of tokens left on the line.
    pub(super) fn remaining(&self) -> usize {
        self.tokens.clone().count()
    }

    /// An error if tokens are left on the line.
    pub(super) fn finish(&mut self, what: &str) -> Result<(), MeshError> {
        match self.tokens.next() {
            None => Ok(()),
            Some(t) => Err(self.error(format!("unexpected '{t}' after {what}"))),
        }
    }
}
