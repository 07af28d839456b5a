//! The trial table's CSV: a cell written, a line split (RFC 4180's quoting).

/// A CSV cell: quoted when it holds a comma, a quote or a line break.
pub fn cell(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

/// A table's header line: its columns, found by name.
#[derive(Debug)]
pub struct Header<'a> {
    /// The column names.
    pub cells: Vec<String>,
    path: &'a std::path::Path,
}

impl<'a> Header<'a> {
    /// The header `line` of the table at `path` (named in errors).
    pub fn new(line: &str, path: &'a std::path::Path) -> Self {
        Self {
            cells: split(line),
            path,
        }
    }

    /// The index of column `name`.
    ///
    /// # Errors
    /// The table has no such column.
    pub fn col(&self, name: &str) -> anyhow::Result<usize> {
        use anyhow::Context;
        self.cells
            .iter()
            .position(|c| c == name)
            .with_context(|| format!("{}: no column {name:?}", self.path.display()))
    }
}

/// `cells` as one CSV line (no line break).
pub fn line(cells: &[String]) -> String {
    cells.iter().map(|c| cell(c)).collect::<Vec<_>>().join(",")
}

/// Splits a CSV line (quoted cells may hold commas and doubled quotes).
pub fn split(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cell = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cell.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut cell)),
            (c, _) => cell.push(c),
        }
    }
    out.push(cell);
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn cells_written_are_split_back() {
        let cells = ["a", "b,c", "d\"e", ""];
        let line: Vec<String> = cells.iter().map(|c| super::cell(c)).collect();
        assert_eq!(line.join(","), "a,\"b,c\",\"d\"\"e\",");
        assert_eq!(super::split(&line.join(",")), cells);
    }
}
