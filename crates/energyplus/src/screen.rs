//! The screen every model passes before EnergyPlus sees it: a submitted IDF is untrusted code.
//!
//! EnergyPlus 25.2 runs Python inside its own process for `PythonPlugin:*` objects (a module
//! from any path the IDF names, with the whole environment of the process that started it),
//! and co-simulation through `ExternalInterface:*` (BCVTB sockets, FMUs: native code). Other
//! objects read files by path: a schedule from `/proc/self/environ` would quote the worker's
//! secrets back in an error or a result. So a model is refused when it has an object of a
//! class that runs code, or a file field that points outside the run folder (absolute, a
//! parent folder, a home folder). The file fields are every field of the 25.2 IDD that takes a
//! file path ([`FILE_FIELDS`]; `the_list_covers_every_file_field_of_the_idd` checks it against
//! the engine's IDD).
//!
//! The screen is applied where a model file is loaded ([`crate::Model::from_toml`]) and again
//! to the exact input of every run ([`crate::Runner::run`]), after every edit bemcal applies.

use std::path::Path;

use crate::idd::Idd;
use crate::idf::{Idf, IdfObject};
use crate::Error;

/// Class prefixes whose objects run code inside or beside EnergyPlus.
/// (`ExternalInterface` itself switches the interface on; its `:` classes configure it.)
pub const CODE_CLASSES: [&str; 2] = ["PythonPlugin:", "ExternalInterface"];

/// `(class, field)`: every field of the EnergyPlus 25.2 IDD that names a file, outside the
/// classes of [`CODE_CLASSES`] (refused whole).
pub const FILE_FIELDS: [(&str, &str); 7] = [
    ("Schedule:File", "File Name"),
    ("Schedule:File:Shading", "File Name"),
    ("Construction:WindowDataFile", "File Name"),
    ("Table:IndependentVariable", "External File Name"),
    ("Table:Lookup", "External File Name"),
    ("Coil:DX:ASHRAE205:Performance", "Representation File Name"),
    ("Chiller:Electric:ASHRAE205", "Representation File Name"),
];

/// Checks `idf` (read from `source`, for messages): the first refused object, with its line
/// (or its name where bemcal made it), is the error.
pub fn screen(idf: &Idf, idd: &Idd, source: &Path) -> Result<(), Error> {
    for o in &idf.objects {
        if let Some(prefix) = CODE_CLASSES
            .iter()
            .find(|p| starts_with_ignore_case(&o.class, p))
        {
            return Err(refused(
                o,
                source,
                format!(
                    "{}: objects that run code in or beside EnergyPlus ({}*) are refused: bemcal runs every model as untrusted code",
                    what(o),
                    prefix.trim_end_matches(':')
                ),
            ));
        }
        for (class, field) in FILE_FIELDS {
            if !o.class.eq_ignore_ascii_case(class) {
                continue;
            }
            let Some(value) = idd.field_index(class, field).and_then(|i| o.fields.get(i)) else {
                continue;
            };
            if let Some(why) = outside_run_folder(value) {
                return Err(refused(
                    o,
                    source,
                    format!(
                        "{} field '{field}' = '{}': {why}; a model may name only files inside its run folder",
                        what(o),
                        bemcal_excerpt::excerpt(value, 80)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Why `path` points outside the run folder, or `None` when it is a plain relative name.
pub fn outside_run_folder(path: &str) -> Option<&'static str> {
    let p = path.trim();
    if p.is_empty() {
        return None;
    }
    let bytes = p.as_bytes();
    if p.starts_with('/') || p.starts_with('\\') {
        return Some("an absolute path");
    }
    if bytes.len() >= 2 && bytes[1] == b':' && bytes[0].is_ascii_alphabetic() {
        return Some("an absolute path (a drive)");
    }
    if p.starts_with('~') || p.starts_with('$') || p.contains("%") {
        return Some("a home folder or a variable");
    }
    if p.split(['/', '\\']).any(|part| part.trim() == "..") {
        return Some("a parent folder ('..')");
    }
    None
}

/// Compares bytes: a class name is the submitter's text, with any character where the prefix
/// ends (slicing the `str` there panicked on a multi-byte one, found by `tests/fuzz.rs`).
fn starts_with_ignore_case(s: &str, prefix: &str) -> bool {
    s.as_bytes()
        .get(..prefix.len())
        .is_some_and(|head| head.eq_ignore_ascii_case(prefix.as_bytes()))
}

fn what(o: &IdfObject) -> String {
    match o.name() {
        Some(n) if !n.is_empty() => format!("{} '{}'", o.class, bemcal_excerpt::excerpt(n, 60)),
        _ => o.class.clone(),
    }
}

fn refused(o: &IdfObject, source: &Path, message: String) -> Error {
    Error::Input {
        path: source.to_path_buf(),
        line: o.line,
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn idd() -> Idd {
        Idd::parse(
            "Schedule:File,\n  A1, \\field Name\n  A2, \\field Schedule Type Limits Name\n  A3, \\field File Name\n\
             Lights,\n  A1, \\field Name\n",
        )
    }

    fn check(text: &str) -> Result<(), Error> {
        let idf = Idf::parse(text, Path::new("m.idf")).unwrap();
        screen(&idf, &idd(), Path::new("m.idf"))
    }

    #[test]
    fn code_objects_are_refused_with_their_line() {
        let e = check("Lights,L1;\n\nPythonPlugin:Instance,\n  steal, No, env, Plugin;\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("m.idf:3:"), "{e}");
        assert!(e.contains("PythonPlugin:Instance 'steal'"), "{e}");
        let e = check("externalinterface:functionalmockupunitimport, x.fmu, 10;")
            .unwrap_err()
            .to_string();
        assert!(e.contains("(ExternalInterface*)"), "{e}");
    }

    #[test]
    fn a_class_with_a_multi_byte_character_where_a_prefix_ends_is_screened() {
        check("Pipe:Adiabat\u{e9}, P1;\nPipe:Adiabatic:X\u{e9}, P2;\n").unwrap();
        assert!(check("Lights, L1;\nPythonPlugin:\u{e9}, y;\n").is_err());
    }

    #[test]
    fn file_fields_must_stay_in_the_run_folder() {
        for bad in [
            "/proc/self/environ",
            "../secrets.csv",
            "~/x.csv",
            "C:\\x.csv",
            "a/../../b",
        ] {
            let e = check(&format!("Schedule:File, occ, Fraction, {bad}, 1, 0;"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("'File Name'") && e.contains("run folder"),
                "{bad}: {e}"
            );
        }
        check("Schedule:File, occ, Fraction, occupancy.csv, 1, 0;").unwrap();
        check("Lights, /not/a/file/field;").unwrap();
    }

    /// Every field of the engine's IDD whose name says it takes a file is in [`FILE_FIELDS`]
    /// or in a refused class (needs EnergyPlus; skipped without it).
    #[test]
    fn the_list_covers_every_file_field_of_the_idd() {
        let Ok(engine) = crate::Engine::locate() else {
            eprintln!("skipping: no EnergyPlus");
            return;
        };
        let text = std::fs::read_to_string(engine.idd()).unwrap();
        let mut class = String::new();
        let mut missing = vec![];
        for line in text.lines() {
            let body = line.split('!').next().unwrap_or("");
            if !body.starts_with([' ', '\t', '\\']) && body.trim().ends_with([',', ';']) {
                class = body.trim().trim_end_matches([',', ';']).to_string();
                continue;
            }
            let Some(pos) = line.find("\\field ") else {
                continue;
            };
            let field = line[pos + 7..].trim();
            let names_a_file = ["File Name", "File Path", "Search Path", "Directory"]
                .iter()
                .any(|w| field.contains(w))
                && !field.contains("Suffix");
            let known = CODE_CLASSES
                .iter()
                .any(|p| starts_with_ignore_case(&class, p))
                || FILE_FIELDS
                    .iter()
                    .any(|(c, f)| c.eq_ignore_ascii_case(&class) && f.eq_ignore_ascii_case(field));
            if names_a_file && !known {
                missing.push(format!("{class}: {field}"));
            }
        }
        assert!(missing.is_empty(), "file fields not screened: {missing:?}");
    }
}
