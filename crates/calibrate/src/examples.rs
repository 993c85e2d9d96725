//! The bundled example building, carried inside the binary so that an installed `bemcal` (a
//! wheel's copy, outside any repository) can write it out: `bemcal example office --out DIR`.

use std::path::{Path, PathBuf};

/// A bundled example: a name and its files (name, text).
#[derive(Debug, Clone, Copy)]
pub struct Example {
    /// The name `bemcal example` takes.
    pub name: &'static str,
    /// One line on what it is.
    pub about: &'static str,
    /// The files it writes, by file name.
    pub files: &'static [(&'static str, &'static str)],
}

/// Every bundled example.
pub const EXAMPLES: &[Example] = &[
    Example {
        name: "office",
        about:
            "the example office: model.toml (4 storeys, 20 zones, 38 parameters) with project.toml \
            (the demo's calibration), small.toml (a one-zone box) with quick.toml (six parameters, \
            `make quick`); meters come from `bemcal synthesize` or your own CSV",
        files: &[
            (
                "model.toml",
                include_str!("../../../examples/office/model.toml"),
            ),
            (
                "project.toml",
                include_str!("../../../examples/office/project.toml"),
            ),
            (
                "small.toml",
                include_str!("../../../examples/office/small.toml"),
            ),
            (
                "quick.toml",
                include_str!("../../../examples/office/quick.toml"),
            ),
        ],
    },
    Example {
        name: "own-idf",
        about: "your own IDF: building.idf (a one-zone office with IDF Editor's field comments) \
            mapped by model.toml onto six parameters (people, lights and equipment, \
            infiltration, both set-point schedules; set, scale and offset edits), with \
            project.toml (`make quick`'s settings); meters from `bemcal synthesize` as \
            project.toml says, or your own CSV",
        files: &[
            (
                "building.idf",
                include_str!("../../../examples/own-idf/building.idf"),
            ),
            (
                "model.toml",
                include_str!("../../../examples/own-idf/model.toml"),
            ),
            (
                "project.toml",
                include_str!("../../../examples/own-idf/project.toml"),
            ),
        ],
    },
];

/// The example called `name`.
pub fn find(name: &str) -> Option<&'static Example> {
    EXAMPLES.iter().find(|e| e.name == name)
}

impl Example {
    /// Writes the example's files into `dir` (created if needed) and returns their paths. A file
    /// already there is left as it is and refused, so that a user's edits are never overwritten.
    pub fn write_to(&self, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir)?;
        let taken: Vec<String> = self
            .files
            .iter()
            .filter(|(name, _)| dir.join(name).exists())
            .map(|(name, _)| dir.join(name).display().to_string())
            .collect();
        if !taken.is_empty() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                format!(
                    "{} already exist(s); choose another folder",
                    taken.join(", ")
                ),
            ));
        }
        self.files
            .iter()
            .map(|(name, text)| {
                let path = dir.join(name);
                std::fs::write(&path, text).map(|()| path)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_office_example_writes_its_files_once() {
        let dir = tempfile::tempdir().unwrap();
        let office = find("office").unwrap();
        let written = office.write_to(dir.path()).unwrap();
        assert_eq!(written.len(), 4);
        let quick = std::fs::read_to_string(dir.path().join("quick.toml")).unwrap();
        assert!(quick.contains("model = \"small.toml\""));
        let again = office.write_to(dir.path()).unwrap_err();
        assert_eq!(again.kind(), std::io::ErrorKind::AlreadyExists);
        assert!(find("nowhere").is_none());

        let own = find("own-idf").unwrap();
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(own.write_to(dir.path()).unwrap().len(), 3);
        let map = std::fs::read_to_string(dir.path().join("model.toml")).unwrap();
        assert!(map.contains("path = \"building.idf\""));
    }
}
