//! Every CSV file lodcloth writes, through the `csv` crate: a field holding
//! a comma, a quote or a line break (a scene's free-text name, a note) is
//! quoted, so it stays one field and the columns after it do not shift.
//! Each row must have the header's number of fields.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::{io_err, OutputError};

/// A CSV table being written: a header, then rows of cells (already
/// formatted, so each column keeps the precision its writer chose).
pub struct CsvTable<W: Write> {
    w: csv::Writer<W>,
    /// Where it goes, for errors.
    path: String,
    /// Fields per row (the header's).
    width: usize,
}

impl CsvTable<BufWriter<File>> {
    /// Create (truncate) `path` and write `header`.
    pub fn create(path: &Path, header: &[&str]) -> Result<Self, OutputError> {
        let file = File::create(path).map_err(io_err(path))?;
        CsvTable::start(BufWriter::new(file), path.display().to_string(), header)
    }
}

impl CsvTable<Vec<u8>> {
    /// A table built in memory (see [`CsvTable::into_text`]).
    pub fn in_memory(header: &[&str]) -> Self {
        CsvTable::start(Vec::new(), "(CSV in memory)".into(), header).expect("writing to memory does not fail")
    }

    /// The table's text.
    pub fn into_text(self) -> String {
        let bytes = self.finish().expect("writing to memory does not fail");
        String::from_utf8(bytes).expect("every cell is a Rust string")
    }
}

impl<W: Write> CsvTable<W> {
    fn start(inner: W, path: String, header: &[&str]) -> Result<Self, OutputError> {
        let mut t = CsvTable {
            w: csv::WriterBuilder::new().from_writer(inner),
            path,
            width: header.len(),
        };
        t.row(header)?;
        Ok(t)
    }

    /// One row; quoted where a cell needs it. A row with another number of
    /// fields than the header is an error naming the file, and writes
    /// nothing.
    pub fn row<S: AsRef<str>>(&mut self, cells: &[S]) -> Result<(), OutputError> {
        let path = &self.path;
        if cells.len() != self.width {
            return Err(OutputError::Io {
                path: path.clone(),
                source: std::io::Error::other(format!(
                    "a row of {} fields under a header of {}",
                    cells.len(),
                    self.width
                )),
            });
        }
        self.w
            .write_record(cells.iter().map(|c| c.as_ref()))
            .map_err(|e| OutputError::Io {
                path: path.clone(),
                source: e.into(),
            })
    }

    /// Flush buffered rows to the file now (e.g. before giving up on a run,
    /// so what was written stays readable).
    pub fn flush(&mut self) -> Result<(), OutputError> {
        let path = &self.path;
        self.w.flush().map_err(|source| OutputError::Io {
            path: path.clone(),
            source,
        })
    }

    /// Flush and hand back the writer.
    pub fn finish(self) -> Result<W, OutputError> {
        let path = self.path;
        self.w.into_inner().map_err(|e| OutputError::Io {
            path,
            source: e.into_error(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_text_with_commas_quotes_and_line_breaks_stays_one_field() {
        let name = "flag, 2:1 \"windy\"\nsecond line";
        let mut t = CsvTable::in_memory(&["scene", "level", "mean"]);
        t.row(&[name, "16x8", "0.012345"]).unwrap();
        t.row(&["plain", "8x8", "1e-3"]).unwrap();
        let text = t.into_text();
        let mut r = csv::Reader::from_reader(text.as_bytes());
        assert_eq!(r.headers().unwrap(), vec!["scene", "level", "mean"]);
        let rows: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
        assert_eq!(rows.len(), 2);
        assert_eq!(&rows[0][0], name);
        assert_eq!(&rows[0][1], "16x8");
        assert_eq!(&rows[0][2], "0.012345");
        assert_eq!(&rows[1][0], "plain");
        // Plain cells are not quoted: the file reads as before for simple names.
        assert!(text.contains("\nplain,8x8,1e-3\n"), "{text}");
    }

    #[test]
    fn a_row_of_the_wrong_width_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        let mut t = CsvTable::create(&path, &["a", "b"]).unwrap();
        t.row(&["1", "2"]).unwrap();
        let err = t.row(&["1"]).unwrap_err().to_string();
        assert!(err.contains("t.csv"), "{err}");
        t.finish().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "a,b\n1,2\n");
    }
}
